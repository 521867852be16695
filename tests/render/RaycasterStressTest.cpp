// Stress cases of the raycasters: each test name says what it guards. "No NaN, no holes, no seams":
// every image is finite, agrees with the CPU reference, and a bricked store renders like a
// single-brick store of the same volume. Each case runs on the GPU raycaster, the CPU
// raycaster's SIMD march and its scalar loop (the parameter).
#include "RenderTestSupport.h"
#include "render/CpuRaycaster.h"

#include <cmath>

namespace bc::render {
namespace {

using test::TestStore;

/// A TF with one narrow opaque peak of half-width `halfWidth` at `centre` (native units).
TransferFunction peakTf(double centre, double halfWidth, const VolumeValueStats& stats) {
    const std::string json = R"({"name":"peak","points":[)"
                             R"({"value":)" +
                             std::to_string(centre - halfWidth) +
                             R"(,"rgba":[1,0.8,0.6,0]},)"
                             R"({"value":)" +
                             std::to_string(centre) +
                             R"(,"rgba":[1,0.8,0.6,0.9]},)"
                             R"({"value":)" +
                             std::to_string(centre + halfWidth) + R"(,"rgba":[1,0.8,0.6,0]}]})";
    return TransferFunction::parse(json, "<peak>", stats);
}

/// True when some pixel is visible in `want` (alpha > 0.1) but empty in `got`: a hole.
bool hasHole(const Image& got, const Image& want) {
    for (std::size_t i = 3; i < got.rgba.size(); i += 4)
        if (want.rgba[i] > 0.1f && got.rgba[i] < 0.5f * want.rgba[i]) return true;
    return false;
}

/// The raycaster under test: "gpu", "cpu" (the SIMD march across rays, the default),
/// "cpu_samples" (SIMD across one ray's samples) or "cpu_scalar".
class RaycasterStress : public ::testing::TestWithParam<std::string> {
  protected:
    void SetUp() override {
        if (GetParam() == "gpu") test::glContext();
    }
    /// The frame of the parameter's raycaster (a new instance per call).
    Image frame(TestStore& t, const TransferFunction& tf, const Camera& camera, RenderOptions o,
                FrameStats* stats = nullptr) const {
        FrameStats s;
        Image image;
        if (GetParam() == "gpu") {
            GpuRaycaster r;
            image = r.render(*t.store, *t.cache, tf, camera, o, s);
        } else {
            o.simd = GetParam() != "cpu_scalar";
            o.packets = GetParam() == "cpu";
            CpuRaycaster r;
            image = r.render(*t.store, *t.cache, tf, camera, o, s);
        }
        if (stats) *stats = s;
        return image;
    }
    void expectCloseToReference(TestStore& t, const TransferFunction& tf, const Camera& camera,
                                const RenderOptions& o, const std::string& what,
                                double minPsnr = 40.0, double minCoverage = 0.01) const;
};

void RaycasterStress::expectCloseToReference(TestStore& t, const TransferFunction& tf,
                                             const Camera& camera, const RenderOptions& o,
                                             const std::string& what, double minPsnr,
                                             double minCoverage) const {
    RenderOptions gpuOptions = o;
    gpuOptions.earlyTermination = false;
    const Image gpu = frame(t, tf, camera, gpuOptions);
    const Image ref = test::referenceFrame(t, tf, camera, o);
    const auto c = compareImages(gpu, ref);
    test::printComparison(what, c);
    EXPECT_TRUE(test::allFinite(gpu)) << what;
    EXPECT_FALSE(hasHole(gpu, ref)) << what;
    EXPECT_GE(c.psnrDb, minPsnr) << what;
    double alpha = 0;
    for (std::size_t i = 3; i < ref.rgba.size(); i += 4)
        alpha += ref.rgba[i];
    EXPECT_GT(alpha, minCoverage * o.width * o.height)
        << what << ": the view shows almost nothing, so proves nothing";
}

RenderOptions small(std::uint32_t edge = 128) {
    RenderOptions o;
    o.width = o.height = edge;
    return o;
}

TEST_P(RaycasterStress, CameraInsideTheVolumeStartsRaysAtTheEye) {
    auto spec = test::realScan("headsq");
    if (!spec) return test::missingData("scan headsq");
    auto t = test::ingestSpec(*spec, {16, 2, 8});
    const auto tf = TransferFunction::preset("ct-skin", t->stats);
    const Box box = LevelGeometry::of(*t->store, 0).box;
    Camera c;
    c.eye = box.centre();
    c.target = box.centre() + glm::dvec3(1, 0.3, 0.2);
    c.up = {0, 0, 1};
    c.fovYDeg = 70;
    expectCloseToReference(*t, tf, c, small(), "headsq camera inside");
}

// Orthographic pixel rays land exactly on the x = 32k brick faces and run along the z axis.
TEST_P(RaycasterStress, RaysExactlyAlongBrickFacesAndAxesShowNoSeam) {
    auto source = brickstore::makeSynthetic(brickstore::SynthKind::Phantom, {128, 128, 96}, 7);
    auto bricked = test::ingestStore(*source, {32, 2, 8});
    auto source1 = brickstore::makeSynthetic(brickstore::SynthKind::Phantom, {128, 128, 96}, 7);
    auto single = test::ingestStore(*source1, {128, 2, 8});
    const auto tf = TransferFunction::preset("ct-bone", bricked->stats);
    Camera c;
    c.orthographic = true;
    c.eye = {63.5, 64, 500}; // pixel i's ray at x = i exactly (faces at 0, 32, 64, 96)
    c.target = {63.5, 64, 0};
    c.up = {0, 1, 0};
    c.orthoHeight = 128;
    const RenderOptions o = small();
    const Image a = frame(*bricked, tf, c, o);
    const Image b = frame(*single, tf, c, o);
    const auto cmp = compareImages(a, b);
    test::printComparison("phantom rays on brick faces, bricked vs single", cmp);
    EXPECT_TRUE(test::allFinite(a));
    EXPECT_FALSE(hasHole(a, b));
    EXPECT_LE(cmp.maxAbs, 1.0 / 255.0);
    expectCloseToReference(*bricked, tf, c, o, "phantom rays on brick faces vs reference");
}

TEST_P(RaycasterStress, GrazingRaysAlongTheTopFaceStayFiniteAndSeamless) {
    auto source = brickstore::makeSynthetic(brickstore::SynthKind::Phantom, {96, 96, 64}, 3);
    auto t = test::ingestStore(*source, {16, 2, 8});
    const auto tf = TransferFunction::preset("ct-skin", t->stats);
    Camera c;
    c.eye = {-200, 48, 64.0001}; // just above the top face, looking across it
    c.target = {48, 48, 63.9};
    c.up = {0, 0, 1};
    c.fovYDeg = 20;
    expectCloseToReference(*t, tf, c, small(), "phantom grazing rays");
}

TEST_P(RaycasterStress, NonCubicSpacingOfCtheadMatchesReference) {
    auto spec = test::realScan("cthead"); // 1 x 1 x 2 mm
    if (!spec) return test::missingData("scan cthead");
    auto t = test::ingestSpec(*spec, {64, 2, 8});
    const auto tf = TransferFunction::preset("ct-bone", t->stats);
    const Camera c =
        Camera::orbit(LevelGeometry::of(*t->store, 0).box, 90, 0); // side view: z stretched
    expectCloseToReference(*t, tf, c, small(), "cthead 1x1x2 mm side view", 45.0);
}

TEST_P(RaycasterStress, SignedSixteenBitDicomMatchesReference) {
    auto spec = test::realScan("pancreas"); // i16, HU -1000..1988
    if (!spec) return test::missingData("scan pancreas");
    auto t = test::ingestSpec(*spec, {64, 2, 8});
    ASSERT_EQ(t->store->info().volume.type, brickstore::VoxelType::I16);
    const auto tf = TransferFunction::preset("ct-bone", t->stats);
    const Camera c = Camera::orbit(LevelGeometry::of(*t->store, 0).box, 200, 30);
    expectCloseToReference(*t, tf, c, small(), "pancreas i16", 45.0);
}

TEST_P(RaycasterStress, FloatDataMatchesReference) {
    auto spec = test::realScan("hydrogen"); // f32 0..1
    if (!spec) return test::missingData("scan hydrogen");
    auto t = test::ingestSpec(*spec, {16, 2, 8});
    ASSERT_EQ(t->store->info().volume.type, brickstore::VoxelType::F32);
    const auto tf = TransferFunction::preset("smoke", t->stats);
    const Camera c = Camera::orbit(LevelGeometry::of(*t->store, 0).box, 45, 35);
    expectCloseToReference(*t, tf, c, small(), "hydrogen f32", 45.0);
}

// A TF opaque only at one value between two integers: samples between voxels reach it.
TEST_P(RaycasterStress, OneValueWidePeakIsRenderedAndNeverSkipped) {
    auto spec = test::realScan("CT_AVM");
    if (!spec) return test::missingData("scan CT_AVM");
    auto t = test::ingestSpec(*spec, {32, 2, 8});
    const auto tf = peakTf(100.5, 0.5, t->stats);
    const Camera c = Camera::orbit(LevelGeometry::of(*t->store, 0).box, 30, 20);
    RenderOptions none = small(), bricks = small();
    none.skip = SkipMode::None;
    FrameStats sb;
    const Image a = frame(*t, tf, c, none);
    const Image b = frame(*t, tf, c, bricks, &sb);
    const auto cmp = compareImages(a, b);
    test::printComparison("CT_AVM one-value peak, skip vs none", cmp);
    EXPECT_LE(cmp.maxAbs, 1.0 / 255.0);
    EXPECT_GT(sb.bricksSkipped, 0u);
    double alpha = 0;
    for (std::size_t i = 3; i < a.rgba.size(); i += 4)
        alpha += a.rgba[i];
    EXPECT_GT(alpha, 1.0) << "the peak shows nothing";
    expectCloseToReference(*t, tf, c, small(), "CT_AVM one-value peak vs reference", 35.0, 0.001);
}

// The brick-skipping guard of DESIGN.md: a TF whose only opaque value lies strictly between
// a brick's voxel values (never equal to any voxel) must not skip that brick.
TEST_P(RaycasterStress, PeakStrictlyBetweenVoxelValuesKeepsItsBrick) {
    // Two-valued checkerboard: voxels are 0 or 255 only; opacity only around 127.75.
    auto source = brickstore::makeSynthetic(brickstore::SynthKind::Checker, {64, 64, 64}, 1);
    auto t = test::ingestStore(*source, {16, 2, 8});
    const double lo = t->store->info().valueMin, hi = t->store->info().valueMax;
    const auto tf = peakTf(0.5 * (lo + hi) + 0.25, 0.5, t->stats);
    const Camera c = Camera::orbit(LevelGeometry::of(*t->store, 0).box, 20, 30);
    RenderOptions none = small(), bricks = small();
    none.skip = SkipMode::None;
    FrameStats sb;
    const Image a = frame(*t, tf, c, none);
    const Image b = frame(*t, tf, c, bricks, &sb);
    EXPECT_EQ(sb.bricksSkipped, 0u);
    EXPECT_LE(compareImages(a, b).maxAbs, 1.0 / 255.0);
    double alpha = 0;
    for (std::size_t i = 3; i < b.rgba.size(); i += 4)
        alpha += b.rgba[i];
    EXPECT_GT(alpha, 1.0);
}

TEST_P(RaycasterStress, StepsFromFiveHundredthsToFourVoxelsMatchReference) {
    auto spec = test::realScan("headsq");
    if (!spec) return test::missingData("scan headsq");
    auto t = test::ingestSpec(*spec, {32, 2, 8});
    const auto tf = TransferFunction::preset("ct-bone", t->stats);
    const Camera c = Camera::orbit(LevelGeometry::of(*t->store, 0).box, 150, 10);
    for (double step : {0.05, 0.5, 1.7, 4.0}) {
        RenderOptions o = small(64);
        o.stepVoxels = step;
        expectCloseToReference(*t, tf, c, o, "headsq step " + std::to_string(step), 40.0);
    }
}

// Positions near x = 16384 voxels leave float about 1/1000 voxel of precision
// (test::farChecker): no NaN, hole or seam at the far end.
TEST_P(RaycasterStress, SixteenThousandVoxelWideVolumeHasNoNaNHolesOrSeams) {
    const test::FarChecker c = test::farChecker();
    expectCloseToReference(*c.store, c.tf, c.camera, small(), "checker 16384 wide, far end", 40.0);
}

INSTANTIATE_TEST_SUITE_P(Raycasters, RaycasterStress,
                         ::testing::Values("gpu", "cpu", "cpu_samples", "cpu_scalar"),
                         [](const auto& info) { return info.param; });

} // namespace
} // namespace bc::render
