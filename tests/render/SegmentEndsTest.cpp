// A maximum or minimum samples the two ends of the segment a ray keeps besides its lattice
// (render/MODES.md): a face that the lattice steps over is still seen, by every renderer and
// however a frame's bricks are batched.
#include "RenderTestSupport.h"

namespace bc::render {
namespace {

using test::TestStore;

/// 16 x 16 x 10 voxels of 100 but the first slice (z = 0), 10, and the last (z = 9), 200; in
/// bricks of 8, so the last slice's brick layer (z from 8) holds no sample of a lattice of 3
/// voxels along z (samples at z = 1.5, 4.5, 7.5: every one reads 100).
std::unique_ptr<TestStore> facesStore() {
    const std::uint64_t nx = 16, ny = 16, nz = 10;
    std::vector<std::uint8_t> voxels(nx * ny * nz, 100);
    for (std::uint64_t i = 0; i < nx * ny; ++i) {
        voxels[i] = 10;
        voxels[(nz - 1) * nx * ny + i] = 200;
    }
    return test::ingestVoxels(voxels, {nx, ny, nz}, {8, 2, 4});
}

/// Looking along +z through the middle of the volume, orthographic: every ray enters at z = 0
/// and leaves at z = 10.
Camera alongZ() {
    return test::orthoAlongZ(8.0, 8.0, 8.0);
}

RenderOptions stepOver(BlendMode mode) {
    RenderOptions o;
    o.width = o.height = 24;
    o.mode = mode;
    o.stepVoxels = 3.0;
    o.rayGuided = false; // batches by the budget alone
    return o;
}

/// The ramp runs from transparent black at 10 to opaque white at 200: a maximum that saw the
/// last slice is opaque white, a minimum that saw the first is transparent (the lattice alone
/// would give 100, alpha 0.47, for both).
void expectTheFaces(const Image& image, BlendMode mode, const std::string& what) {
    double lowest = 1.0, highest = 0.0;
    for (std::size_t i = 3; i < image.rgba.size(); i += 4) {
        lowest = std::min<double>(lowest, image.rgba[i]);
        highest = std::max<double>(highest, image.rgba[i]);
    }
    if (mode == BlendMode::Maximum)
        EXPECT_GT(lowest, 0.99) << what << ": the last slice missed";
    else
        EXPECT_LT(highest, 0.01) << what << ": the first slice missed";
}

Image underBudget(TestStore& t, Renderer& renderer, std::uint64_t budgetBytes,
                  const TransferFunction& tf, const RenderOptions& o, FrameStats& stats) {
    return test::underBudget(t, renderer, budgetBytes, tf, alongZ(), o, stats);
}

TEST(SegmentEnds, EveryCpuRendererSeesTheFacesTheLatticeStepsOverInOneBatchOrMany) {
    const auto t = facesStore();
    const TransferFunction tf = test::greyRamp(t->stats);
    const std::uint64_t twoBricks = 2 * t->store->brickBytes();
    for (const BlendMode mode : {BlendMode::Maximum, BlendMode::Minimum}) {
        SCOPED_TRACE(toString(mode));
        const RenderOptions o = stepOver(mode);
        expectTheFaces(test::referenceFrame(*t, tf, alongZ(), o), mode, "reference, whole");
        ReferenceRenderer reference;
        FrameStats refStats, refTiny;
        const Image ref = reference.render(*t->store, *t->cache, tf, alongZ(), o, refStats);
        expectTheFaces(ref, mode, "reference over bricks");
        const Image refBatched = underBudget(*t, reference, twoBricks, tf, o, refTiny);
        EXPECT_GE(refTiny.batches, 3u);
        EXPECT_LE(compareImages(refBatched, ref).maxAbs, 1e-6) << "reference in batches";
        FrameStats one, many;
        CpuRaycaster cpu;
        const Image whole = underBudget(*t, cpu, 1ull << 30, tf, o, one);
        expectTheFaces(whole, mode, "cpu");
        EXPECT_EQ(one.batches, 1u);
        EXPECT_GE(compareImages(whole, ref).psnrDb, 50.0);
        const Image batched = underBudget(*t, cpu, twoBricks, tf, o, many);
        EXPECT_GE(many.batches, 3u) << "the budget must force batches";
        EXPECT_EQ(compareImages(batched, whole).maxAbs, 0.0) << "cpu in batches";
        for (const bool alongRay : {false, true}) {
            RenderOptions other = o;
            other.simd = alongRay;
            other.packets = false;
            EXPECT_EQ(compareImages(test::cpuFrame(*t, tf, alongZ(), other), whole).maxAbs, 0.0)
                << (alongRay ? "SIMD along one ray" : "scalar march");
        }
        // Without skipping and early termination, the lattice takes three samples a ray and the
        // ends two more; with them, what cannot matter is left out (the same image): the ends,
        // taken first, reach the table's end (200 a maximum, 10 a minimum) and end the ray.
        RenderOptions plain = o;
        plain.skip = SkipMode::None;
        plain.earlyTermination = false;
        FrameStats all;
        EXPECT_EQ(compareImages(underBudget(*t, cpu, 1ull << 30, tf, plain, all), whole).maxAbs,
                  0.0);
        EXPECT_EQ(all.samples, std::uint64_t(o.width) * o.height * 5);
        EXPECT_LE(one.samples, all.samples);
    }
}

TEST(SegmentEndsGl, TheGpuRaycasterSeesThemInOnePassOrInBatches) {
    test::glContext();
    const auto t = facesStore();
    const TransferFunction tf = test::greyRamp(t->stats);
    const std::uint64_t e = t->store->layout().storedEdge();
    const std::uint64_t slot = e * e * e * brickstore::voxelBytes(t->store->info().volume.type);
    GpuRaycaster roomy, tight(GpuRaycasterConfig{2 * slot});
    for (const BlendMode mode : {BlendMode::Maximum, BlendMode::Minimum}) {
        SCOPED_TRACE(toString(mode));
        const RenderOptions o = stepOver(mode);
        FrameStats one, many;
        const Image whole = test::gpuFrame(*t, roomy, tf, alongZ(), o, &one);
        expectTheFaces(whole, mode, "gpu");
        EXPECT_GE(compareImages(whole, test::referenceFrame(*t, tf, alongZ(), o)).psnrDb, 50.0);
        const Image batched = test::gpuFrame(*t, tight, tf, alongZ(), o, &many);
        EXPECT_GE(many.batches, 3u) << "the pool must force batches";
        EXPECT_LE(compareImages(batched, whole).maxAbs, 1e-6) << "gpu in batches";
    }
}

} // namespace
} // namespace bc::render
