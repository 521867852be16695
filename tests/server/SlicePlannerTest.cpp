// Long frames in slices (server/SlicePlanner.h): the slices of a frame cover it exactly once,
// each within its budget of estimated cost at the speed its renderer has shown, and that speed
// follows the durations reported. No clock is read and nothing sleeps: durations are given, and
// a frame drawn slice by slice is timed by a clock the test moves.
#include "server/SlicePlanner.h"

#include "render/BrickPlan.h"
#include "render/RendererRegistry.h"
#include "server/RendererCache.h"

#include <gtest/gtest.h>

#include <chrono>
#include <cstdint>
#include <vector>

namespace bc::server {
namespace {

render::Box cube(double edgeMm) {
    render::Box box;
    box.max = glm::dvec3(edgeMm);
    return box;
}

/// A perspective view of `box` from 30 degrees azimuth, 20 elevation, close enough that some
/// rays miss it.
render::View viewOf(const render::Box& box, std::uint32_t width, std::uint32_t height) {
    return render::View::of(render::Camera::orbit(box, 30.0, 20.0, 1.2), width, height);
}

/// Slices of about `budget` until the frame is done, each checked against the rules of
/// SlicePlanner::next: it starts where the one before ended, lies in one row or is whole rows,
/// and its cost is what its pixels cost.
std::vector<Slice> sliceAll(SlicePlanner& p, std::uint32_t w, std::uint32_t h, double budget) {
    std::vector<Slice> slices;
    std::uint64_t cursor = 0;
    while (!p.done()) {
        const Slice s = p.next(budget);
        EXPECT_GE(s.region.pixels(), 1u) << "a slice of no pixel";
        EXPECT_EQ(std::uint64_t(s.region.y) * w + s.region.x, cursor) << "a gap or an overlap";
        EXPECT_TRUE(s.region.height == 1 || (s.region.x == 0 && s.region.width == w));
        EXPECT_LE(s.region.x + s.region.width, w);
        EXPECT_LE(s.region.y + s.region.height, h);
        double cost = 0;
        for (std::uint32_t y = s.region.y; y < s.region.y + s.region.height; ++y)
            for (std::uint32_t x = s.region.x; x < s.region.x + s.region.width; ++x)
                cost += p.pixelCost(x, y);
        EXPECT_NEAR(s.cost, cost, 1e-9 * cost);
        cursor += s.region.pixels();
        slices.push_back(s);
        if (slices.size() > std::size_t(w) * h) {
            ADD_FAILURE() << "more slices than pixels";
            break;
        }
    }
    EXPECT_EQ(cursor, std::uint64_t(w) * h) << "the slices do not cover the frame";
    return slices;
}

TEST(SlicePlannerTest, SlicesCoverTheFrameExactlyOnce) {
    const render::Box box = cube(64);
    for (const auto& [w, h] : std::vector<std::pair<std::uint32_t, std::uint32_t>>{
             {1, 1}, {7, 5}, {64, 48}, {1, 30}, {30, 1}}) {
        SlicePlanner probe(viewOf(box, w, h), box, 1.0);
        const double row = probe.rowCost(0);
        for (const double budget : {0.0, 1.0, row / 3, 2.5 * row, 1e300}) {
            SlicePlanner p(viewOf(box, w, h), box, 1.0);
            std::vector<int> covered(std::size_t(w) * h, 0);
            for (const Slice& s : sliceAll(p, w, h, budget))
                for (std::uint32_t y = s.region.y; y < s.region.y + s.region.height; ++y)
                    for (std::uint32_t x = s.region.x; x < s.region.x + s.region.width; ++x)
                        ++covered[std::size_t(y) * w + x];
            for (std::size_t i = 0; i < covered.size(); ++i)
                ASSERT_EQ(covered[i], 1)
                    << w << "x" << h << ", budget " << budget << ", pixel " << i;
        }
    }
}

TEST(SlicePlannerTest, ASliceFitsItsBudgetAtAKnownSpeedAndTakesAllThatFits) {
    const render::Box box = cube(64);
    RendererSpeeds speeds;
    speeds.learn("cpu", 4000.0, 10.0);            // 400 cost units a millisecond
    const double budget = 2.0 * speeds.of("cpu"); // 800 units
    SlicePlanner p(viewOf(box, 40, 30), box, 0.5);
    ASSERT_LT(budget, p.rowCost(15)) << "a row through the volume is over a slice: runs too";
    bool wholeRows = false, runs = false;
    for (const Slice& s : sliceAll(p, 40, 30, budget)) {
        const render::PixelRect& r = s.region;
        if (r.pixels() > 1) {
            EXPECT_LE(s.cost, budget);
        }
        if (r.x == 0 && r.width == 40 && r.height >= 1 && s.cost <= budget) {
            wholeRows = true;
            // Rows are taken while the next fits.
            if (r.y + r.height < 30) {
                EXPECT_GT(s.cost + p.rowCost(r.y + r.height), budget);
            }
        } else {
            runs = true;
            if (r.x + r.width < 40) {
                EXPECT_GT(s.cost + p.pixelCost(r.x + r.width, r.y), budget);
            }
        }
    }
    EXPECT_TRUE(wholeRows) << "rows that miss the volume are cheap: several go in a slice";
    EXPECT_TRUE(runs);
}

TEST(SlicePlannerTest, APixelCostsItsRaysSamplesInsideTheBoxPlusOne) {
    // Looking down z at a 10 mm cube from 10 mm above it, 3x3 pixels 20/3 mm apart: the middle
    // ray crosses 10 mm, the others miss.
    const render::Box box = cube(10);
    render::Camera camera;
    camera.eye = {5, 5, 20};
    camera.target = {5, 5, 0};
    camera.up = {0, 1, 0};
    camera.orthographic = true;
    camera.orthoHeight = 20;
    SlicePlanner p(render::View::of(camera, 3, 3), box, 0.5);
    EXPECT_DOUBLE_EQ(p.pixelCost(1, 1), 1.0 + 10.0 / 0.5);
    EXPECT_DOUBLE_EQ(p.pixelCost(0, 1), 1.0);
    EXPECT_DOUBLE_EQ(p.pixelCost(2, 2), 1.0);
    EXPECT_DOUBLE_EQ(p.rowCost(1), 1.0 + 21.0 + 1.0);
    EXPECT_DOUBLE_EQ(p.rowCost(0), 3.0);
}

TEST(SlicePlannerTest, AOneByOneFrameIsOneSliceWhateverTheBudget) {
    const render::Box box = cube(8);
    for (const double budget : {0.0, 1e-9, 1e300}) {
        SlicePlanner p(viewOf(box, 1, 1), box, 1.0);
        ASSERT_FALSE(p.done());
        const Slice s = p.next(budget);
        EXPECT_EQ(s.region, (render::PixelRect{0, 0, 1, 1}));
        EXPECT_TRUE(p.done());
    }
}

TEST(SlicePlannerTest, ABudgetUnderOneRowTakesRunsWithinARow) {
    const render::Box box = cube(64);
    SlicePlanner probe(viewOf(box, 32, 24), box, 1.0);
    double cheapest = probe.rowCost(0);
    for (std::uint32_t y = 1; y < 24; ++y)
        cheapest = std::min(cheapest, probe.rowCost(y));
    SlicePlanner p(viewOf(box, 32, 24), box, 1.0);
    for (const Slice& s : sliceAll(p, 32, 24, 0.5 * cheapest))
        EXPECT_EQ(s.region.height, 1u);
}

TEST(SlicePlannerTest, SpeedsFollowTheReportedDurations) {
    RendererSpeeds speeds;
    EXPECT_EQ(speeds.of("cpu"), RendererSpeeds::kFirstCostPerMs) << "before anything is drawn";
    speeds.learn("cpu", 1000.0, 10.0);
    EXPECT_DOUBLE_EQ(speeds.of("cpu"), 100.0) << "the first measure is taken as it is";
    speeds.learn("cpu", 500.0, 10.0);
    EXPECT_DOUBLE_EQ(speeds.of("cpu"), 50.0) << "slower: believed at once";
    speeds.learn("cpu", 1000.0, 10.0);
    EXPECT_DOUBLE_EQ(speeds.of("cpu"), 75.0) << "faster: half way";
    speeds.learn("gpu", 1.0, 0.0);
    EXPECT_DOUBLE_EQ(speeds.of("gpu"), 100.0) << "no time at all counts as 0.01 ms";
    EXPECT_DOUBLE_EQ(speeds.of("cpu"), 75.0) << "renderers are kept apart";
    EXPECT_EQ(speeds.of("splat"), RendererSpeeds::kFirstCostPerMs);
}

TEST(SlicePlannerTest, AZeroSpeedTakesAPixelASliceAndAHugeOneTheWholeFrame) {
    const render::Box box = cube(32);
    RendererSpeeds speeds;
    speeds.learn("stuck", 0.0, 100.0);
    speeds.learn("fast", 1e300, 1.0);
    ASSERT_EQ(speeds.of("stuck"), 0.0);
    SlicePlanner stuck(viewOf(box, 6, 4), box, 1.0);
    const auto pixels = sliceAll(stuck, 6, 4, 50.0 * speeds.of("stuck"));
    EXPECT_EQ(pixels.size(), 24u);
    SlicePlanner fast(viewOf(box, 6, 4), box, 1.0);
    const auto whole = sliceAll(fast, 6, 4, 50.0 * speeds.of("fast"));
    ASSERT_EQ(whole.size(), 1u);
    EXPECT_EQ(whole.front().region, (render::PixelRect{0, 0, 6, 4}));
    // Whether a frame is sliced at all: when it would take over one and a half slices.
    EXPECT_TRUE(drawnInSlices(1000.0, 10.0, 50.0)); // 100 ms
    EXPECT_FALSE(drawnInSlices(700.0, 10.0, 50.0)); // 70 ms
    EXPECT_TRUE(drawnInSlices(1.0, 0.0, 50.0));     // never drawn that fast
    EXPECT_FALSE(drawnInSlices(1e12, 1e300, 50.0));
}

TEST(SlicePlannerTest, AFramesCostIsItsPixelsLongestRaysOrItsVoxels) {
    render::LevelGeometry g;
    g.dims = {10, 20, 30};
    g.spacing = {1.0, 1.0, 2.0};
    g.box.max = {10.0, 20.0, 60.0}; // diagonal sqrt(4100) = 64.03 mm
    render::RenderOptions o;
    o.width = 100;
    o.height = 50;
    o.stepVoxels = 0.5; // 0.5 mm
    const FrameCost rays = frameCost(g, o, false);
    EXPECT_EQ(rays.perPixel, 129u); // ceil(128.06)
    EXPECT_DOUBLE_EQ(rays.total, 5000.0 * 129.0);
    const FrameCost voxels = frameCost(g, o, true);
    EXPECT_DOUBLE_EQ(voxels.total, 6000.0 + 5000.0);
}

TEST(SlicePlannerTest, PastePutsAPartsPixelsInTheirPlace) {
    const std::uint32_t w = 5, h = 4;
    std::vector<std::uint8_t> frame(std::size_t(w) * h * 4, 7);
    render::Image part(2, 3);
    for (std::uint32_t y = 0; y < 3; ++y)
        for (std::uint32_t x = 0; x < 2; ++x)
            for (int c = 0; c < 4; ++c)
                part.pixel(x, y)[c] = float(10 * y + x + c) / 255.0f;
    const render::PixelRect at{2, 1, 2, 3};
    paste(frame, w, part, at);
    const std::vector<std::uint8_t> bytes = render::toRgba8(part);
    for (std::uint32_t y = 0; y < h; ++y)
        for (std::uint32_t x = 0; x < w; ++x)
            for (int c = 0; c < 4; ++c) {
                const bool inside = x >= 2 && x < 4 && y >= 1 && y < 4;
                const std::uint8_t want =
                    inside ? bytes[(std::size_t(y - 1) * 2 + (x - 2)) * 4 + c] : 7;
                ASSERT_EQ(frame[(std::size_t(y) * w + x) * 4 + c], want) << x << "," << y;
            }
}

TEST(SlicePlannerTest, TheBandsOfACheckFrameCoverItsRowsInWholeLatticeRows) {
    const render::Box box = cube(64);
    for (const std::uint32_t stride : {2u, 3u}) {
        const render::PixelLattice lattice{stride};
        SlicePlanner p(viewOf(box, 40, 31), box, 1.0);
        for (const double budget : {1e-9, 0.5 * p.rowCost(15), 1e300}) {
            std::uint32_t row = 0, bands = 0;
            while (row < 31) {
                const std::uint32_t rows = p.checkRows(lattice, row, budget);
                ASSERT_GE(lattice.first(row + rows), lattice.first(row) + 1) << "no lattice row";
                ASSERT_TRUE(row + rows == 31 ||
                            lattice.pixel(lattice.first(row + rows)) == row + rows)
                    << "a band ends between lattice rows";
                row += rows;
                ++bands;
            }
            EXPECT_EQ(row, 31u);
            if (budget > 1e299) {
                EXPECT_EQ(bands, 1u);
            }
            if (budget < 1e-8) {
                EXPECT_EQ(bands, lattice.first(31)) << "one lattice row a band";
            }
        }
    }
}

/// A frame of `w` x `h` drawn in slices by drawNext, with a draw that writes each pixel's
/// coordinates and a clock that moves 0.1 ms a pixel drawn.
struct FakeSlicedFrame {
    FakeSlicedFrame(std::uint32_t w, std::uint32_t h) {
        const render::Box box = cube(64);
        d.kind = render::RendererRegistry::builtin().find("cpu");
        d.options.width = w;
        d.options.height = h;
        d.view = viewOf(box, w, h);
        d.cost = 1000000;
        d.slicing.emplace(d.view, box, 1.0);
        d.rgba8.assign(std::size_t(w) * h * 4, 0);
        d.sliceTargetMs = 50;
        hooks.draw = [this](const render::RenderOptions& o, render::FrameStats& stats) {
            const render::PixelRect r =
                o.region.whole() ? render::PixelRect{0, 0, o.width, o.height} : o.region;
            render::Image image(r.width, r.height);
            for (std::uint32_t y = 0; y < r.height; ++y)
                for (std::uint32_t x = 0; x < r.width; ++x) {
                    image.pixel(x, y)[0] = float(r.x + x) / 255.0f;
                    image.pixel(x, y)[1] = float(r.y + y) / 255.0f;
                    image.pixel(x, y)[3] = 1.0f;
                }
            stats = {};
            stats.samples = r.pixels();
            clock += std::chrono::microseconds(100 * r.pixels());
            ++draws;
            return image;
        };
        hooks.sliceMs = [] { return 50.0; };
        hooks.now = [this] { return clock; };
        hooks.sliceDrawn = [this] { ++slicesCounted; };
        hooks.checkDrawn = [] {};
        hooks.frameSpeeds = &frameSpeeds;
        hooks.sliceSpeeds = &sliceSpeeds;
    }
    FrameDrawing d;
    SliceHooks hooks;
    RendererSpeeds frameSpeeds, sliceSpeeds;
    std::chrono::steady_clock::time_point clock{};
    int draws = 0, slicesCounted = 0;
};

TEST(SlicePlannerTest, AFrameDrawnSliceBySliceIsWholeAndTimedByTheGivenClock) {
    const std::uint32_t w = 24, h = 18;
    FakeSlicedFrame f(w, h);
    f.sliceSpeeds.learn("cpu", 50.0, 50.0); // 1 cost unit a ms: the first slice is short
    int turns = 0;
    while (!drawNext(f.d, f.hooks))
        ASSERT_LT(++turns, int(w * h)) << "the frame never completes";
    EXPECT_GT(f.draws, 1) << "it was not sliced";
    EXPECT_EQ(f.slicesCounted, f.draws);
    EXPECT_EQ(f.d.stats.samples > 0, true);
    for (std::uint32_t y = 0; y < h; ++y)
        for (std::uint32_t x = 0; x < w; ++x) {
            const std::uint8_t* px = &f.d.rgba8[(std::size_t(y) * w + x) * 4];
            ASSERT_EQ(px[0], x) << x << "," << y;
            ASSERT_EQ(px[1], y) << x << "," << y;
            ASSERT_EQ(px[3], 255);
        }
    // 0.1 ms a pixel on the given clock, and the whole frame's speed learnt from that time.
    EXPECT_NEAR(f.d.slicesMs, 0.1 * w * h, 1e-6);
    EXPECT_DOUBLE_EQ(f.d.drawMs, f.d.slicesMs);
    EXPECT_DOUBLE_EQ(f.frameSpeeds.of("cpu"), 1000000.0 / f.d.slicesMs);
    EXPECT_NE(f.sliceSpeeds.of("cpu"), 1.0) << "the slices' speed was not learnt";
}

TEST(SlicePlannerTest, AFrameNotSlicedIsDrawnWholeInOneTurn) {
    FakeSlicedFrame f(8, 6);
    f.d.slicing.reset();
    EXPECT_TRUE(drawNext(f.d, f.hooks));
    EXPECT_EQ(f.draws, 1);
    EXPECT_EQ(f.slicesCounted, 0);
    EXPECT_EQ(f.d.rgba8.size(), 8u * 6u * 4u);
    EXPECT_EQ(f.d.rgba8[(5 * 8 + 7) * 4], 7);
    EXPECT_NEAR(f.d.drawMs, 0.1 * 48, 1e-9);
    EXPECT_DOUBLE_EQ(f.frameSpeeds.of("cpu"), 1000000.0 / f.d.drawMs);
}

} // namespace
} // namespace bc::server
