// The order rank 0 sends every rank for a slice: what it encodes is what a rank decodes, field
// for field, and a torn or out-of-range order is refused with the field named.
#include "server/ClusterOrder.h"

#include <gtest/gtest.h>

namespace bc::server {
namespace {

ClusterOrder anOrder() {
    ClusterOrder o;
    o.volume = "cthead";
    o.renderer = "gpu";
    o.camera.eye = {1.5, -2.25, 3.0};
    o.camera.target = {0.1, 0.2, 0.3};
    o.camera.up = {0, 0, 1};
    o.camera.fovYDeg = 27.5;
    o.camera.orthoHeight = 4.0;
    o.tf.kind = protocol::TfKind::Preset;
    o.tf.preset = "ct-bone";
    render::RenderOptions& r = o.options;
    r.width = 96;
    r.height = 64;
    r.region = {8, 16, 40, 12};
    r.stepVoxels = 0.125; // a refinement pass's
    r.earlyTermination = false;
    r.ertThreshold = 0.95;
    r.skip = render::SkipMode::Bricks;
    r.shading = false;
    r.level = 2;
    r.interactive = true;
    r.hardwareFilter = true;
    r.simd = false;
    r.packets = false;
    r.jitter = true;
    r.preintegrate = true;
    r.octree.ratioThreshold = 0.5;
    r.octree.levelLimit = 3;
    r.cellVoxels = 4;
    r.occlusionFrustums = false;
    r.occlusion.blockPixels = 8;
    r.occlusion.offFrames = 3;
    r.occlusion.probeEvery = 5;
    r.rayGuided = false;
    r.hostKeptBefore = 12345;
    return o;
}

void expectSame(const render::RenderOptions& a, const render::RenderOptions& b) {
    EXPECT_EQ(a.width, b.width);
    EXPECT_EQ(a.height, b.height);
    EXPECT_EQ(a.region, b.region);
    EXPECT_EQ(a.stepVoxels, b.stepVoxels);
    EXPECT_EQ(a.earlyTermination, b.earlyTermination);
    EXPECT_EQ(a.ertThreshold, b.ertThreshold);
    EXPECT_EQ(a.skip, b.skip);
    EXPECT_EQ(a.shading, b.shading);
    EXPECT_EQ(a.level, b.level);
    EXPECT_EQ(a.interactive, b.interactive);
    EXPECT_EQ(a.hardwareFilter, b.hardwareFilter);
    EXPECT_EQ(a.simd, b.simd);
    EXPECT_EQ(a.packets, b.packets);
    EXPECT_EQ(a.jitter, b.jitter);
    EXPECT_EQ(a.preintegrate, b.preintegrate);
    EXPECT_EQ(a.octree, b.octree);
    EXPECT_EQ(a.cellVoxels, b.cellVoxels);
    EXPECT_EQ(a.occlusionFrustums, b.occlusionFrustums);
    EXPECT_EQ(a.occlusion.blockPixels, b.occlusion.blockPixels);
    EXPECT_EQ(a.occlusion.offFrames, b.occlusion.offFrames);
    EXPECT_EQ(a.occlusion.probeEvery, b.occlusion.probeEvery);
    EXPECT_EQ(a.rayGuided, b.rayGuided);
    EXPECT_EQ(a.parts, b.parts);
    EXPECT_EQ(a.part, b.part);
    EXPECT_EQ(a.hostKeptBefore, b.hostKeptBefore);
    EXPECT_EQ(a.stride, b.stride);
    EXPECT_EQ(a.mode, b.mode);
    EXPECT_EQ(a.isoValue, b.isoValue);
    EXPECT_EQ(a.clip, b.clip);
}

TEST(ClusterOrder, EveryFieldArrivesAsSent) {
    const ClusterOrder sent = anOrder();
    const ClusterOrder got = decodeOrder(encodeOrder(sent));
    EXPECT_EQ(got.volume, sent.volume);
    EXPECT_EQ(got.renderer, sent.renderer);
    EXPECT_EQ(got.camera.eye, sent.camera.eye);
    EXPECT_EQ(got.camera.target, sent.camera.target);
    EXPECT_EQ(got.camera.up, sent.camera.up);
    EXPECT_EQ(got.camera.fovYDeg, sent.camera.fovYDeg);
    EXPECT_EQ(got.camera.orthographic, sent.camera.orthographic);
    EXPECT_EQ(got.camera.orthoHeight, sent.camera.orthoHeight);
    EXPECT_EQ(got.tf, sent.tf);
    expectSame(got.options, sent.options);
    // A mode and a cut travel too (only when the frame has them: ClusterOrder.cpp).
    ClusterOrder cut = anOrder();
    cut.options.preintegrate = false; // composite only
    cut.options.mode = render::BlendMode::Isosurface;
    cut.options.isoValue = 612.5;
    cut.options.clip.cropped = true;
    cut.options.clip.cropMin = {1, 2, 3};
    cut.options.clip.cropMax = {40, 50, 60};
    cut.options.clip.planeCount = 2;
    cut.options.clip.planes[0] = {{1, 0, 0}, -4};
    cut.options.clip.planes[1] = {{0, -0.5, 2}, 7};
    cut.options.clip.cap = true;
    expectSame(decodeOrder(encodeOrder(cut)).options, cut.options);
    EXPECT_GT(encodeOrder(cut).size(), encodeOrder(sent).size());
}

std::string errorOf(const std::vector<std::uint8_t>& bytes) {
    try {
        decodeOrder(bytes);
    } catch (const std::runtime_error& e) {
        return e.what();
    }
    return "";
}

TEST(ClusterOrder, ATornOrBadOrderIsRefusedNamingTheField) {
    const std::vector<std::uint8_t> bytes = encodeOrder(anOrder());
    // Cut anywhere: refused, never drawn.
    for (std::size_t n = 0; n < bytes.size(); ++n)
        EXPECT_NE(errorOf({bytes.begin(), bytes.begin() + std::ptrdiff_t(n)}), "") << n << " bytes";
    auto withBytes = [](std::vector<std::uint8_t> b) {
        b.push_back(0);
        return b;
    };
    EXPECT_NE(errorOf(withBytes(bytes)).find("bytes after"), std::string::npos);

    ClusterOrder o = anOrder();
    o.camera.target = o.camera.eye;
    EXPECT_NE(errorOf(encodeOrder(o)).find("cluster order:"), std::string::npos);
    o = anOrder();
    o.options.stepVoxels = 0;
    EXPECT_NE(errorOf(encodeOrder(o)).find("step"), std::string::npos);
    o = anOrder();
    o.options.region = {90, 0, 40, 12};
    EXPECT_NE(errorOf(encodeOrder(o)).find("region"), std::string::npos);

    // A flag of 2 (the camera's orthographic flag, after the names and 10 doubles).
    std::vector<std::uint8_t> b = bytes;
    const std::size_t flag = 1 + 6 + 1 + 3 + 8 * 10;
    ASSERT_LE(b[flag], 1);
    b[flag] = 2;
    EXPECT_NE(errorOf(b).find("camera.orthographic"), std::string::npos) << errorOf(b);
}

} // namespace
} // namespace bc::server
