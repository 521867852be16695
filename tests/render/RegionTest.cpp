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

#include <random>

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
