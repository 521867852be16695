// Interactive frames on a time budget (server/InteractiveBudget.h): the level and scale of a
// moving camera's frames follows the time its frames take. The controller is driven here by
// frame times from a cost model of its own (a fixed part and a part per drawn pixel, as the
// raycasters' frames have), so that what it decides is checked exactly, not timed.
#include "server/InteractiveBudget.h"
#include "ServerTestSupport.h"
#include "server/Catalog.h"
#include "server/ViewRequest.h"

#include <gtest/gtest.h>

#include <chrono>
#include <cmath>
#include <cstdint>
#include <thread>
#include <tuple>
#include <vector>

namespace bc::server {
namespace {

/// A frame's ms: `fixedMs` plus `perPixelMs` per drawn pixel at level 0, half that a level
/// coarser (a ray crosses half the samples).
struct Cost {
    double fixedMs, perPixelMs;
    double operator()(std::uint64_t pixels, std::uint32_t level = 0) const {
        return fixedMs + perPixelMs * std::ldexp(1.0, -int(level)) * double(pixels);
    }
};

struct Flown {
    std::uint32_t level, divisor;
    double ms;
};

const LevelRange kOneLevel{0, 0, {}, {}};

/// The divisor of the next frame at a single level.
std::uint32_t divisorOf(InteractiveBudget& budget, const std::string& volume,
                        const std::string& renderer, std::uint32_t width, std::uint32_t height) {
    return budget.choose(volume, renderer, width, height, kOneLevel).divisor;
}

/// `frames` interactive frames of (volume, renderer) at `edge`^2 under `budget`.
std::vector<Flown> fly(InteractiveBudget& budget, const std::string& volume, Cost cost, int frames,
                       std::uint32_t edge = 512, const LevelRange& levels = kOneLevel,
                       std::uint32_t sharers = 1) {
    std::vector<Flown> out;
    for (int i = 0; i < frames; ++i) {
        const InteractiveChoice c = budget.choose(volume, "cpu", edge, edge, levels, sharers);
        const std::uint64_t pixels = std::uint64_t(InteractiveBudget::drawnEdge(edge, c.divisor)) *
                                     InteractiveBudget::drawnEdge(edge, c.divisor);
        const double ms = cost(pixels, c.level);
        budget.record(volume, "cpu", c.level, pixels, ms);
        out.push_back({c.level, c.divisor, ms});
    }
    return out;
}

/// The time of the frame one divisor step larger than `d` (its image larger), or -1 at 1.
double nextLarger(Cost cost, std::uint32_t d, std::uint32_t edge = 512) {
    std::uint32_t previous = 0;
    for (const std::uint32_t c : InteractiveBudget::kDivisors) {
        if (c == d) break;
        previous = c;
    }
    if (previous == 0) return -1;
    const std::uint64_t e = InteractiveBudget::drawnEdge(edge, previous);
    return cost(e * e);
}

TEST(FrameBudget, NothingKnownDrawsHalfSizeAndACheapVolumeFullSize) {
    InteractiveBudget budget(66);
    EXPECT_EQ(divisorOf(budget, "v", "cpu", 512, 512), 2u);
    EXPECT_LT(budget.expectedMs("v", "cpu", 0, 1), 0.0);
    const auto frames = fly(budget, "v", {2.0, 1e-5}, 3);
    EXPECT_EQ(frames.back().divisor, 1u);
}

TEST(FrameBudget, MeetsTheTargetWithin25PercentAfterTenFramesOnAScanFourTimesLarger) {
    const double target = 66;
    for (const double fixedMs : {0.0, 5.0, 15.0}) {
        InteractiveBudget budget(target);
        const Cost small{fixedMs, 0.6e-3};     // 512^2 full size: 157 ms + fixed
        const Cost large{fixedMs * 4, 2.4e-3}; // four times the voxels: four times the work
        const auto first = fly(budget, "scan", small, 10);
        EXPECT_LE(first.back().ms, 1.25 * target) << "fixed " << fixedMs;
        // Then the same volume name serves a scan four times larger (reopened): the first
        // frames run late, and ten frames later the target holds again.
        const auto second = fly(budget, "scan", large, 10);
        EXPECT_GT(second.front().ms, target) << "the larger scan's first frame is late";
        for (std::size_t i = 4; i < second.size(); ++i)
            EXPECT_LE(second[i].ms, 1.25 * target) << "frame " << i << ", fixed " << fixedMs;
        // And the image is the largest that fits: the next larger one would not.
        const Flown last = second.back();
        const double larger = nextLarger(large, last.divisor);
        if (larger >= 0) {
            EXPECT_GT(larger, target) << "divisor " << last.divisor;
        }
    }
}

TEST(FrameBudget, ImageScaleGoesBeforeLevelAndLevelWhenScaleIsNotEnough) {
    const LevelRange four{0, 3, {}, {}};
    // 512^2 at level 0 takes 400 ms: a third of the edge (171^2, 44 ms) meets 66 ms at level 0.
    InteractiveBudget budget(66);
    auto frames = fly(budget, "v", {0.0, 400.0 / (512.0 * 512.0)}, 10, 512, four);
    EXPECT_EQ(frames.back().level, 0u);
    EXPECT_EQ(frames.back().divisor, 3u);
    // 25 times slower: even 64^2 at level 0 (156 ms) misses; level 1 (78 ms) too; level 2's
    // 64^2 (39 ms) meets it, and the larger images of level 2 do not.
    InteractiveBudget slow(66);
    frames = fly(slow, "v", {0.0, 10000.0 / (512.0 * 512.0)}, 12, 512, four);
    for (std::size_t i = 6; i < frames.size(); ++i) {
        EXPECT_EQ(frames[i].level, 2u) << "frame " << i;
        EXPECT_EQ(frames[i].divisor, 8u) << "frame " << i;
        EXPECT_LE(frames[i].ms, 66.0 * 1.25) << "frame " << i;
    }
}

TEST(FrameBudget, ALevelWhoseBricksDoNotFitTheHostShareIsPassedOver) {
    // Level 0 is over the volume's host cache share (every frame of it reloads bricks), level 1
    // fits: drawn at level 1 from the first frame, however cheap its rays look.
    InteractiveBudget budget(66);
    const LevelRange mosaic{0, 3, {false, true, true, true}, {}};
    const auto frames = fly(budget, "mosaic", {0.0, 1e-6}, 4, 512, mosaic);
    for (const Flown& f : frames)
        EXPECT_EQ(f.level, 1u);
    EXPECT_EQ(frames.front().divisor, InteractiveBudget::kFirstDivisor);
    EXPECT_EQ(frames.back().divisor, 1u);
    // When none fits, the coarsest.
    const LevelRange none{0, 2, {false, false, false}, {}};
    EXPECT_EQ(budget.choose("mosaic", "cpu", 512, 512, none).level, 2u);
    // A level the client asked for is the only one.
    EXPECT_EQ(budget.choose("mosaic", "cpu", 512, 512, {0, 0, {}, {}}).level, 0u);
}

TEST(FrameBudget, ALevelNotDrawnYetIsExpectedFromTheNearestDrawnOne) {
    InteractiveBudget budget(66);
    budget.record("v", "cpu", 1, 1000, 10.0);
    EXPECT_DOUBLE_EQ(budget.expectedMs("v", "cpu", 1, 1000), 10.0);
    EXPECT_DOUBLE_EQ(budget.expectedMs("v", "cpu", 0, 1000), 20.0); // twice a level finer
    EXPECT_DOUBLE_EQ(budget.expectedMs("v", "cpu", 3, 1000), 2.5);  // half a level coarser
    // Level 3 measured slower than expected (4 ms, not 2.5): believed at once, and level 1
    // moves by the same factor, 1.6.
    budget.record("v", "cpu", 3, 1000, 4.0);
    EXPECT_DOUBLE_EQ(budget.expectedMs("v", "cpu", 3, 1000), 4.0);
    EXPECT_DOUBLE_EQ(budget.expectedMs("v", "cpu", 1, 1000), 16.0);
    EXPECT_DOUBLE_EQ(budget.expectedMs("v", "cpu", 4, 1000), 2.0);
    EXPECT_DOUBLE_EQ(budget.expectedMs("v", "cpu", 2, 1000), 8.0); // level 1 and 3 as near: 1
    // Faster than expected: half way, and the others by the same factor (3 -> 2 ms: 0.5).
    budget.record("v", "cpu", 4, 1000, 0.0);
    EXPECT_NEAR(budget.expectedMs("v", "cpu", 4, 1000), 1.0, 1e-2);
    EXPECT_NEAR(budget.expectedMs("v", "cpu", 3, 1000), 2.0, 1e-2);
    EXPECT_NEAR(budget.expectedMs("v", "cpu", 1, 1000), 8.0, 1e-2);
}

TEST(FrameBudget, AfterASlowFrameTheBudgetComesBackToTheLevelItLeft) {
    // 512^2 at level 0 in 100 ms: half size meets 66 ms. One frame runs 5 s (caches gone cold,
    // the machine busy) and the budget drops to coarser levels; their fast frames bring every
    // level's rate down again, and within eight frames it is back at level 0, half size.
    const LevelRange four{0, 3, {}, {}};
    const Cost cost{0.0, 100.0 / (512.0 * 512.0)};
    InteractiveBudget budget(66);
    auto frames = fly(budget, "v", cost, 6, 512, four);
    ASSERT_EQ(frames.back().level, 0u);
    ASSERT_EQ(frames.back().divisor, 2u);
    const InteractiveChoice c = budget.choose("v", "cpu", 512, 512, four);
    const std::uint64_t e = InteractiveBudget::drawnEdge(512, c.divisor);
    budget.record("v", "cpu", c.level, e * e, 5000.0);
    EXPECT_GT(budget.choose("v", "cpu", 512, 512, four).level, 0u) << "the slow frame is believed";
    frames = fly(budget, "v", cost, 8, 512, four);
    EXPECT_EQ(frames.back().level, 0u);
    EXPECT_EQ(frames.back().divisor, 2u);
}

TEST(FrameBudget, TheLevelDrawnLastIsKeptWhileItsSmallestImageIsWithinTwiceTheTarget) {
    const LevelRange two{0, 1, {}, {}};
    const double pixels64 = 64.0 * 64.0; // 512^2 over 8
    // Level 0's smallest image at 1.5 x the target: kept (level 1 would have to load its
    // bricks); at 2.5 x: level 1.
    for (const auto& [times, level] : {std::pair<double, std::uint32_t>{1.5, 0}, {2.5, 1}}) {
        InteractiveBudget budget(66);
        budget.record("v", "cpu", 0, 4096, times * 66.0);
        const InteractiveChoice c = budget.choose("v", "cpu", 512, 512, two);
        EXPECT_EQ(c.level, level) << times << " x the target";
        if (level == 0) {
            EXPECT_EQ(c.divisor, 8u);
            EXPECT_NEAR(c.expectedMs, times * 66.0 * pixels64 / 4096.0, 1e-9);
        }
    }
    // Not drawn last: a level is taken only within the target.
    InteractiveBudget budget(66);
    budget.record("v", "cpu", 0, 4096, 1.5 * 66.0);
    // Level 1 drawn last, as fast as level 0 predicts (nothing moves): level 0 must now meet
    // the target, and does not.
    budget.record("v", "cpu", 1, 4096, 1.5 * 66.0 / 2.0);
    EXPECT_EQ(budget.choose("v", "cpu", 512, 512, two).level, 1u);
}

// A level whose bricks are not resident costs a long first frame to enter (its view's bricks
// loaded: over a second for the mosaic's level 1 on the dev VM, which every session waits
// for). One late frame does not send the budget there: only kColdEntryFrames choices in a row
// that want it do; a warm level is entered at once.
TEST(FrameBudget, AColdLevelIsEnteredOnlyWhenFramesInARowWantIt) {
    const double pixels64 = 64.0 * 64.0; // 512^2 over 8: level 0's smallest image
    for (const bool warm : {false, true}) {
        InteractiveBudget budget(66);
        const LevelRange two{0, 1, {}, {true, warm}};
        budget.record("v", "cpu", 0, 4096, 30.0); // level 0 at 64^2 in 30 ms: within 66
        ASSERT_EQ(budget.choose("v", "cpu", 512, 512, two).level, 0u);
        // One frame 10 times slower (another session's load): level 0's smallest image is
        // expected at 300 ms, over twice the target, and level 1 within it.
        budget.record("v", "cpu", 0, 4096, 300.0);
        for (std::uint32_t i = 1; i <= InteractiveBudget::kColdEntryFrames; ++i) {
            const InteractiveChoice c = budget.choose("v", "cpu", 512, 512, two);
            const bool entered = warm || i == InteractiveBudget::kColdEntryFrames;
            EXPECT_EQ(c.level, entered ? 1u : 0u) << "choice " << i << (warm ? " warm" : " cold");
            if (!entered) {
                EXPECT_EQ(c.divisor, 8u) << "level 0's smallest image meanwhile";
                EXPECT_NEAR(c.expectedMs, 300.0 * pixels64 / 4096.0, 1e-9);
            }
            if (warm) break;
        }
    }
    // The late frame was a one-off: the next level-0 frames are fast again, and the count of
    // choices wanting level 1 starts over.
    InteractiveBudget budget(66);
    const LevelRange two{0, 1, {}, {true, false}};
    budget.record("v", "cpu", 0, 4096, 30.0);
    for (int round = 0; round < 3; ++round) {
        budget.record("v", "cpu", 0, 4096, 300.0);
        for (std::uint32_t i = 1; i < InteractiveBudget::kColdEntryFrames; ++i)
            EXPECT_EQ(budget.choose("v", "cpu", 512, 512, two).level, 0u);
        budget.record("v", "cpu", 0, 4096, 1.0); // fast: half way down, within the target
        budget.record("v", "cpu", 0, 4096, 1.0);
        budget.record("v", "cpu", 0, 4096, 1.0);
        EXPECT_EQ(budget.choose("v", "cpu", 512, 512, two).level, 0u);
    }
}

TEST(FrameBudget, TimeWaitingForBricksIsNotTakenForTheRays) {
    InteractiveBudget budget(66);
    budget.record("v", "cpu", 0, 1000, 500.0, 490.0); // a cold frame: 490 ms of loading
    EXPECT_DOUBLE_EQ(budget.expectedMs("v", "cpu", 0, 1000), 10.0);
    budget.record("v", "cpu", 0, 1000, 5.0, 50.0); // load over the frame's time: clamped
    EXPECT_NEAR(budget.expectedMs("v", "cpu", 0, 1000), 5.0, 1e-3);
}

TEST(FrameBudget, SessionsMovingAtOnceShareTheTarget) {
    // 512^2 in 100 ms: alone, half size (25 ms) meets 66 ms and full size does not; four
    // sessions get 16.5 ms each, which a third of the edge (11 ms) meets.
    const Cost cost{0.0, 100.0 / (512.0 * 512.0)};
    InteractiveBudget budget(66);
    EXPECT_EQ(fly(budget, "v", cost, 6).back().divisor, 2u);
    const auto shared = fly(budget, "v", cost, 6, 512, kOneLevel, 4);
    EXPECT_EQ(shared.back().divisor, 3u);
    EXPECT_LE(shared.back().ms, 66.0 / 4);
}

TEST(FrameBudget, ASlowFrameIsBelievedAtOnceAFastOneByHalves) {
    InteractiveBudget budget(50);
    budget.record("v", "cpu", 0, 1000, 10.0); // 0.01 ms a pixel
    EXPECT_DOUBLE_EQ(budget.expectedMs("v", "cpu", 0, 1000), 10.0);
    budget.record("v", "cpu", 0, 1000, 40.0); // slower: taken as it is
    EXPECT_DOUBLE_EQ(budget.expectedMs("v", "cpu", 0, 1000), 40.0);
    budget.record("v", "cpu", 0, 1000, 20.0); // faster: half way
    EXPECT_DOUBLE_EQ(budget.expectedMs("v", "cpu", 0, 1000), 30.0);
    budget.record("v", "cpu", 0, 0, 1e9); // nothing drawn: nothing learnt
    EXPECT_DOUBLE_EQ(budget.expectedMs("v", "cpu", 0, 1000), 30.0);
}

TEST(FrameBudget, VolumesAndRenderersAreKeptApart) {
    InteractiveBudget budget(66);
    budget.record("heavy", "cpu", 0, 1000, 1000.0);
    budget.record("light", "cpu", 0, 1000, 0.001);
    EXPECT_EQ(divisorOf(budget, "heavy", "cpu", 512, 512), 8u);
    EXPECT_EQ(divisorOf(budget, "light", "cpu", 512, 512), 1u);
    EXPECT_EQ(divisorOf(budget, "heavy", "gpu", 512, 512), InteractiveBudget::kFirstDivisor);
}

TEST(FrameBudget, NoDrawnEdgeBelowTheMinimum) {
    InteractiveBudget budget(1);
    budget.record("v", "cpu", 0, 1, 1000.0);                // hopeless: the smallest image allowed
    EXPECT_EQ(divisorOf(budget, "v", "cpu", 512, 512), 8u); // 64^2
    EXPECT_EQ(divisorOf(budget, "v", "cpu", 64, 64), 4u);   // 16^2, not 11^2
    EXPECT_EQ(divisorOf(budget, "v", "cpu", 600, 40), 2u);  // 300x20, not 200x14
    EXPECT_EQ(divisorOf(budget, "v", "cpu", 8, 8), 1u);     // smaller than the minimum asked
    EXPECT_THROW(InteractiveBudget(0), std::invalid_argument);
}

TEST(FrameBudget, UpscaleReplicatesEachDrawnPixel) {
    // 5x3 drawn at divisor 3 for a 13x7 request, and at divisor 2 (the half-size frames) for a
    // 10x6 one: pixel (x, y) is drawn (x / d, y / d), the last row and column clipped to the
    // drawn image.
    const std::uint32_t dw = 5, dh = 3;
    std::vector<std::uint8_t> drawn(dw * dh * 4);
    for (std::uint32_t i = 0; i < dw * dh; ++i)
        for (int c = 0; c < 4; ++c)
            drawn[4 * i + c] = std::uint8_t(10 * i + c);
    for (const auto& [d, w, h] :
         {std::tuple<std::uint32_t, std::uint32_t, std::uint32_t>{3, 13, 7}, {2, 10, 6}}) {
        const std::vector<std::uint8_t> out = upscaleBy(drawn, dw, dh, w, h, d);
        ASSERT_EQ(out.size(), std::size_t(w) * h * 4);
        for (std::uint32_t y = 0; y < h; ++y)
            for (std::uint32_t x = 0; x < w; ++x) {
                const std::uint32_t from = std::min(y / d, dh - 1) * dw + std::min(x / d, dw - 1);
                for (int c = 0; c < 4; ++c)
                    ASSERT_EQ(out[(y * w + x) * 4 + c], drawn[4 * from + c])
                        << "divisor " << d << ": " << x << "," << y;
            }
    }
}

/// Interactive frames of a session at 65x47, sent as drawn: their drawn sizes, under the
/// server's `interactiveMs` and the session's own `sessionMs` (0: none sent).
std::vector<std::pair<int, int>> drawnSizes(std::uint32_t interactiveMs, int frames,
                                            std::uint16_t sessionMs = 0) {
    const test::TempDir dir;
    DaemonConfig c = test::generatedConfig(dir, {{"phantom", 32}});
    c.interactiveMs = interactiveMs;
    test::TestDaemon daemon(std::move(c));
    client::Client client(daemon.clientConfig());
    const auto info = client.openVolume("phantom");
    if (sessionMs > 0) client.setFrameBudget({sessionMs, 0});
    protocol::RenderOptions o = test::smallCpuFrames(65);
    o.height = 47;
    o.quality = protocol::Quality::Interactive;
    o.codec = protocol::Codec::Raw;
    o.flags = protocol::kFlagUnscaledInteractive;
    client.setRenderOptions(o);
    std::vector<std::pair<int, int>> sizes;
    for (int i = 0; i < frames; ++i) {
        client.setCamera(test::orbitCamera(info, 10.0 * i, std::uint32_t(i + 1)));
        client.requestFrame();
        const auto frame = client.nextFrame();
        EXPECT_FALSE(frame.header.refined);
        EXPECT_FALSE(frame.header.cached);
        sizes.emplace_back(frame.header.width, frame.header.height);
    }
    return sizes;
}

TEST(FrameBudget, TheDaemonDrawsInteractiveFramesAtTheScaleItsBudgetAllows) {
    // Without a budget: half size, rounded up, every frame.
    for (const auto& s : drawnSizes(0, 4))
        EXPECT_EQ(s, std::make_pair(33, 24));
    // With one that any frame of a 32^3 phantom meets: half size while nothing is known, then
    // the requested size.
    const auto sizes = drawnSizes(10000, 4);
    EXPECT_EQ(sizes.front(), std::make_pair(33, 24));
    for (std::size_t i = 1; i < sizes.size(); ++i)
        EXPECT_EQ(sizes[i], std::make_pair(65, 47)) << "frame " << i;
    // A session's own target (SetFrameBudget) where the server has none.
    const auto own = drawnSizes(0, 4, 10000);
    EXPECT_EQ(own.front(), std::make_pair(33, 24));
    for (std::size_t i = 1; i < own.size(); ++i)
        EXPECT_EQ(own[i], std::make_pair(65, 47)) << "frame " << i;
}

double counter(const std::vector<std::pair<std::string, double>>& stats, const std::string& name) {
    for (const auto& [n, v] : stats)
        if (n == name) return v;
    return -1;
}

/// A continuous adaptive session's frames after one camera, until `last` says stop (at most
/// `most` frames).
template <typename Last>
std::vector<client::ReceivedFrame> framesAtRest(client::Client& c, const protocol::VolumeInfo& v,
                                                Last last, std::size_t most = 12) {
    c.requestFrame(protocol::FrameMode::ContinuousOn);
    c.setCamera(test::orbitCamera(v, 30, 1));
    std::vector<client::ReceivedFrame> frames;
    while (frames.size() < most) {
        frames.push_back(c.nextFrame());
        if (last(frames.back())) break;
    }
    return frames;
}

/// A daemon serving a 48^3 phantom, and an adaptive CPU session of edge^2 frames on it under a
/// bound at rest of `boundDb`.
struct BoundedSession {
    test::TempDir dir;
    test::TestDaemon daemon;
    client::Client c;
    protocol::VolumeInfo v;

    BoundedSession(std::uint16_t edge, std::uint8_t boundDb)
        : daemon(test::generatedConfig(dir, {{"phantom", 48}})), c(daemon.clientConfig()),
          v(c.openVolume("phantom")) {
        protocol::RenderOptions o = test::smallCpuFrames(edge);
        o.quality = protocol::Quality::Adaptive;
        c.setRenderOptions(o);
        c.setFrameBudget({0, boundDb});
    }
    /// The refined frames after camera 1 comes to rest, until one's estimate reaches `boundDb`.
    std::vector<client::ReceivedFrame> refinedAtRest(std::uint8_t boundDb) {
        const auto frames = framesAtRest(c, v, [&](const client::ReceivedFrame& f) {
            return f.header.refined && f.header.estimatedPsnrDb >= boundDb;
        });
        std::vector<client::ReceivedFrame> refined;
        for (const auto& f : frames)
            if (f.header.refined) refined.push_back(f);
        return refined;
    }
};

TEST(FrameBudget, AtRestTheDaemonRefinesUntilTheEstimateMeetsTheBound) {
    BoundedSession s(64, 45);
    EXPECT_TRUE(s.c.server().capabilities & protocol::kCapFrameBudget);
    const std::vector<client::ReceivedFrame> refined = s.refinedAtRest(45);
    ASSERT_GE(refined.size(), 2u);
    EXPECT_EQ(refined.front().header.estimatedPsnrDb, 0) << "the first pass has no estimate";
    for (std::size_t i = 1; i < refined.size(); ++i) {
        EXPECT_GT(refined[i].header.estimatedPsnrDb, 0) << "pass " << i;
        EXPECT_EQ(refined[i].header.cameraId, 1u);
        EXPECT_EQ(refined[i].header.scale, 1);
        EXPECT_GT(refined[i].header.samples, refined[i - 1].header.samples) << "a finer step";
    }
    ASSERT_GE(refined.back().header.estimatedPsnrDb, 45);
    // The pass that met the bound was the last: no refined frame follows it.
    ASSERT_TRUE(test::renderIdle(s.c));
    EXPECT_EQ(counter(s.c.stats(), "frames_refined_total"), double(refined.size()));
    EXPECT_EQ(counter(s.c.stats(), "refinement_checks_total"), 0.0) << "64^2 is drawn whole";
}

// From 256^2 on, the first pass at rest is drawn at half the step and checked against a sparse
// frame at the step (render/RefinementEstimate.h): it carries its estimate, and the frames at
// rest reach the bound one pass sooner.
TEST(FrameBudget, AtRestALargeFramesFirstPassComesWithItsEstimate) {
    BoundedSession s(256, 45);
    const std::vector<client::ReceivedFrame> refined = s.refinedAtRest(45);
    ASSERT_GE(refined.size(), 1u);
    EXPECT_GT(refined.front().header.estimatedPsnrDb, 0) << "the first pass has its estimate";
    for (std::size_t i = 1; i < refined.size(); ++i)
        EXPECT_GT(refined[i].header.samples, refined[i - 1].header.samples) << "a finer step";
    ASSERT_GE(refined.back().header.estimatedPsnrDb, 45);
    ASSERT_TRUE(test::renderIdle(s.c));
    EXPECT_EQ(counter(s.c.stats(), "frames_refined_total"), double(refined.size()));
    EXPECT_EQ(counter(s.c.stats(), "refinement_checks_total"), 1.0);
    // Without a bound the frame at rest is one pass at the session's step, unchecked.
    s.c.setFrameBudget({0, 0});
    s.c.setCamera(test::orbitCamera(s.v, 60, 2));
    client::ReceivedFrame f = s.c.nextFrame();
    while (!(f.header.refined && f.header.cameraId == 2))
        f = s.c.nextFrame();
    EXPECT_EQ(f.header.estimatedPsnrDb, 0);
    // Nor at a step whose half would be finer than any pass may be (1/16 voxel): one pass at it.
    protocol::RenderOptions fine = test::smallCpuFrames(256);
    fine.quality = protocol::Quality::Adaptive;
    fine.stepVoxels = 0.1f;
    s.c.setRenderOptions(fine);
    s.c.setFrameBudget({0, 45});
    s.c.setCamera(test::orbitCamera(s.v, 90, 3));
    f = s.c.nextFrame();
    while (!(f.header.refined && f.header.cameraId == 3))
        f = s.c.nextFrame();
    EXPECT_EQ(f.header.estimatedPsnrDb, 0);
    ASSERT_TRUE(test::renderIdle(s.c));
    EXPECT_EQ(counter(s.c.stats(), "refinement_checks_total"), 1.0);
}

// The bound at rest holds in the other modes as in composite: a maximum, and an isosurface of
// a cropped volume, refine until their estimate meets it, each pass at a finer step.
TEST(FrameBudget, AtRestEveryModeRefinesUntilTheEstimateMeetsTheBound) {
    for (const auto mode : {protocol::BlendMode::Maximum, protocol::BlendMode::Isosurface}) {
        SCOPED_TRACE(int(mode));
        BoundedSession s(64, 40);
        protocol::SetModeAndClip m;
        m.mode = mode;
        if (mode == protocol::BlendMode::Isosurface) {
            m.isoValue = 0.5 * (s.v.valueMin + s.v.valueMax);
            m.cropped = true;
            for (int a = 0; a < 3; ++a)
                m.cropMax[a] = s.v.dims[a] * s.v.spacingMm[a] * (a == 0 ? 0.6 : 1.0);
        }
        s.c.setModeAndClip(m);
        const std::vector<client::ReceivedFrame> refined = s.refinedAtRest(40);
        ASSERT_GE(refined.size(), 2u);
        for (std::size_t i = 1; i < refined.size(); ++i) {
            EXPECT_GT(refined[i].header.estimatedPsnrDb, 0) << "pass " << i;
            EXPECT_GT(refined[i].header.samples, refined[i - 1].header.samples) << "a finer step";
        }
        EXPECT_GE(refined.back().header.estimatedPsnrDb, 40);
        const std::vector<std::uint8_t>& rgba = refined.back().rgba;
        bool shown = false;
        for (std::size_t p = 3; p < rgba.size(); p += 4)
            shown = shown || rgba[p] > 0;
        EXPECT_TRUE(shown) << "the view shows something";
        ASSERT_TRUE(test::renderIdle(s.c));
    }
}

TEST(FrameBudget, WithoutABoundOneRefinedFrameAndACameraThatMovesStopsTheRefinement) {
    const test::TempDir dir;
    test::TestDaemon daemon(test::generatedConfig(dir, {{"phantom", 48}}));
    client::Client c(daemon.clientConfig());
    const auto v = c.openVolume("phantom");
    protocol::RenderOptions o = test::smallCpuFrames(64);
    o.quality = protocol::Quality::Adaptive;
    c.setRenderOptions(o);
    framesAtRest(c, v, [](const client::ReceivedFrame& f) { return f.header.refined; });
    ASSERT_TRUE(test::renderIdle(c));
    EXPECT_EQ(counter(c.stats(), "frames_refined_total"), 1.0);
    // Under the highest bound, the camera moves as soon as the first estimate arrives: the
    // passes stop there, and the new view is drawn.
    c.setFrameBudget({0, 50});
    c.setCamera(test::orbitCamera(v, 60, 2));
    client::ReceivedFrame f = c.nextFrame();
    while (!(f.header.refined && f.header.estimatedPsnrDb > 0 && f.header.cameraId == 2))
        f = c.nextFrame();
    c.setCamera(test::orbitCamera(v, 90, 3));
    do
        f = c.nextFrame();
    while (f.header.cameraId != 3);
    // From camera 3's first frame on, no pass of camera 2 comes: its refinement stopped.
    for (int i = 0; i < 12 && !(f.header.refined && f.header.estimatedPsnrDb >= 50); ++i) {
        f = c.nextFrame();
        EXPECT_EQ(f.header.cameraId, 3u);
    }
}

/// A 32^3 phantom in bricks of 8 (levels of 32, 16 and 8 voxels) with a host cache of
/// `cacheBytes`, as the catalog would serve it.
struct LevelsVolume {
    test::TempDir dir;
    Volume v;
    explicit LevelsVolume(std::uint64_t cacheBytes) {
        auto source = brickstore::makeSynthetic(brickstore::SynthKind::Phantom, {32, 32, 32}, 1);
        brickstore::IngestConfig config;
        config.geometry = {8, 2, 4};
        brickstore::ingest(*source, dir.file("p.bcs"), config);
        v.name = "p";
        v.store = brickstore::BrickStore::open(dir.file("p.bcs"));
        v.cache = std::make_unique<brickstore::BrickCache>(
            *v.store, brickstore::BrickCacheConfig{cacheBytes});
    }
};

TEST(LevelFitting, ALevelsBytesAreItsStoredBricksDecompressed) {
    LevelsVolume p(64ull << 20);
    const auto levels = std::uint32_t(p.v.store->layout().levels().size());
    ASSERT_EQ(levels, 3u);
    for (std::uint32_t l = 0; l < levels; ++l) {
        EXPECT_GT(p.v.store->storedBricks(l), 0u) << "level " << l;
        EXPECT_EQ(levelBytes(p.v, l),
                  double(p.v.store->storedBricks(l)) * double(p.v.store->brickBytes()));
    }
    EXPECT_EQ(levelBytes(p.v, 7), levelBytes(p.v, 2)) << "past the last level: the last";
    EXPECT_GT(levelBytes(p.v, 0), levelBytes(p.v, 1));
}

TEST(LevelFitting, ALevelFitsWhenItsBytesAreWithinTheCacheShare) {
    LevelsVolume probe(64ull << 20);
    const double level1 = levelBytes(probe.v, 1);
    LevelsVolume p{std::uint64_t(level1)}; // exactly level 1's bytes
    EXPECT_FALSE(levelFits(p.v, 0));
    EXPECT_TRUE(levelFits(p.v, 1)) << "the bound is inclusive";
    EXPECT_TRUE(levelFits(p.v, 2));
    LevelsVolume tight{std::uint64_t(level1) - 1};
    EXPECT_FALSE(levelFits(tight.v, 1));
}

TEST(LevelFitting, InteractiveLevelsAreTheOneAskedForOrEveryLevelMarked) {
    LevelsVolume probe(64ull << 20);
    LevelsVolume p{std::uint64_t(levelBytes(probe.v, 1))};
    protocol::RenderOptions o;
    o.level = 1;
    LevelRange r = interactiveLevels(p.v, o);
    EXPECT_EQ(r.first, 1u);
    EXPECT_EQ(r.last, 1u);
    EXPECT_TRUE(r.fits.empty() && r.warm.empty());
    o.level = 9; // past the last level: the last
    r = interactiveLevels(p.v, o);
    EXPECT_EQ(r.first, 2u);
    EXPECT_EQ(r.last, 2u);
    o.level = protocol::kLevelAutomatic;
    r = interactiveLevels(p.v, o);
    EXPECT_EQ(r.first, 0u);
    EXPECT_EQ(r.last, 2u);
    EXPECT_EQ(r.fits, (std::vector<bool>{false, true, true}));
    EXPECT_EQ(r.warm, (std::vector<bool>{false, false, false})) << "nothing is resident yet";
    // The coarsest level's one brick loaded: that level is warm, the others not.
    ASSERT_EQ(p.v.store->layout().levels()[2].bricks, (std::array<std::uint32_t, 3>{1, 1, 1}));
    p.v.cache->pin(brickstore::BrickKey{2, {0, 0, 0}});
    r = interactiveLevels(p.v, o);
    EXPECT_EQ(r.warm, (std::vector<bool>{false, false, true}));
}

} // namespace
} // namespace bc::server
