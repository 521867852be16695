// The error bound at rest (render/RefinementEstimate.h): a frame at rest is refined by
// halving the step, and each pass after the first carries an estimate of its PSNR against the
// converged image, taken from the pass before. On every shared scan and its presets, at the
// daemon's defaults (jittered ray starts, early termination), these tests draw the passes the
// daemon draws under a 40 dB bound and hold every estimate to the measured error: never more
// than kOptimisticDb above it, and at most kPessimisticDb below it (a factor of 3.2 in RMSE;
// an estimate claims no more than kMaxEstimateDb), and the pass where the daemon stops under a
// bound of 30, 40 or 50 dB meets it. The first pass of a large frame is checked against a
// sparse frame at twice its step instead (RenderOptions::stride): the same holds of that
// estimate, at lattices far sparser than the daemon's (a ninth and a quarter of a 96^2 frame:
// 1024 and 2304 pixels, where the daemon's hold at least kCheckPixels). The true image is the
// CPU raycaster at 1/32 voxel without jitter or early termination, checked to be settled (1/16
// against 1/32).
#include "render/RefinementEstimate.h"
#include "RenderTestSupport.h"

#include <algorithm>
#include <cmath>
#include <limits>
#include <utility>
#include <vector>

namespace bc::render {
namespace {

constexpr double kBoundDb = 40.0;
/// How far an estimate may be above (optimistic) or below (pessimistic) the measured PSNR.
constexpr double kOptimisticDb = 1.0, kPessimisticDb = 10.0;

TEST(RefinementEstimate, PsnrOfEightBitFrames) {
    std::vector<std::uint8_t> a(4 * 100, 0), b = a;
    EXPECT_TRUE(std::isinf(psnrRgb8(a, b)));
    b[0] = 255; // one channel of one pixel off by 255: MSE = 1/300
    EXPECT_NEAR(psnrRgb8(a, b), 10.0 * std::log10(300.0), 1e-9);
    b[0] = 0;
    b[3] = 255; // alpha does not count
    EXPECT_TRUE(std::isinf(psnrRgb8(a, b)));
    EXPECT_THROW(psnrRgb8(a, std::vector<std::uint8_t>(8)), std::invalid_argument);
    // The estimate: 6.02 dB over the difference, capped.
    b[0] = 255;
    EXPECT_NEAR(estimatedPsnrDb(a, b), 10.0 * std::log10(300.0) + 20.0 * std::log10(2.0), 1e-9);
    EXPECT_NEAR(estimatedPsnrDb(a, b, 0.0), 10.0 * std::log10(300.0), 1e-9) << "no gain";
    EXPECT_DOUBLE_EQ(estimatedPsnrDb(a, a), kMaxEstimateDb);
}

TEST(RefinementEstimate, PassesHalveTheStepUntilTheBoundOrTheFinestStep) {
    EXPECT_DOUBLE_EQ(refinementStep(1.0, 0), 1.0);
    EXPECT_DOUBLE_EQ(refinementStep(1.0, 3), 0.125);
    EXPECT_DOUBLE_EQ(refinementStep(0.5, 1), 0.25);
    EXPECT_TRUE(refineFurther(-1, 40, 1.0));   // the first pass has no estimate
    EXPECT_TRUE(refineFurther(39.9, 40, 1.0)); // short of the bound
    EXPECT_FALSE(refineFurther(40.0, 40, 1.0));
    EXPECT_FALSE(refineFurther(-1, 0, 1.0));                          // no bound: one pass
    EXPECT_TRUE(refineFurther(30, 40, 2 * kFinestRefinementStep));    // the finest comes next
    EXPECT_FALSE(refineFurther(30, 40, kFinestRefinementStep));       // nothing finer
    EXPECT_FALSE(refineFurther(30, 40, kFinestRefinementStep * 1.5)); // half would be finer
}

TEST(RefinementEstimate, TheCheckLatticeHoldsAtLeastItsPixelsAndPicksThemOut) {
    EXPECT_EQ(checkStride(512, 512), 4u); // 128^2 pixels
    EXPECT_EQ(checkStride(256, 256), 2u);
    EXPECT_EQ(checkStride(255, 256), 1u); // too small for a sparse check
    EXPECT_EQ(checkStride(64, 64), 1u);
    EXPECT_EQ(checkStride(1920, 1080), 11u);
    for (const auto& [w, h] :
         {std::pair{512u, 512u}, {1920u, 1080u}, {300u, 4000u}, {16384u, 2u}}) {
        const std::uint32_t s = checkStride(w, h);
        const PixelLattice l{s}, next{s + 1};
        EXPECT_GE(std::uint64_t(l.first(w)) * l.first(h), kCheckPixels) << w << "x" << h;
        if (s > 1) {
            EXPECT_LT(std::uint64_t(next.first(w)) * next.first(h), kCheckPixels);
        }
    }
    // A 5x3 frame whose pixel (x, y) holds x, y, x + y, 255, at stride 2: pixels (1, 1), (3, 1).
    std::vector<std::uint8_t> frame;
    for (std::uint8_t y = 0; y < 3; ++y)
        for (std::uint8_t x = 0; x < 5; ++x)
            frame.insert(frame.end(), {x, y, std::uint8_t(x + y), 255});
    EXPECT_EQ(latticeOf(frame, 5, 3, 2), (std::vector<std::uint8_t>{1, 1, 2, 255, 3, 1, 4, 255}));
    EXPECT_EQ(latticeOf(frame, 5, 3, 1), frame);
    EXPECT_THROW(latticeOf(frame, 5, 4, 2), std::invalid_argument);
}

class RefinementEstimateOnScans : public ::testing::TestWithParam<test::ScanPreset> {};

TEST_P(RefinementEstimateOnScans, EstimatesFollowTheMeasuredErrorAndTheBoundIsMet) {
    const test::ScanPreset& k = GetParam();
    auto t = test::ingestRealScan(k.scan);
    if (!t) GTEST_SKIP() << k.scan << " is not in ../shared/data";
    const auto tf = TransferFunction::preset(k.preset, t->stats);
    const Camera c = Camera::orbit(LevelGeometry::of(*t->store, 0).box, 30, 20);
    RenderOptions o; // the daemon's frame at rest for the protocol's defaults
    o.width = o.height = 96;
    o.jitter = true;
    o.shading = tf.shading().value_or(true);
    RenderOptions finer = o, fine = o;
    finer.jitter = fine.jitter = false;
    finer.earlyTermination = fine.earlyTermination = false;
    fine.stepVoxels = 1.0 / 16.0;
    finer.stepVoxels = 1.0 / 32.0;
    const std::vector<std::uint8_t> truth = toRgba8(test::cpuFrame(*t, tf, c, finer));
    const double settled = psnrRgb8(toRgba8(test::cpuFrame(*t, tf, c, fine)), truth);
    EXPECT_GT(settled, kMaxEstimateDb + 3.0) << "the true image is not settled";

    // The passes the daemon draws under the highest bound a client may ask for; a lower bound
    // stops at the first of them whose estimate reaches it.
    struct Pass {
        double estimate, measured;
    };
    std::vector<Pass> passes;
    std::vector<std::uint8_t> previous;
    for (std::uint32_t pass = 0;; ++pass) {
        RenderOptions p = o;
        p.stepVoxels = float(refinementStep(o.stepVoxels, pass));
        const std::vector<std::uint8_t> frame = toRgba8(test::cpuFrame(*t, tf, c, p));
        const double measured = std::min(psnrRgb8(frame, truth), 99.0);
        const double estimate = pass == 0 ? -1.0 : estimatedPsnrDb(frame, previous);
        std::printf("[ %s %s ] pass %u step %.4g: measured %.1f dB, estimated %.1f dB\n",
                    k.scan.c_str(), k.preset.c_str(), pass, p.stepVoxels, measured, estimate);
        if (pass > 0) {
            // Above kMaxEstimateDb the estimate claims no more than that.
            EXPECT_LE(estimate, measured + kOptimisticDb) << "pass " << pass;
            EXPECT_GE(estimate, std::min(measured, kMaxEstimateDb) - kPessimisticDb)
                << "pass " << pass;
        }
        passes.push_back({estimate, measured});
        previous = frame;
        if (!refineFurther(estimate, kMaxEstimateDb, p.stepVoxels)) break;
    }
    for (const double bound : {30.0, kBoundDb, kMaxEstimateDb}) {
        const auto met = std::find_if(passes.begin(), passes.end(),
                                      [&](const Pass& p) { return p.estimate >= bound; });
        if (met != passes.end()) {
            EXPECT_GE(met->measured, bound) << "the pass that claims " << bound << " dB";
        } else {
            EXPECT_LT(bound, kBoundDb + 1) << "no pass reached " << bound << " dB";
        }
    }

    // A large frame's first pass (pass 1, at half the step) checked against the lattice of
    // pass 0 (a sparse frame at the step): the estimate over the lattice's pixels.
    ASSERT_GE(passes.size(), 2u);
    RenderOptions sparse = o, first = o;
    first.stepVoxels = float(refinementStep(o.stepVoxels, 1));
    const std::vector<std::uint8_t> pass1 = toRgba8(test::cpuFrame(*t, tf, c, first));
    for (const std::uint32_t stride : {2u, 3u}) {
        sparse.stride = stride;
        const std::vector<std::uint8_t> check = toRgba8(test::cpuFrame(*t, tf, c, sparse));
        const double estimate = estimatedPsnrDb(latticeOf(pass1, o.width, o.height, stride), check);
        const double measured = passes[1].measured;
        std::printf("[ %s %s ] pass 1 checked at stride %u: estimated %.1f dB (%.1f from the "
                    "whole pass 0)\n",
                    k.scan.c_str(), k.preset.c_str(), stride, estimate, passes[1].estimate);
        EXPECT_LE(estimate, measured + kOptimisticDb) << "stride " << stride;
        EXPECT_GE(estimate, std::min(measured, kMaxEstimateDb) - kPessimisticDb)
            << "stride " << stride;
        for (const double bound : {30.0, kBoundDb})
            if (estimate >= bound) {
                EXPECT_GE(measured, bound) << "stride " << stride;
            }
    }
}

// The isosurface's passes are estimated without the halving gain (kHalvingGainDb): its error
// falls slower than the halvings' differences where a step misses thin parts of the surface.
// The pancreas's surface at the middle of its values, the daemon's passes at rest: the pass
// that claims the bound meets it.
TEST(RefinementEstimateIso, ThePassThatClaimsTheBoundMeetsIt) {
    auto t = test::ingestRealScan("pancreas");
    if (!t) return test::missingData("scan pancreas");
    const auto tf = TransferFunction::preset("ct-bone", t->stats);
    const Camera c = Camera::orbit(LevelGeometry::of(*t->store, 0).box, 30, 20);
    RenderOptions o;
    o.width = o.height = 128;
    o.mode = BlendMode::Isosurface;
    o.isoValue = 0.5 * (t->stats.valueMin + t->stats.valueMax);
    RenderOptions finest = o;
    finest.stepVoxels = 1.0 / 32.0;
    finest.earlyTermination = false;
    const std::vector<std::uint8_t> truth = toRgba8(test::cpuFrame(*t, tf, c, finest));
    std::vector<std::uint8_t> previous;
    for (std::uint32_t pass = 0;; ++pass) {
        RenderOptions p = o;
        p.stepVoxels = float(refinementStep(o.stepVoxels, pass));
        const std::vector<std::uint8_t> frame = toRgba8(test::cpuFrame(*t, tf, c, p));
        const double measured = psnrRgb8(frame, truth);
        const double estimate = pass == 0 ? -1.0 : estimatedPsnrDb(frame, previous, 0.0);
        std::printf("[ pancreas iso ] pass %u step %.4g: measured %.1f dB, estimated %.1f dB "
                    "(%.1f with the halving gain)\n",
                    pass, p.stepVoxels, measured, estimate,
                    pass == 0 ? -1.0 : estimatedPsnrDb(frame, previous));
        if (estimate >= kBoundDb) {
            EXPECT_GE(measured, kBoundDb) << "pass " << pass << " claims the bound";
            break;
        }
        ASSERT_TRUE(refineFurther(estimate, kBoundDb, p.stepVoxels)) << "the bound was not reached";
        previous = frame;
    }
}

INSTANTIATE_TEST_SUITE_P(SharedScans, RefinementEstimateOnScans,
                         ::testing::ValuesIn(test::invariantScans()), [](const auto& info) {
                             std::string name = info.param.scan + "_" + info.param.preset;
                             for (char& ch : name)
                                 if (!std::isalnum(static_cast<unsigned char>(ch))) ch = '_';
                             return name;
                         });

} // namespace
} // namespace bc::render
