// Capping (Clip::cap, render/MODES.md "Capping"): a ray that enters what it keeps through a cut
// draws the cut's face first. On a solid of one value the face is what the optical model says,
// in every renderer and however a frame's bricks are batched; the volume's own faces and the
// faces where rays leave are not capped; on real scans the CPU and GPU raycasters draw the
// reference's capped image, skipping changes no pixel, and parts combine to the one-part frame.
#include "RenderTestSupport.h"
#include "render/Composite.h"
#include "render/Partition.h"

#include <glm/geometric.hpp>

namespace bc::render {
namespace {

using test::TestStore;

/// 16^3 voxels of 100 but the four edge columns along z (101, so that no brick is of one value;
/// 10 at the first voxel and 200 at the last, which set the values' range), in bricks of 8.
/// No ray of alongZ() reads the columns, nor does its gradient.
std::unique_ptr<TestStore> solidStore() {
    const std::uint64_t n = 16;
    std::vector<std::uint8_t> voxels(n * n * n, 100);
    for (std::uint64_t z = 0; z < n; ++z)
        for (const std::uint64_t y : {std::uint64_t(0), n - 1})
            for (const std::uint64_t x : {std::uint64_t(0), n - 1})
                voxels[(z * n + y) * n + x] = 101;
    voxels.front() = 10;
    voxels.back() = 200;
    return test::ingestVoxels(voxels, {n, n, n}, {8, 2, 4});
}

/// Looking along +z through the middle, orthographic: every ray enters at z = 0, through
/// x, y in [4, 12].
Camera alongZ() {
    return test::orthoAlongZ(8.0, 8.0, 8.0);
}

/// Keeps z >= 4.3 (a cut every ray enters through, face on), capped.
RenderOptions cutFaceOn(BlendMode mode) {
    RenderOptions o;
    o.width = o.height = 24;
    o.mode = mode;
    o.earlyTermination = false; // the face and what lies behind it, exactly
    o.rayGuided = false;        // batches by the budget alone
    o.clip.planeCount = 1;
    o.clip.planes[0] = {{0.0, 0.0, 1.0}, -4.3};
    o.clip.cap = true;
    return o;
}

/// The face of value 100 seen face on (|cos| = 1: lit = colour (ambient + diffuse) +
/// specular) over what the uncapped frame draws behind it, pixel by pixel. `iso`: the frame
/// is an isosurface at a value below 100 (the face opaque in the iso value's colour).
void expectTheFace(const Image& capped, const Image& uncapped, const TransferFunction& tf,
                   std::optional<double> iso, const std::string& what) {
    const auto f = tf.table(1.0).lookup(iso.value_or(100.0));
    const double a = iso ? 1.0 : double(f[3]);
    const double lift = ShadingModel::kAmbient + ShadingModel::kDiffuse;
    double worst = 0.0;
    for (std::size_t p = 0; p < capped.rgba.size(); p += 4) {
        for (int c = 0; c < 4; ++c) {
            const double face =
                c == 3 ? a : a * std::min(1.0, double(f[c]) * lift + ShadingModel::kSpecular);
            const double want = std::min(1.0, face + (1.0 - a) * uncapped.rgba[p + c]);
            worst = std::max(worst, std::abs(capped.rgba[p + c] - want));
        }
    }
    EXPECT_LE(worst, 2e-5) << what << ": the face is not the model's";
}

Image underBudget(TestStore& t, Renderer& renderer, std::uint64_t budgetBytes,
                  const TransferFunction& tf, const RenderOptions& o, FrameStats& stats) {
    return test::underBudget(t, renderer, budgetBytes, tf, alongZ(), o, stats);
}

TEST(CapRules, TheProjectionsRefuseACapAndTheEntryFaceIsTheCutsNormal) {
    RenderOptions o;
    o.clip.cap = true;
    o.clip.planeCount = 1;
    for (const BlendMode mode : {BlendMode::Maximum, BlendMode::Minimum, BlendMode::Average}) {
        o.mode = mode;
        EXPECT_EQ(test::refusal([&] {
                      o.validate();
                  }).rfind("cap: mode " + std::string(toString(mode)), 0),
                  0u);
    }
    for (const BlendMode mode : {BlendMode::Composite, BlendMode::Isosurface}) {
        o.mode = mode;
        EXPECT_NO_THROW(o.validate());
    }
    // Entering a crop box along +x then -x, and a plane (kept x >= 15) in front of the box.
    Clip c;
    c.cropped = true;
    c.cropMin = {10, 0, 0};
    c.cropMax = {20, 100, 100};
    glm::dvec3 n;
    EXPECT_DOUBLE_EQ(c.interval({0, 50, 50}, {1, 0, 0}, &n)[0], 10.0);
    EXPECT_EQ(n, glm::dvec3(1, 0, 0));
    EXPECT_DOUBLE_EQ(c.interval({30, 50, 50}, {-1, 0, 0}, &n)[0], 10.0);
    EXPECT_EQ(n, glm::dvec3(-1, 0, 0));
    c.planeCount = 1;
    c.planes[0] = {{2e200, 0, 0}, -30e200}; // a huge normal: unit all the same
    EXPECT_DOUBLE_EQ(c.interval({0, 50, 50}, {1, 0, 0}, &n)[0], 15.0);
    EXPECT_EQ(n, glm::dvec3(1, 0, 0));
    // Nothing bounds the start of a ray leaving through the plane only.
    Clip back;
    back.planeCount = 1;
    back.planes[0] = {{-1, 0, 0}, 15};
    EXPECT_LT(back.interval({0, 50, 50}, {1, 0, 0}, &n)[0], -1e300);
    EXPECT_EQ(n, glm::dvec3(0.0));
}

TEST(Capping, EveryCpuRendererDrawsTheModelsFaceInOneBatchOrMany) {
    const auto t = solidStore();
    const TransferFunction tf = test::greyRamp(t->stats);
    const std::uint64_t twoBricks = 2 * t->store->brickBytes();
    for (const BlendMode mode : {BlendMode::Composite, BlendMode::Isosurface}) {
        SCOPED_TRACE(toString(mode));
        RenderOptions o = cutFaceOn(mode);
        const bool iso = mode == BlendMode::Isosurface;
        o.isoValue = 50.0;
        RenderOptions uncut = o;
        uncut.clip.cap = false;
        const std::optional<double> isoValue = iso ? std::optional(50.0) : std::nullopt;
        const Image refWhole = test::referenceFrame(*t, tf, alongZ(), o);
        expectTheFace(refWhole, test::referenceFrame(*t, tf, alongZ(), uncut), tf, isoValue,
                      "reference, whole");
        ReferenceRenderer reference;
        FrameStats refStats, refTiny;
        const Image ref = reference.render(*t->store, *t->cache, tf, alongZ(), o, refStats);
        EXPECT_LE(compareImages(ref, refWhole).maxAbs, 1e-6) << "reference over bricks";
        if (!iso) { // an isosurface's reference reads the level whole
            const Image refBatched = underBudget(*t, reference, twoBricks, tf, o, refTiny);
            EXPECT_GE(refTiny.batches, 2u);
            EXPECT_LE(compareImages(refBatched, ref).maxAbs, 1e-6) << "reference in batches";
        }
        CpuRaycaster cpu;
        FrameStats one, many;
        const Image whole = underBudget(*t, cpu, 1ull << 30, tf, o, one);
        EXPECT_EQ(one.batches, 1u);
        expectTheFace(whole, test::cpuFrame(*t, tf, alongZ(), uncut), tf, isoValue, "cpu");
        EXPECT_GE(compareImages(whole, refWhole).psnrDb, 50.0);
        const Image batched = underBudget(*t, cpu, twoBricks, tf, o, many);
        EXPECT_GE(many.batches, 2u) << "the budget must force batches";
        EXPECT_EQ(compareImages(batched, whole).maxAbs, 0.0) << "cpu in batches";
        for (const bool alongRay : {false, true}) {
            RenderOptions other = o;
            other.simd = alongRay;
            other.packets = false;
            EXPECT_EQ(compareImages(test::cpuFrame(*t, tf, alongZ(), other), whole).maxAbs, 0.0)
                << (alongRay ? "SIMD along one ray" : "scalar march");
        }
        RenderOptions plain = o;
        plain.skip = SkipMode::None;
        EXPECT_EQ(compareImages(test::cpuFrame(*t, tf, alongZ(), plain), whole).maxAbs, 0.0)
            << "skipping off";
    }
}

TEST(Capping, OnlyTheFacesRaysEnterThroughInsideTheBoxAreCapped) {
    const auto t = solidStore();
    const TransferFunction tf = test::greyRamp(t->stats);
    for (const BlendMode mode : {BlendMode::Composite, BlendMode::Isosurface}) {
        SCOPED_TRACE(toString(mode));
        RenderOptions o = cutFaceOn(mode);
        o.isoValue = 50.0;
        // Rays leave through this plane (kept z <= 11.7) and enter through the box: no face.
        o.clip.planes[0] = {{0.0, 0.0, -1.0}, 11.7};
        RenderOptions uncapped = o;
        uncapped.clip.cap = false;
        EXPECT_EQ(compareImages(test::cpuFrame(*t, tf, alongZ(), o),
                                test::cpuFrame(*t, tf, alongZ(), uncapped))
                      .maxAbs,
                  0.0)
            << "a face rays leave through";
        // A crop box that is the volume's box: its faces are the volume's, not cuts.
        o.clip.planeCount = 0;
        o.clip.cropped = true;
        o.clip.cropMin = {0, 0, 0};
        o.clip.cropMax = {16, 16, 16};
        uncapped.clip = o.clip;
        uncapped.clip.cap = false;
        EXPECT_EQ(compareImages(test::referenceFrame(*t, tf, alongZ(), o),
                                test::referenceFrame(*t, tf, alongZ(), uncapped))
                      .maxAbs,
                  0.0)
            << "the volume's own face";
        // An isosurface above the face's value draws no face.
        if (mode == BlendMode::Isosurface) {
            RenderOptions high = cutFaceOn(mode);
            high.isoValue = 150.0;
            RenderOptions highUncapped = high;
            highUncapped.clip.cap = false;
            EXPECT_EQ(compareImages(test::cpuFrame(*t, tf, alongZ(), high),
                                    test::cpuFrame(*t, tf, alongZ(), highUncapped))
                          .maxAbs,
                      0.0);
        }
    }
}

TEST(CapGl, TheGpuRaycasterDrawsTheModelsFaceInOnePassOrInBatches) {
    test::glContext();
    const auto t = solidStore();
    const TransferFunction tf = test::greyRamp(t->stats);
    const std::uint64_t e = t->store->layout().storedEdge();
    const std::uint64_t slot = e * e * e * brickstore::voxelBytes(t->store->info().volume.type);
    GpuRaycaster roomy, tight(GpuRaycasterConfig{2 * slot});
    for (const BlendMode mode : {BlendMode::Composite, BlendMode::Isosurface}) {
        SCOPED_TRACE(toString(mode));
        RenderOptions o = cutFaceOn(mode);
        o.isoValue = 50.0;
        RenderOptions uncut = o;
        uncut.clip.cap = false;
        FrameStats one, many;
        const Image whole = test::gpuFrame(*t, roomy, tf, alongZ(), o, &one);
        expectTheFace(whole, test::gpuFrame(*t, roomy, tf, alongZ(), uncut), tf,
                      mode == BlendMode::Isosurface ? std::optional(50.0) : std::nullopt, "gpu");
        EXPECT_GE(compareImages(whole, test::referenceFrame(*t, tf, alongZ(), o)).psnrDb, 50.0);
        const Image batched = test::gpuFrame(*t, tight, tf, alongZ(), o, &many);
        EXPECT_GE(many.batches, 2u) << "the pool must force batches";
        EXPECT_LE(compareImages(batched, whole).maxAbs, 1e-6) << "gpu in batches";
    }
}

/// A crop box and an oblique plane through the centre, capped.
Clip cappedCut(const Box& box) {
    Clip clip;
    clip.cropped = true;
    for (int a = 0; a < 3; ++a) {
        clip.cropMin[a] = box.min[a] + 0.1 * box.size()[a];
        clip.cropMax[a] = box.min[a] + 0.8 * box.size()[a];
    }
    const glm::dvec3 n = glm::normalize(glm::dvec3(1, -0.5, 0.3));
    clip.planeCount = 1;
    clip.planes[0] = ClipPlane{{n.x, n.y, n.z}, -glm::dot(n, box.centre())};
    clip.cap = true;
    return clip;
}

// The daemon draws a long frame in slices (RenderOptions::region), a slice planning the bricks
// its own rays reach: each of a capped frame's pixels is the whole frame's, in every renderer
// that draws regions.
TEST(Capping, AFrameDrawnInSlicesIsTheWholeFrame) {
    auto source = brickstore::makeSynthetic(brickstore::SynthKind::Phantom, {96, 96, 96}, 1);
    const auto t = test::ingestStore(*source, {32, 2, 8});
    const TransferFunction ramp = test::greyRamp(t->stats);
    const Box box = LevelGeometry::of(*t->store, 0).box;
    RenderOptions o;
    o.width = o.height = 48;
    o.earlyTermination = false;
    o.clip = cappedCut(box);
    for (const double azimuth : {40.0, 160.0, 280.0}) {
        const Camera camera = Camera::orbit(box, azimuth, 4.0);
        CpuRaycaster cpu;
        ReferenceRenderer reference;
        FrameStats stats;
        const Image whole = test::cpuFrame(*t, ramp, camera, o);
        EXPECT_EQ(compareImages(test::drawnInRegions(cpu, *t, ramp, camera, o), whole).maxAbs, 0.0)
            << "cpu, azimuth " << azimuth;
        const Image ref = reference.render(*t->store, *t->cache, ramp, camera, o, stats);
        EXPECT_LE(compareImages(test::drawnInRegions(reference, *t, ramp, camera, o), ref).maxAbs,
                  1e-6)
            << "reference, azimuth " << azimuth;
    }
}

/// Scan `name` capped (ct-bone, cappedCut(), orbit 40,30), composite and isosurface, at
/// `edge`^2: `draw(tf, camera, options)` gives the reference's image (>= 50 dB), skipping and
/// early termination off change no pixel, and (with `uncappedDiffers`) the faces show.
template <class Draw>
void expectTheReferencesCappedImage(const std::string& name, std::uint32_t edge,
                                    const std::string& label, bool uncappedDiffers,
                                    const Draw& draw) {
    const auto t = test::ingestRealScan(name);
    if (!t) return test::missingData("scan " + name);
    const TransferFunction bone = TransferFunction::preset("ct-bone", t->stats);
    const Box box = LevelGeometry::of(*t->store, 0).box;
    const Camera camera = Camera::orbit(box, 40.0, 30.0);
    ReferenceRenderer reference;
    for (const BlendMode mode : {BlendMode::Composite, BlendMode::Isosurface}) {
        SCOPED_TRACE(toString(mode));
        RenderOptions o;
        o.width = o.height = edge;
        o.mode = mode;
        o.clip = cappedCut(box);
        o.isoValue = 0.5 * (bone.domainMin() + bone.domainMax());
        FrameStats refStats;
        const Image ref = reference.render(*t->store, *t->cache, bone, camera, o, refStats);
        const Image fast = draw(*t, bone, camera, o);
        const ImageComparison c = compareImages(fast, ref);
        test::printComparison(name + " " + toString(mode) + " capped" + label, c);
        EXPECT_GE(c.psnrDb, 50.0);
        RenderOptions plain = o;
        plain.skip = SkipMode::None;
        plain.earlyTermination = mode == BlendMode::Composite;
        EXPECT_EQ(compareImages(draw(*t, bone, camera, plain), fast).maxAbs, 0.0);
        if (!uncappedDiffers) continue;
        RenderOptions uncapped = o;
        uncapped.clip.cap = false;
        EXPECT_GT(compareImages(draw(*t, bone, camera, uncapped), fast).maxAbs, 0.05)
            << "the faces change the image";
    }
}

class CapOnScans : public ::testing::TestWithParam<std::string> {};

TEST_P(CapOnScans, TheCpuRaycasterDrawsTheReferencesCappedImageAndSkippingChangesNoPixel) {
    expectTheReferencesCappedImage(
        GetParam(), 96, "", true,
        [](TestStore& t, const TransferFunction& tf, const Camera& c, const RenderOptions& o) {
            return test::cpuFrame(t, tf, c, o);
        });
}

INSTANTIATE_TEST_SUITE_P(RealScans, CapOnScans,
                         ::testing::Values("cthead", "CT_AVM", "Iguana", "headsq"));

class CapOnScansGl : public ::testing::TestWithParam<std::string> {};

TEST_P(CapOnScansGl, TheGpuRaycasterDrawsTheReferencesCappedImageAndSkippingChangesNoPixel) {
    test::glContext();
    GpuRaycaster gpu;
    expectTheReferencesCappedImage(
        GetParam(), 64, " gpu", false,
        [&](TestStore& t, const TransferFunction& tf, const Camera& c, const RenderOptions& o) {
            return test::gpuFrame(t, gpu, tf, c, o);
        });
}

INSTANTIATE_TEST_SUITE_P(RealScans, CapOnScansGl, ::testing::Values("cthead", "CT_AVM"));

} // namespace
} // namespace bc::render
