// FrameStats of a frame drawn in slices: every field of each slice reaches the frame's sum, the
// work added up and the counts of bricks as the largest slice's.
#include "render/RenderTypes.h"

#include <gtest/gtest.h>

namespace bc::render {
namespace {

/// A slice's statistics with every field set: work `w`, counts of bricks `b`.
FrameStats slice(std::uint64_t w, std::uint64_t b, bool occlusion) {
    FrameStats s;
    s.level = 1;
    s.samples = w;
    s.oracleSamples = w + 1;
    s.bricksTotal = 100;
    s.bricksCulled = 50 - b;
    s.bricksSkipped = b;
    s.bricksVisited = b + 2;
    s.bricksConstant = b / 2;
    s.bricksUploaded = w + 2;
    s.bytesUploaded = w + 3;
    s.batches = std::uint32_t(w + 4);
    s.bricksEntered = b + 1;
    s.bricksDeferred = w + 5;
    s.bricksRequested = w + 6;
    s.resumePasses = std::uint32_t(w + 7);
    s.guidedFallback = occlusion;
    s.bricksUnreached = w + 8;
    s.hostKeptBytes = w + 9;
    s.octreeLeaps = w + 10;
    s.octreeBricksRebuilt = w + 11;
    s.octreeRebuildMs = double(w) + 12;
    s.cellBricksBuilt = w + 13;
    s.cellBuildMs = double(w) + 14;
    s.cellBricks = b + 3;
    s.occlusionUsed = occlusion;
    s.occlusionReason = occlusion ? "" : "first frame";
    s.occlusionFrustums = w + 15;
    s.occlusionTriangles = w + 16;
    s.occlusionBuildMs = double(w) + 17;
    s.samplesSavedByStart = w + 18;
    s.uploadMs = double(w) + 19;
    s.renderMs = double(w) + 20;
    s.readbackMs = double(w) + 21;
    s.totalMs = double(w) + 22;
    s.renderer = "gpu";
    return s;
}

TEST(FrameStats, ASlicedFrameSumsTheWorkOfEverySliceAndKeepsTheLargestBrickCounts) {
    FrameStats f = slice(100, 10, false);
    addSlice(f, slice(1000, 20, true));
    EXPECT_EQ(f.level, 1u);
    EXPECT_EQ(f.samples, 1100u);
    EXPECT_EQ(f.oracleSamples, 1102u);
    EXPECT_EQ(f.bricksTotal, 100u);
    EXPECT_EQ(f.bricksCulled, 30u);
    EXPECT_EQ(f.bricksSkipped, 20u);
    EXPECT_EQ(f.bricksVisited, 22u);
    EXPECT_EQ(f.bricksConstant, 10u);
    EXPECT_EQ(f.bricksUploaded, 1104u);
    EXPECT_EQ(f.bytesUploaded, 1106u);
    EXPECT_EQ(f.batches, 1108u);
    EXPECT_EQ(f.bricksEntered, 21u);
    EXPECT_EQ(f.bricksDeferred, 1110u);
    EXPECT_EQ(f.bricksRequested, 1112u);
    EXPECT_EQ(f.resumePasses, 1114u);
    EXPECT_TRUE(f.guidedFallback);
    EXPECT_EQ(f.bricksUnreached, 1116u);
    EXPECT_EQ(f.hostKeptBytes, 1118u);
    EXPECT_EQ(f.octreeLeaps, 1120u);
    EXPECT_EQ(f.octreeBricksRebuilt, 1122u);
    EXPECT_DOUBLE_EQ(f.octreeRebuildMs, 1124.0);
    EXPECT_EQ(f.cellBricksBuilt, 1126u);
    EXPECT_DOUBLE_EQ(f.cellBuildMs, 1128.0);
    EXPECT_EQ(f.cellBricks, 23u);
    EXPECT_TRUE(f.occlusionUsed);
    EXPECT_STREQ(f.occlusionReason, "");
    EXPECT_EQ(f.occlusionFrustums, 1130u);
    EXPECT_EQ(f.occlusionTriangles, 1132u);
    EXPECT_DOUBLE_EQ(f.occlusionBuildMs, 1134.0);
    EXPECT_EQ(f.samplesSavedByStart, 1136u);
    EXPECT_DOUBLE_EQ(f.uploadMs, 1138.0);
    EXPECT_DOUBLE_EQ(f.renderMs, 1140.0);
    EXPECT_DOUBLE_EQ(f.readbackMs, 1142.0);
    EXPECT_DOUBLE_EQ(f.totalMs, 1144.0);
    EXPECT_EQ(f.renderer, "gpu");
}

TEST(FrameStats, ASliceWithoutOcclusionKeepsTheReasonOfTheFirst) {
    FrameStats f = slice(1, 1, false);
    addSlice(f, slice(1, 1, false));
    EXPECT_FALSE(f.occlusionUsed);
    EXPECT_STREQ(f.occlusionReason, "first frame");
    EXPECT_FALSE(f.guidedFallback);
}

} // namespace
} // namespace bc::render
