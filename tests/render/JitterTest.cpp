// Jittered ray starts (RenderOptions::jitter): a per-pixel offset of less than one step,
// deterministic per pixel, so every exactness the fixed lattice has survives it: skipping on
// and off, SIMD and scalar, slices and the whole frame give the same image; the GPU raycaster
// takes the same samples.
#include "RenderTestSupport.h"
#include "render/CpuRaycaster.h"

#include <set>

namespace bc::render {
namespace {

using test::TestStore;

Image cpu(TestStore& t, const TransferFunction& tf, const Camera& c, const RenderOptions& o,
          FrameStats* stats = nullptr) {
    return test::cpuFrame(t, tf, c, o, stats);
}

RenderOptions jittered(std::uint32_t edge = 96) {
    RenderOptions o;
    o.width = o.height = edge;
    o.jitter = true;
    return o;
}

TEST(Jitter, OffsetsAreInTheUnitIntervalDeterministicAndSpread) {
    double sum = 0;
    std::set<float> distinct;
    for (std::uint32_t y = 0; y < 256; ++y)
        for (std::uint32_t x = 0; x < 256; ++x) {
            const float j = rayJitter(x, y);
            ASSERT_GE(j, 0.0f);
            ASSERT_LT(j, 1.0f);
            ASSERT_EQ(j, rayJitter(x, y));
            sum += j;
            distinct.insert(j);
        }
    EXPECT_NEAR(sum / 65536.0, 0.5, 0.01);
    EXPECT_GT(distinct.size(), 60000u);
    // Neighbours differ by far more than rounding: no flat patches that would keep the rings.
    int close = 0;
    for (std::uint32_t x = 0; x < 255; ++x)
        close += std::abs(rayJitter(x + 1, 7) - rayJitter(x, 7)) < 0.05f;
    EXPECT_LT(close, 30);
}

TEST(Jitter, SkippingSimdAndSlicesKeepTheImageExactly) {
    auto spec = test::realScan("CT_AVM");
    if (!spec) return test::missingData("scan CT_AVM");
    auto t = test::ingestSpec(*spec, {32, 2, 8});
    const auto tf = TransferFunction::preset("vessels", t->stats);
    const Camera c = Camera::orbit(LevelGeometry::of(*t->store, 0).box, 120, 15);
    RenderOptions plain = jittered(), scalar = jittered();
    plain.skip = SkipMode::None;
    plain.earlyTermination = false;
    scalar.simd = false;
    FrameStats sp, sa;
    const Image a = cpu(*t, tf, c, plain, &sp);
    const Image b = cpu(*t, tf, c, jittered(), &sa);
    const Image s = cpu(*t, tf, c, scalar);
    EXPECT_GT(test::alphaSum(a), 1.0) << "the view shows nothing, so proves nothing";
    EXPECT_LT(sa.samples, sp.samples);
    EXPECT_LE(compareImages(a, b).maxAbs, 1.0 - 0.99); // early termination's bound only
    EXPECT_EQ(compareImages(b, s).maxAbs, 0.0);
    RenderOptions noErt = jittered();
    noErt.earlyTermination = false;
    EXPECT_EQ(compareImages(a, cpu(*t, tf, c, noErt)).maxAbs, 0.0);
    CpuRaycaster sliced;
    EXPECT_EQ(compareImages(b, test::drawnInRegions(sliced, *t, tf, c, jittered())).maxAbs, 0.0);
    // And it moves the samples: the image is not the unjittered one.
    RenderOptions fixed = jittered();
    fixed.jitter = false;
    EXPECT_GT(compareImages(b, cpu(*t, tf, c, fixed)).maxAbs, 1.0 / 255.0);
}

TEST(Jitter, TheReferenceTakesTheSameSamples) {
    auto spec = test::realScan("headsq");
    if (!spec) return test::missingData("scan headsq");
    auto t = test::ingestSpec(*spec, {32, 2, 8});
    const auto tf = TransferFunction::preset("ct-skin", t->stats);
    const Camera c = Camera::orbit(LevelGeometry::of(*t->store, 0).box, 30, 20);
    RenderOptions o = jittered();
    o.earlyTermination = false;
    const Image ref = test::referenceFrame(*t, tf, c, o);
    const auto cmp = compareImages(cpu(*t, tf, c, o), ref);
    test::printComparison("headsq jittered, CPU raycaster vs reference", cmp);
    EXPECT_GE(cmp.psnrDb, 60.0);
    RenderOptions fixed = o;
    fixed.jitter = false;
    EXPECT_LT(compareImages(cpu(*t, tf, c, fixed), ref).psnrDb, 50.0);
}

TEST(JitterGl, GpuRaycasterTakesTheSameJitteredSamples) {
    auto spec = test::realScan("headsq");
    if (!spec) return test::missingData("scan headsq");
    test::glContext();
    auto t = test::ingestSpec(*spec, {32, 2, 8});
    const auto tf = TransferFunction::preset("ct-skin", t->stats);
    const Camera c = Camera::orbit(LevelGeometry::of(*t->store, 0).box, 30, 20);
    RenderOptions o = jittered(128);
    o.earlyTermination = false;
    GpuRaycaster gpu;
    const Image g = test::gpuFrame(*t, gpu, tf, c, o);
    const Image p = cpu(*t, tf, c, o);
    const auto cmp = compareImages(g, p);
    test::printComparison("headsq jittered, GPU vs CPU raycaster", cmp);
    EXPECT_LE(cmp.maxAbs, 2.0 / 255.0);
    RenderOptions fixed = o;
    fixed.jitter = false;
    EXPECT_GT(compareImages(g, test::gpuFrame(*t, gpu, tf, c, fixed)).maxAbs, 2.0 / 255.0);
}

} // namespace
} // namespace bc::render
