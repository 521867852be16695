// The GPU splatter draws RenderOptions::region (GL: llvmpipe in CI, small images): a frame
// assembled from regions (rows, runs of a row, single pixels; odd sizes) is the whole frame to
// the bit, and a thin slice uploads and draws only what reaches it.
#include "RenderTestSupport.h"
#include "render/GpuSplatter.h"
#include "render/RendererRegistry.h"

namespace bc::render {
namespace {

TEST(RegionGl, GpuSplatterDrawsEachPixelOfARegionAsInTheWholeFrame) {
    auto t = test::ingestRealScan("cthead");
    if (!t) return test::missingData("scan cthead");
    test::glContext();
    const auto tf = TransferFunction::preset("ct-bone", t->stats);
    const Box box = LevelGeometry::of(*t->store, 0).box;
    const RendererKind* kind = RendererRegistry::builtin().find("splat-gpu");
    ASSERT_TRUE(kind && kind->regions);
    GpuSplatter splat;
    // Splats near, points in slabs far.
    for (const Camera& camera : {Camera::orbit(box, 30, 20), Camera::orbit(box, 30, 20, 3.0)}) {
        RenderOptions o;
        o.width = 61; // odd sizes: no region lines up with anything
        o.height = 47;
        FrameStats stats;
        const Image whole = splat.render(*t->store, *t->cache, tf, camera, o, stats);
        const Image sliced = test::drawnInRegions(splat, *t, tf, camera, o);
        EXPECT_EQ(compareImages(sliced, whole).maxAbs, 0.0) << "a region changed pixels";
        EXPECT_GT(test::alphaSum(whole), 0.01 * o.width * o.height) << "the view shows little";
    }
}

TEST(RegionGl, GpuSplatterSliceDrawsOnlyWhatReachesIt) {
    auto t = test::ingestRealScan("cthead");
    if (!t) return test::missingData("scan cthead");
    test::glContext();
    GpuSplatter splat;
    test::expectAThinSliceDrawsLess(splat, *t, TransferFunction::preset("ct-skin", t->stats),
                                    Camera::orbit(LevelGeometry::of(*t->store, 0).box, 30, 20));
}

} // namespace
} // namespace bc::render
