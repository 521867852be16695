// RenderOptions::region on the GPU raycaster: a region is drawn under a scissor on the
// full-size passes, so each of its pixels is exactly that pixel of the whole frame, with the
// pool large or small (one pass or many); a slice neither uses nor disturbs what whole frames
// keep (occlusion frustums, ray guidance).
#include "RenderTestSupport.h"
#include "render/GpuRaycaster.h"

namespace bc::render {
namespace {

/// The frame assembled from regions (test::drawnInRegions); each slice says it is one and
/// defers no brick (ray guidance is whole-frame state).
Image gpuInRegions(GpuRaycaster& r, test::TestStore& t, const TransferFunction& tf,
                   const Camera& camera, const RenderOptions& o, std::vector<FrameStats>* parts) {
    std::vector<FrameStats> own;
    std::vector<FrameStats>& stats = parts ? *parts : own;
    Image frame = test::drawnInRegions(r, t, tf, camera, o, &stats);
    for (const FrameStats& s : stats) {
        EXPECT_STREQ(s.occlusionReason, "a slice of a frame");
        EXPECT_EQ(s.bricksDeferred, 0u);
    }
    return frame;
}

std::uint64_t slotBytes(const test::TestStore& t) {
    const std::uint64_t e = t.store->layout().storedEdge();
    return e * e * e * brickstore::voxelBytes(t.store->info().volume.type);
}

TEST(RegionGl, GpuRaycasterDrawsEachPixelOfARegionAsInTheWholeFrame) {
    test::glContext();
    auto t = test::ingestRealScan("cthead");
    if (!t) return test::missingData("scan cthead");
    const auto tf = TransferFunction::preset("ct-bone", t->stats);
    const Camera camera = Camera::orbit(LevelGeometry::of(*t->store, 0).box, 30, 20);
    RenderOptions o;
    o.width = 61; // odd sizes: no region lines up with anything
    o.height = 47;
    // A pool of every brick (one pass), and one of 3 bricks (many passes, each a batch).
    const std::uint64_t bricks = LevelGeometry::of(*t->store, 0).brickCount();
    for (const std::uint64_t slots : {bricks, std::uint64_t(3)}) {
        SCOPED_TRACE(slots);
        GpuRaycaster gpu({slots * slotBytes(*t)});
        FrameStats whole;
        const Image image = gpu.render(*t->store, *t->cache, tf, camera, o, whole);
        std::vector<FrameStats> parts;
        const Image sliced = gpuInRegions(gpu, *t, tf, camera, o, &parts);
        EXPECT_EQ(compareImages(sliced, image).maxAbs, 0.0) << "a region changed pixels";
        EXPECT_GT(test::alphaSum(image), 0.05 * o.width * o.height)
            << "the view shows almost nothing";
        // The slices take the whole frame's samples between them, no more.
        std::uint64_t samples = 0;
        for (const FrameStats& s : parts)
            samples += s.samples;
        EXPECT_EQ(samples, whole.samples);
        if (slots == 3) {
            EXPECT_GT(parts[3].batches, 1u) << "the small pool drew one batch";
        }
        // The one-pixel region plans fewer bricks than the whole view.
        EXPECT_LT(parts[4].bricksVisited, whole.bricksVisited);
    }
}

// Slices between whole frames leave the whole frames as they were: the frame after them still
// starts its rays at the previous whole frame's occlusion frustums and is the image it would
// have been without the slices.
TEST(RegionGl, SlicesLeaveOcclusionFrustumsToWholeFrames) {
    test::glContext();
    auto t = test::ingestRealScan("cthead");
    if (!t) return test::missingData("scan cthead");
    const auto tf = TransferFunction::preset("ct-bone", t->stats);
    const Box box = LevelGeometry::of(*t->store, 0).box;
    RenderOptions o;
    o.width = o.height = 128; // rays denser than the occupancy cells
    GpuRaycaster withSlices, without;
    FrameStats s;
    for (GpuRaycaster* r : {&withSlices, &without})
        r->render(*t->store, *t->cache, tf, Camera::orbit(box, 30, 20), o, s);
    gpuInRegions(withSlices, *t, tf, Camera::orbit(box, 120, 20), o, nullptr);
    FrameStats a, b;
    const Image afterSlices =
        withSlices.render(*t->store, *t->cache, tf, Camera::orbit(box, 32, 20), o, a);
    const Image plain = without.render(*t->store, *t->cache, tf, Camera::orbit(box, 32, 20), o, b);
    EXPECT_TRUE(a.occlusionUsed) << a.occlusionReason;
    EXPECT_TRUE(b.occlusionUsed) << b.occlusionReason;
    EXPECT_EQ(a.samples, b.samples);
    EXPECT_EQ(compareImages(afterSlices, plain).maxAbs, 0.0);
}

} // namespace
} // namespace bc::render
