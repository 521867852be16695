// RenderOptions::region: the renderers that draw regions (all of them; the GPU renderers'
// tests are RegionGl in RegionGlTest.cpp and SplatRegionGlTest.cpp) give each
// pixel of a region exactly as in the whole frame, so a frame drawn in slices (how the daemon
// draws long frames) is the frame drawn whole; a slice of the splatter draws only the bricks
// that reach it; a region outside the image is refused, and so is any region by a renderer that
// draws whole images only.
#include "RenderTestSupport.h"
#include "render/CpuRaycaster.h"
#include "render/HybridSplatter.h"
#include "render/ReferenceRenderer.h"
#include "render/RendererRegistry.h"

#include <algorithm>
#include <random>
#include <utility>

namespace bc::render {
namespace {

using test::drawnInRegions;

TEST(Region, CpuRenderersDrawEachPixelOfARegionAsInTheWholeFrame) {
    auto t = test::ingestRealScan("cthead");
    if (!t) return test::missingData("scan cthead");
    const auto tf = TransferFunction::preset("ct-bone", t->stats);
    const Camera camera = Camera::orbit(LevelGeometry::of(*t->store, 0).box, 30, 20);
    RenderOptions o;
    o.width = 61; // odd sizes: no region lines up with the renderers' tiles
    o.height = 47;
    for (const char* name : {"cpu", "reference", "splat"}) {
        SCOPED_TRACE(name);
        const RendererKind* kind = RendererRegistry::builtin().find(name);
        ASSERT_TRUE(kind && kind->regions);
        auto renderer = kind->create();
        FrameStats stats;
        const Image whole = renderer->render(*t->store, *t->cache, tf, camera, o, stats);
        const Image sliced = drawnInRegions(*renderer, *t, tf, camera, o);
        const auto c = compareImages(sliced, whole);
        EXPECT_EQ(c.maxAbs, 0.0) << "a region changed pixels";
        EXPECT_GT(test::alphaSum(whole), 0.05 * o.width * o.height)
            << "the view shows almost nothing";
    }
}

// The splatter's paths, each bit for bit: points in slabs (a far camera), splats from the
// paper's (index, half angle) table, orthographic, one band drawn serially, occlusion culling
// off, early termination off.
TEST(Region, SplatterDrawsEachPixelOfARegionAsInTheWholeFrameOnEveryPath) {
    auto t = test::ingestRealScan("cthead");
    if (!t) return test::missingData("scan cthead");
    const auto tf = TransferFunction::preset("ct-skin", t->stats);
    const Box box = LevelGeometry::of(*t->store, 0).box;
    Camera ortho = Camera::orbit(box, 300, -25);
    ortho.orthographic = true;
    ortho.orthoHeight = 2.0 * box.radius();
    HybridSplatterConfig byIndex, serial, noCulling;
    byIndex.exactDistanceFootprint = false;
    serial.parallelDraw = false;
    noCulling.occlusionCulling = false;
    struct Case {
        const char* what;
        Camera camera;
        HybridSplatterConfig config;
        bool ert = true;
        bool points = false; ///< the view must draw points (slabs)
    };
    const std::vector<Case> cases = {
        {"points (far)", Camera::orbit(box, 30, 20, 3.0), {}, true, true},
        {"splats by index", Camera::orbit(box, 120, 10, 0.8), byIndex},
        {"orthographic", ortho, {}},
        {"serial", Camera::orbit(box, 200, 30), serial},
        {"no culling, no ert", Camera::orbit(box, 30, 20), noCulling, false},
    };
    RenderOptions o;
    o.width = 53;
    o.height = 41;
    for (const Case& c : cases) {
        SCOPED_TRACE(c.what);
        o.earlyTermination = c.ert;
        HybridSplatter splat(c.config);
        FrameStats stats;
        const Image whole = splat.render(*t->store, *t->cache, tf, c.camera, o, stats);
        const HybridSplatStats counts = splat.lastFrame();
        const Image sliced = drawnInRegions(splat, *t, tf, c.camera, o);
        EXPECT_EQ(compareImages(sliced, whole).maxAbs, 0.0) << "a region changed pixels";
        EXPECT_GT(test::alphaSum(whole), 0.01 * o.width * o.height) << "the view shows little";
        if (!c.points) continue;
        EXPECT_GT(counts.points, 1000u) << "the far view should draw points";
        EXPECT_GT(counts.slabs, 0u);
    }
}

// A slice costs what it covers: a thin band of rows draws fewer bricks and voxels than the whole
// frame (HostBudget.HybridSplatterSlices* counts the loads of a frame in slices).
TEST(Region, SplatterSlicesDrawOnlyTheBricksThatReachThem) {
    auto t = test::ingestRealScan("cthead");
    if (!t) return test::missingData("scan cthead");
    HybridSplatter splat;
    test::expectAThinSliceDrawsLess(splat, *t, TransferFunction::preset("ct-skin", t->stats),
                                    Camera::orbit(LevelGeometry::of(*t->store, 0).box, 30, 20));
}

// RenderOptions::stride: the CPU raycaster draws the rays of every stride-th pixel (the
// lattice's), each exactly as in the whole frame, on each of its paths (scalar, SIMD along
// rays, packets, pre-integrated; skipping none, bricks or all; jittered; in one batch or in
// several under a host budget of a few bricks, ray-guided or not), at odd sizes and strides;
// and takes fewer samples. What the daemon checks a first refinement pass against.
TEST(Region, AStrideDrawsEachLatticePixelAsInTheWholeFrame) {
    auto t = test::ingestRealScan("cthead");
    if (!t) return test::missingData("scan cthead");
    const auto tf = TransferFunction::preset("ct-skin", t->stats);
    const Camera camera = Camera::orbit(LevelGeometry::of(*t->store, 0).box, 30, 20);
    struct Case {
        const char* what;
        int loop; ///< 0 scalar, 1 SIMD along rays, 2 packets, 3 pre-integrated
        SkipMode skip = SkipMode::All;
        std::uint64_t budget = std::uint64_t(1) << 30;
        bool guided = true;
    };
    constexpr std::uint64_t kFewBricks = 1u << 20; // ~11 bricks of 36^3 u16
    const std::vector<Case> cases = {
        {"scalar", 0},
        {"simd", 1},
        {"packets", 2},
        {"pre-integrated", 3},
        {"packets, no skipping", 2, SkipMode::None},
        {"packets, bricks only", 2, SkipMode::Bricks},
        {"packets, a few bricks at a time", 2, SkipMode::All, kFewBricks, false},
        {"packets, a few bricks at a time, ray-guided", 2, SkipMode::All, kFewBricks, true},
        {"scalar, a few bricks at a time, ray-guided", 0, SkipMode::All, kFewBricks, true},
    };
    CpuRaycaster cpu;
    for (const Case& c : cases)
        for (const std::uint32_t stride : {2u, 3u, 4u, 7u}) {
            SCOPED_TRACE(std::string(c.what) + ", stride " + std::to_string(stride));
            RenderOptions o;
            o.width = 61; // odd: lattices that do not divide the image
            o.height = 47;
            o.jitter = true;
            o.simd = c.loop > 0;
            o.packets = c.loop == 2;
            o.preintegrate = c.loop == 3;
            o.skip = c.skip;
            o.rayGuided = c.guided;
            brickstore::BrickCache cache(*t->store, brickstore::BrickCacheConfig{c.budget});
            FrameStats wholeStats, sparseStats;
            const Image whole = cpu.render(*t->store, cache, tf, camera, o, wholeStats);
            o.stride = stride;
            const Image sparse = cpu.render(*t->store, cache, tf, camera, o, sparseStats);
            const PixelLattice l{stride};
            ASSERT_EQ(sparse.width, l.first(o.width));
            ASSERT_EQ(sparse.height, l.first(o.height));
            ASSERT_LT(l.pixel(sparse.width - 1), o.width);
            ASSERT_GE(l.pixel(sparse.width), o.width) << "a lattice pixel left out";
            int differing = 0;
            for (std::uint32_t j = 0; j < sparse.height; ++j)
                for (std::uint32_t i = 0; i < sparse.width; ++i)
                    differing += !std::equal(sparse.pixel(i, j), sparse.pixel(i, j) + 4,
                                             whole.pixel(l.pixel(i), l.pixel(j)));
            EXPECT_EQ(differing, 0) << "lattice pixels unlike the whole frame's";
            // In bands of rows (how the daemon draws it beside a sliced frame): the same.
            Image banded(sparse.width, sparse.height);
            for (const auto& [y0, y1] : {std::pair{0u, 10u}, {10u, 23u}, {23u, 47u}}) {
                o.region = {0, y0, o.width, y1 - y0};
                const Image band = cpu.render(*t->store, cache, tf, camera, o, sparseStats);
                const PixelRect at = *l.of(o.region);
                ASSERT_EQ(band.width, at.width);
                ASSERT_EQ(band.height, at.height);
                for (std::uint32_t j = 0; j < band.height; ++j)
                    std::copy_n(band.pixel(0, j), 4 * band.width, banded.pixel(0, at.y + j));
            }
            o.region = {};
            EXPECT_EQ(compareImages(banded, sparse).maxAbs, 0.0) << "bands unlike the whole";
            EXPECT_GT(test::alphaSum(sparse), 0.05 * sparse.width * sparse.height);
            EXPECT_LT(double(sparseStats.samples) * stride * stride,
                      2.0 * double(wholeStats.samples)); // a ray in stride^2
            if (c.budget == kFewBricks) {
                EXPECT_GT(sparseStats.batches, 1u);
            }
        }
    // A stride is drawn of the whole volume (one part), of a region that holds a pixel of its
    // lattice, and by the CPU raycaster only.
    RenderOptions o;
    o.width = o.height = 32;
    FrameStats stats;
    auto refused = [&](Renderer& r, const RenderOptions& bad, const char* why) {
        SCOPED_TRACE(std::string(r.name()) + ": " + why);
        try {
            r.render(*t->store, *t->cache, tf, camera, bad, stats);
            ADD_FAILURE() << "drawn";
        } catch (const std::invalid_argument& e) {
            EXPECT_NE(std::string(e.what()).find("stride"), std::string::npos) << e.what();
        }
    };
    RenderOptions bad = o;
    bad.stride = 0;
    refused(cpu, bad, "stride 0");
    bad.stride = 64; // its pixels start at 32
    refused(cpu, bad, "past the image");
    bad.stride = 4; // its pixels: 2, 6, 10...
    bad.region = {3, 0, 3, 32};
    refused(cpu, bad, "a region without a lattice pixel");
    bad.stride = 2;
    bad.region = {};
    bad.parts = 2;
    refused(cpu, bad, "a part");
    bad.parts = 1;
    ReferenceRenderer reference;
    HybridSplatter splat;
    refused(reference, bad, "the reference");
    refused(splat, bad, "the splatter");
    EXPECT_FALSE(RendererRegistry::builtin().find("gpu")->strided);
    EXPECT_TRUE(RendererRegistry::builtin().find("cpu")->strided);
}

TEST(Region, ARegionOutsideTheImageOrFromAWholeFrameRendererIsRefused) {
    auto t = test::ingestRealScan("cthead");
    if (!t) return test::missingData("scan cthead");
    const auto tf = TransferFunction::preset("ct-bone", t->stats);
    const Camera camera = Camera::orbit(LevelGeometry::of(*t->store, 0).box, 30, 20);
    RenderOptions o;
    o.width = o.height = 32;
    FrameStats stats;
    CpuRaycaster cpu;
    HybridSplatter splat;
    for (Renderer* r : {static_cast<Renderer*>(&cpu), static_cast<Renderer*>(&splat)})
        for (const PixelRect bad : {PixelRect{0, 0, 33, 1}, PixelRect{31, 0, 2, 1},
                                    PixelRect{0, 32, 1, 1}, PixelRect{0, 0, 1, 0}}) {
            SCOPED_TRACE(std::string(r->name()) + " " + std::to_string(bad.x) + "," +
                         std::to_string(bad.y) + " " + std::to_string(bad.width) + "x" +
                         std::to_string(bad.height));
            o.region = bad;
            try {
                r->render(*t->store, *t->cache, tf, camera, o, stats);
                ADD_FAILURE() << "a region outside the image was drawn";
            } catch (const std::invalid_argument& e) {
                EXPECT_NE(std::string(e.what()).find("region"), std::string::npos) << e.what();
            }
        }
    // A renderer that draws whole images only (checkView without drawsRegions) refuses any
    // region but the whole image, naming it.
    o.region = {0, 0, 8, 8};
    const View view = View::of(camera, o.width, o.height);
    try {
        Renderer::checkView(view, o);
        ADD_FAILURE() << "a whole-frame renderer accepted a region";
    } catch (const std::invalid_argument& e) {
        EXPECT_NE(std::string(e.what()).find("region"), std::string::npos) << e.what();
    }
    o.region = {};
    EXPECT_NO_THROW(Renderer::checkView(view, o));
}

// Culling by a region's own frustum is conservative: a box that any ray through a pixel of the
// region meets (ahead of the eye) is never outside it; and it culls what a whole-view plan
// keeps. Random boxes, regions and cameras, wide angles and orthographic included.
TEST(Region, ARegionsFrustumNeverCullsABoxOneOfItsRaysMeets) {
    std::mt19937 rng(16);
    std::uniform_real_distribution<double> unit(0.0, 1.0);
    std::uint64_t met = 0, culledByRegion = 0;
    for (int trial = 0; trial < 300; ++trial) {
        Camera camera;
        camera.eye = {unit(rng) * 4 - 2, unit(rng) * 4 - 2, unit(rng) * 4 - 2};
        camera.target = {unit(rng) - 0.5, unit(rng) - 0.5, unit(rng) - 0.5};
        camera.up = {0, 0, 1};
        camera.fovYDeg = 10 + 160 * unit(rng);
        camera.orthographic = trial % 3 == 0;
        camera.orthoHeight = 0.5 + 3 * unit(rng);
        const std::uint32_t w = 8 + rng() % 40, h = 8 + rng() % 40;
        const View view = View::of(camera, w, h);
        PixelRect region;
        region.x = rng() % w;
        region.y = rng() % h;
        region.width = 1 + rng() % (w - region.x);
        region.height = 1 + rng() % (h - region.y);
        for (int b = 0; b < 40; ++b) {
            Box box;
            box.min = {unit(rng) * 3 - 1.5, unit(rng) * 3 - 1.5, unit(rng) * 3 - 1.5};
            box.max = box.min + glm::dvec3(0.05 + 0.5 * unit(rng), 0.05 + 0.5 * unit(rng),
                                           0.05 + 0.5 * unit(rng));
            bool meets = false;
            for (std::uint32_t y = region.y; y < region.y + region.height && !meets; ++y)
                for (std::uint32_t x = region.x; x < region.x + region.width && !meets; ++x) {
                    const auto t = intersectBox(view.basis.ray(x, y, w, h), box);
                    meets = t[1] >= std::max(t[0], 0.0);
                }
            const bool outside = outsideRegion(box, view, region);
            if (meets) {
                ++met;
                ASSERT_FALSE(outside) << "trial " << trial << ", box " << b;
            }
            culledByRegion += outside && !outsideView(box, view.basis);
        }
    }
    EXPECT_GT(met, 500u);
    EXPECT_GT(culledByRegion, 500u) << "a region's frustum should cull more than the view's";
}

} // namespace
} // namespace bc::render
