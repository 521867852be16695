// The GPU raycaster against the CPU reference, and every acceleration against no
// acceleration, on the real scans (accuracy and stability).
#include "RenderTestSupport.h"

namespace bc::render {
namespace {

using test::TestStore;

struct Scan {
    std::string name;
    std::string preset;
};

class GpuVersusReference : public ::testing::TestWithParam<Scan> {};

// PSNR >= 45 dB and SSIM >= 0.99 at the same step and size, 256^2, shaded.
TEST_P(GpuVersusReference, MatchesTheDoublePrecisionReferenceAt256) {
    const Scan scan = GetParam();
    auto spec = test::realScan(scan.name);
    if (!spec) return test::missingData("scan " + scan.name);
    test::glContext();
    auto t = test::ingestSpec(*spec, {32, 2, 8});
    const auto tf = TransferFunction::preset(scan.preset, t->stats);
    const Camera camera = Camera::orbit(LevelGeometry::of(*t->store, 0).box, 30, 20, 1.0);
    RenderOptions o;
    o.earlyTermination = false;
    GpuRaycaster raycaster;
    FrameStats stats;
    const Image gpu = test::gpuFrame(*t, raycaster, tf, camera, o, &stats);
    const Image ref = test::referenceFrame(*t, tf, camera, o);
    const auto c = compareImages(gpu, ref);
    test::printComparison(scan.name + " " + scan.preset + " GPU vs reference", c);
    EXPECT_TRUE(test::allFinite(gpu));
    EXPECT_GE(c.psnrDb, 45.0);
    EXPECT_GE(c.ssim, 0.99);
    EXPECT_GT(stats.samples, 0u);
    double opaque = 0;
    for (std::size_t i = 3; i < gpu.rgba.size(); i += 4)
        opaque += gpu.rgba[i];
    EXPECT_GT(opaque, 0.01 * o.width * o.height) << "the preset shows nothing on " << scan.name;
}

INSTANTIATE_TEST_SUITE_P(RealScans, GpuVersusReference,
                         ::testing::Values(Scan{"cthead", "ct-skin"}, Scan{"cthead", "ct-bone"},
                                           Scan{"CT_AVM", "vessels"}, Scan{"frog", "mr"}),
                         [](const auto& info) {
                             return info.param.name + "_" + [&] {
                                 std::string s = info.param.preset;
                                 for (char& ch : s)
                                     if (ch == '-') ch = '_';
                                 return s;
                             }();
                         });

// No seams: a store of 32^3 bricks renders like a store holding the volume in one brick.
TEST(RaycasterSeams, BrickedEqualsSingleBrickOnCthead) {
    auto spec = test::realScan("cthead");
    if (!spec) return test::missingData("scan cthead");
    test::glContext();
    auto bricked = test::ingestSpec(*spec, {32, 2, 8});
    auto single = test::ingestSpec(*spec, {256, 2, 8});
    ASSERT_EQ(single->store->layout().levels()[0].brickCount(), 1u);
    const auto tf = TransferFunction::preset("ct-bone", bricked->stats);
    const auto tf1 = TransferFunction::preset("ct-bone", single->stats);
    GpuRaycaster raycaster;
    for (double az : {0.0, 37.0, 90.0}) {
        const Camera camera =
            Camera::orbit(LevelGeometry::of(*bricked->store, 0).box, az, az == 90.0 ? 0.0 : 25.0);
        RenderOptions o;
        o.earlyTermination = false;
        const Image a = test::gpuFrame(*bricked, raycaster, tf, camera, o);
        const Image b = test::gpuFrame(*single, raycaster, tf1, camera, o);
        const auto c = compareImages(a, b);
        test::printComparison("cthead 32^3 bricks vs one brick, az " + std::to_string(int(az)), c);
        EXPECT_LE(c.maxAbs, 1.0 / 255.0) << "at (" << c.maxAbsX << "," << c.maxAbsY << ")";
    }
}

// A GPU budget smaller than the visible working set: several front-to-back batches, same image.
TEST(RaycasterOutOfCore, BudgetSmallerThanTheWorkingSetGivesTheSameImage) {
    auto spec = test::realScan("cthead");
    if (!spec) return test::missingData("scan cthead");
    test::glContext();
    auto t = test::ingestSpec(*spec, {32, 2, 8});
    const auto tf = TransferFunction::preset("ct-skin", t->stats);
    const Camera camera = Camera::orbit(LevelGeometry::of(*t->store, 0).box, 60, 30);
    RenderOptions o;
    GpuRaycaster unlimited({256ull << 20}), small({4ull << 20}); // 4 MiB: 44 slots of 36^3 u16
    FrameStats su, ss;
    const Image a = test::gpuFrame(*t, unlimited, tf, camera, o, &su);
    const Image b = test::gpuFrame(*t, small, tf, camera, o, &ss);
    EXPECT_EQ(su.batches, 1u);
    EXPECT_GE(ss.batches, 3u);
    std::printf("[out-of-core] %llu sampled bricks in %u batches of <= %u slots\n",
                (unsigned long long)(ss.bricksVisited - ss.bricksConstant), ss.batches,
                small.pool()->capacity());
    const auto c = compareImages(a, b);
    test::printComparison("cthead budget 4 MiB vs 256 MiB", c);
    EXPECT_LE(c.maxAbs, 1.0 / 255.0);
}

// Early termination at t changes no pixel by more than (1 - t) + 1/255.
TEST(RaycasterEarlyTermination, ChangesNoPixelByMoreThanOneMinusThreshold) {
    auto spec = test::realScan("cthead");
    if (!spec) return test::missingData("scan cthead");
    test::glContext();
    auto t = test::ingestSpec(*spec, {32, 2, 8});
    const auto tf = TransferFunction::preset("ct-skin", t->stats);
    const Camera camera = Camera::orbit(LevelGeometry::of(*t->store, 0).box, 10, 10);
    GpuRaycaster raycaster;
    RenderOptions off;
    off.earlyTermination = false;
    FrameStats sOff;
    const Image full = test::gpuFrame(*t, raycaster, tf, camera, off, &sOff);
    for (double threshold : {0.95, 0.99}) {
        RenderOptions on = off;
        on.earlyTermination = true;
        on.ertThreshold = threshold;
        FrameStats sOn;
        const Image cut = test::gpuFrame(*t, raycaster, tf, camera, on, &sOn);
        const auto c = compareImages(full, cut);
        test::printComparison("cthead ERT " + std::to_string(threshold), c);
        EXPECT_LE(c.maxAbs, (1.0 - threshold) + 1.0 / 255.0);
        EXPECT_LT(sOn.samples, sOff.samples);
    }
}

// Brick skipping changes no pixel beyond 1/255, and skips something on sparse data.
TEST(RaycasterBrickSkipping, ChangesNoPixelOnSparseAngiography) {
    auto spec = test::realScan("CT_AVM");
    if (!spec) return test::missingData("scan CT_AVM");
    test::glContext();
    auto t = test::ingestSpec(*spec, {32, 2, 8});
    const auto tf = TransferFunction::preset("vessels", t->stats);
    const Camera camera = Camera::orbit(LevelGeometry::of(*t->store, 0).box, 120, 15);
    GpuRaycaster plain, skipping; // separate pools, so each frame uploads what it needs
    RenderOptions none, bricks;
    none.skip = SkipMode::None;
    bricks.skip = SkipMode::Bricks;
    FrameStats sn, sb;
    const Image a = test::gpuFrame(*t, plain, tf, camera, none, &sn);
    const Image b = test::gpuFrame(*t, skipping, tf, camera, bricks, &sb);
    const auto c = compareImages(a, b);
    test::printComparison("CT_AVM skip bricks vs none", c);
    EXPECT_LE(c.maxAbs, 1.0 / 255.0);
    EXPECT_GT(sb.bricksSkipped, 0u);
    EXPECT_LT(sb.samples, sn.samples);
    EXPECT_LT(sb.bytesUploaded, sn.bytesUploaded);
}

} // namespace
} // namespace bc::render
