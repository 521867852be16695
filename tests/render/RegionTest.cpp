// RenderOptions::region: the renderers that draw regions (the CPU raycaster and the reference)
// give each pixel of a region exactly as in the whole frame, so a frame drawn in slices (how the
// daemon draws long frames) is the frame drawn whole; the others refuse a region.
#include "RenderTestSupport.h"
#include "render/CpuRaycaster.h"
#include "render/HybridSplatter.h"
#include "render/ReferenceRenderer.h"
#include "render/RendererRegistry.h"

#include <random>

namespace bc::render {
namespace {

/// The frame assembled from regions: whole rows, then runs of a row, as the daemon slices.
Image drawnInRegions(Renderer& r, test::TestStore& t, const TransferFunction& tf,
                     const Camera& camera, RenderOptions o) {
    Image frame(o.width, o.height);
    const std::vector<PixelRect> regions = {
        {0, 0, o.width, 5}, // rows
        {0, 5, 7, 1},
        {7, 5, o.width - 7, 1},            // a row in two runs
        {0, 6, o.width, o.height - 6 - 1}, // rows
        {0, o.height - 1, 1, 1},
        {1, o.height - 1, o.width - 1, 1}, // one pixel, then the rest
    };
    for (const PixelRect& rect : regions) {
        o.region = rect;
        FrameStats stats;
        const Image part = r.render(*t.store, *t.cache, tf, camera, o, stats);
        EXPECT_EQ(part.width, rect.width);
        EXPECT_EQ(part.height, rect.height);
        for (std::uint32_t y = 0; y < part.height; ++y)
            std::copy_n(part.pixel(0, y), std::size_t(part.width) * 4,
                        frame.pixel(rect.x, rect.y + y));
    }
    return frame;
}

TEST(Region, CpuRaycastersDrawEachPixelOfARegionAsInTheWholeFrame) {
    auto spec = test::realScan("cthead");
    if (!spec) return test::missingData("scan cthead");
    auto t = test::ingestSpec(*spec, {32, 2, 8});
    const auto tf = TransferFunction::preset("ct-bone", t->stats);
    const Camera camera = Camera::orbit(LevelGeometry::of(*t->store, 0).box, 30, 20);
    RenderOptions o;
    o.width = 61; // odd sizes: no region lines up with the renderers' tiles
    o.height = 47;
    for (const char* name : {"cpu", "reference"}) {
        SCOPED_TRACE(name);
        const RendererKind* kind = RendererRegistry::builtin().find(name);
        ASSERT_TRUE(kind && kind->regions);
        auto renderer = kind->create();
        FrameStats stats;
        const Image whole = renderer->render(*t->store, *t->cache, tf, camera, o, stats);
        const Image sliced = drawnInRegions(*renderer, *t, tf, camera, o);
        const auto c = compareImages(sliced, whole);
        EXPECT_EQ(c.maxAbs, 0.0) << "a region changed pixels";
        double alpha = 0;
        for (std::size_t i = 3; i < whole.rgba.size(); i += 4)
            alpha += whole.rgba[i];
        EXPECT_GT(alpha, 0.05 * o.width * o.height) << "the view shows almost nothing";
    }
}

TEST(Region, ARegionOutsideTheImageOrFromAWholeFrameRendererIsRefused) {
    auto spec = test::realScan("cthead");
    if (!spec) return test::missingData("scan cthead");
    auto t = test::ingestSpec(*spec, {32, 2, 8});
    const auto tf = TransferFunction::preset("ct-bone", t->stats);
    const Camera camera = Camera::orbit(LevelGeometry::of(*t->store, 0).box, 30, 20);
    RenderOptions o;
    o.width = o.height = 32;
    FrameStats stats;
    CpuRaycaster cpu;
    for (const PixelRect bad : {PixelRect{0, 0, 33, 1}, PixelRect{31, 0, 2, 1},
                                PixelRect{0, 32, 1, 1}, PixelRect{0, 0, 1, 0}}) {
        o.region = bad;
        EXPECT_THROW(cpu.render(*t->store, *t->cache, tf, camera, o, stats), std::invalid_argument);
    }
    o.region = {0, 0, 8, 8};
    HybridSplatter splat;
    try {
        splat.render(*t->store, *t->cache, tf, camera, o, stats);
        ADD_FAILURE() << "the splatter drew a region";
    } catch (const std::invalid_argument& e) {
        EXPECT_NE(std::string(e.what()).find("region"), std::string::npos) << e.what();
    }
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
