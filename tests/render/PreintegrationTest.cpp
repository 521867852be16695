// Pre-integrated classification (RenderOptions::preintegrate, PreintegratedTable): the table
// is exact where skipping needs it (transparent values give exactly zero), a segment of one
// value is the step-corrected opacity, a thin peak between two samples' values is caught,
// the CPU raycaster and the reference draw the same image, skipping and jitter keep it
// exactly, and pre-integrated and plain converge to one image as the step shrinks.
#include "RenderTestSupport.h"
#include "render/CpuRaycaster.h"
#include "render/HybridSplatter.h"

#include <cmath>

namespace bc::render {
namespace {

using test::TestStore;

PointSpec at(double value, float r, float g, float b, float a) {
    return {Placement::Value, value, {r, g, b, a}};
}

/// Transparent below 400, a thin opaque peak at 500 (490..510), transparent again above.
TransferFunction thinPeak() {
    return TransferFunction::fromPoints({at(0, 1, 1, 1, 0), at(490, 1, 0.5f, 0.2f, 0),
                                         at(500, 1, 0.5f, 0.2f, 0.8f), at(510, 1, 0.5f, 0.2f, 0),
                                         at(1000, 1, 1, 1, 0)},
                                        "thin peak", test::unitStats());
}

TEST(Preintegration, TransparentValuesGiveExactlyZero) {
    const PreintegratedTable t = thinPeak().preintegrated();
    // Every pair of values below the peak's support: the integrals are equal to the bit.
    for (double a : {0.0, 3.7, 100.0, 250.25, 480.0})
        for (double b : {0.0, 17.0, 333.3, 489.0}) {
            const auto fa = t.end(a), fb = t.end(b);
            EXPECT_EQ(fa.integral[0], t.end(0.0).integral[0]) << a;
            const auto s = t.segment(fa, fb, 1.0);
            EXPECT_EQ(s[3], 0.0) << a << " -> " << b;
            EXPECT_EQ(t.segment(fb, fa, 4.0)[3], 0.0);
        }
    // ... and above it.
    EXPECT_EQ(t.segment(t.end(515.0), t.end(999.0), 2.0)[3], 0.0);
}

TEST(Preintegration, APeakBetweenTwoTransparentValuesIsCaught) {
    const TransferFunction tf = thinPeak();
    const PreintegratedTable t = tf.preintegrated();
    const TransferFunctionTable plain = tf.table(1.0);
    // Both ends transparent: the plain classification sees nothing, the segment sees the peak.
    EXPECT_EQ(plain.lookup(300.0)[3], 0.0f);
    EXPECT_EQ(plain.lookup(700.0)[3], 0.0f);
    const auto s = t.segment(t.end(300.0), t.end(700.0), 1.0);
    // Independent: integrate tau(v) = -ln(1 - a(v)) of the exact function over [300, 700].
    double integral = 0.0;
    const int n = 400000;
    for (int i = 0; i < n; ++i) {
        const double v = 300.0 + (i + 0.5) * (400.0 / n);
        integral += -std::log1p(-double(tf.evaluate(v)[3])) * (400.0 / n);
    }
    const double expected = -std::expm1(-integral / 400.0);
    EXPECT_NEAR(s[3], expected, 0.02 * expected);
    EXPECT_GT(s[3], 0.01);
    EXPECT_NEAR(s[0], 1.0, 1e-6); // the peak's colour
    EXPECT_NEAR(s[1], 0.5, 1e-6);
    EXPECT_NEAR(s[2], 0.2, 1e-6);
    // The order of the ends does not matter; a longer segment is more opaque.
    EXPECT_NEAR(t.segment(t.end(700.0), t.end(300.0), 1.0)[3], s[3], 1e-12);
    EXPECT_GT(t.segment(t.end(300.0), t.end(700.0), 2.0)[3], s[3]);
}

TEST(Preintegration, ASegmentOfOneValueIsTheStepCorrectedOpacity) {
    const auto tf = TransferFunction::fromPoints(
        {at(0, 0.2f, 0.4f, 0.6f, 0.0f), at(300, 0.9f, 0.3f, 0.1f, 0.3f), at(1000, 1, 1, 1, 0.95f)},
        "ramp", test::unitStats());
    const PreintegratedTable t = tf.preintegrated();
    for (double d : {0.05, 0.5, 1.0, 2.0, 4.0}) {
        const TransferFunctionTable plain = tf.table(d);
        for (std::uint32_t i = 0; i < t.entries; i += 97) {
            const double value = 1000.0 * i / (t.entries - 1);
            const auto e = t.end(value);
            const auto s = t.segment(e, e, d);
            const auto p = plain.lookup(value);
            EXPECT_NEAR(s[3], p[3], 2e-6) << value << " at step " << d;
            if (p[3] > 0.0f) {
                for (int c = 0; c < 3; ++c)
                    EXPECT_NEAR(s[c], p[c], 2e-6) << value;
            }
        }
    }
}

TEST(Preintegration, NumericalEdges) {
    const TransferFunction tf = thinPeak();
    const PreintegratedTable t = tf.preintegrated();
    // Around kMinSpan the two ways of taking the means agree: no jump.
    const double u0 = 500.0; // on the peak
    const double cell = 1000.0 / (t.entries - 1);
    const auto front = t.end(u0);
    for (double f : {0.5, 0.999, 1.001, 2.0}) {
        const auto back = t.end(u0 + f * PreintegratedTable::kMinSpan * cell);
        const auto s = t.segment(front, back, 1.0);
        EXPECT_NEAR(s[3], t.segment(front, front, 1.0)[3], 1e-5) << f;
    }
    // NaN and values beyond the domain clamp, as the plain table does; nothing is NaN.
    for (double v : {std::nan(""), -1e30, -1.0, 1001.0, 1e30, std::numeric_limits<double>::max()}) {
        const auto e = t.end(v);
        EXPECT_TRUE(std::isfinite(e.u)) << v;
        for (double d : {0.01, 1.0, 64.0})
            for (double x : t.segment(e, t.end(500.0), d))
                EXPECT_TRUE(std::isfinite(x)) << v << " step " << d;
    }
    // Opacity 1: a capped extinction, opaque at any step of 0.5 and more, finite integrals.
    const auto opaque = TransferFunction::fromPoints({at(0, 1, 1, 1, 1), at(1000, 1, 1, 1, 1)},
                                                     "opaque", test::unitStats())
                            .preintegrated();
    const auto e = opaque.end(10.0), f = opaque.end(990.0);
    EXPECT_TRUE(std::isfinite(f.integral[0]));
    EXPECT_EQ(float(opaque.segment(e, f, 0.5)[3]), 1.0f);
    EXPECT_EQ(float(opaque.segment(e, e, 64.0)[3]), 1.0f);
    EXPECT_GT(opaque.segment(e, e, 0.01)[3], 0.3); // 1 - exp(-0.4)
    EXPECT_THROW((void)tf.preintegrated(1), std::invalid_argument);
}

Image cpu(TestStore& t, const TransferFunction& tf, const Camera& c, const RenderOptions& o,
          FrameStats* stats = nullptr) {
    return test::cpuFrame(t, tf, c, o, stats);
}

RenderOptions pre(std::uint32_t edge = 96, double step = 1.0) {
    RenderOptions o;
    o.width = o.height = edge;
    o.preintegrate = true;
    o.stepVoxels = step;
    return o;
}

TEST(Preintegration, CpuRaycasterDrawsTheReferencesImage) {
    auto spec = test::realScan("headsq");
    if (!spec) return test::missingData("scan headsq");
    auto t = test::ingestSpec(*spec, {32, 2, 8});
    const Camera c = Camera::orbit(LevelGeometry::of(*t->store, 0).box, 30, 20);
    for (const char* name : {"ct-skin", "ct-bone"})
        for (double step : {0.5, 1.5}) {
            const auto tf = TransferFunction::preset(name, t->stats);
            RenderOptions o = pre(96, step);
            o.earlyTermination = false;
            const Image ref = test::referenceFrame(*t, tf, c, o);
            const auto cmp = compareImages(cpu(*t, tf, c, o), ref);
            test::printComparison(std::string("headsq ") + name + " pre-integrated step " +
                                      std::to_string(step) + ", CPU raycaster vs reference",
                                  cmp);
            EXPECT_GE(cmp.psnrDb, 50.0);
            EXPECT_LE(cmp.maxAbs, 8.0 / 255.0);
            // It is not the plain image.
            RenderOptions plain = o;
            plain.preintegrate = false;
            EXPECT_GT(compareImages(cpu(*t, tf, c, plain), ref).maxAbs, cmp.maxAbs);
        }
}

TEST(Preintegration, SkippingJitterAndSlicesKeepTheImageExactly) {
    auto spec = test::realScan("CT_AVM");
    if (!spec) return test::missingData("scan CT_AVM");
    auto t = test::ingestSpec(*spec, {32, 2, 8});
    const auto tf = TransferFunction::preset("vessels", t->stats);
    const Camera c = Camera::orbit(LevelGeometry::of(*t->store, 0).box, 120, 15);
    // Steps under a leaf, over a leaf, and over a brick (transparent bricks two deep are drawn).
    for (double step : {0.7, 2.5, 40.0}) {
        RenderOptions all = pre(96, step);
        all.jitter = true;
        all.earlyTermination = false;
        RenderOptions none = all, bricks = all, scalar = all;
        none.skip = SkipMode::None;
        bricks.skip = SkipMode::Bricks;
        scalar.simd = false;
        FrameStats sn, sa;
        const Image a = cpu(*t, tf, c, none, &sn);
        const Image b = cpu(*t, tf, c, all, &sa);
        EXPECT_GT(test::alphaSum(a), 0.1) << "the view shows nothing, so proves nothing";
        EXPECT_EQ(compareImages(a, b).maxAbs, 0.0) << "step " << step;
        EXPECT_EQ(compareImages(a, cpu(*t, tf, c, bricks)).maxAbs, 0.0) << "step " << step;
        EXPECT_EQ(compareImages(b, cpu(*t, tf, c, scalar)).maxAbs, 0.0) << "step " << step;
        if (step < 10.0) {
            EXPECT_LT(sa.samples, sn.samples) << "skipping skipped nothing";
        }
        CpuRaycaster sliced;
        EXPECT_EQ(compareImages(b, test::drawnInRegions(sliced, *t, tf, c, all)).maxAbs, 0.0);
        // Early termination moves the image by its bound only.
        RenderOptions ert = all;
        ert.earlyTermination = true;
        EXPECT_LE(compareImages(a, cpu(*t, tf, c, ert)).maxAbs, 1.0 - 0.99);
    }
}

TEST(Preintegration, PreintegratedAndPlainConvergeAsTheStepShrinks) {
    auto spec = test::realScan("headsq");
    if (!spec) return test::missingData("scan headsq");
    auto t = test::ingestSpec(*spec, {32, 2, 8});
    const auto tf = TransferFunction::preset("ct-skin", t->stats);
    const Camera c = Camera::orbit(LevelGeometry::of(*t->store, 0).box, 30, 20);
    double last = 1.0;
    for (double step : {1.0, 0.25, 1.0 / 16.0}) {
        RenderOptions p = pre(64, step), plain = pre(64, step);
        plain.preintegrate = false;
        const auto cmp = compareImages(cpu(*t, tf, c, p), cpu(*t, tf, c, plain));
        test::printComparison(
            "headsq ct-skin, pre-integrated vs plain at step " + std::to_string(step), cmp);
        EXPECT_LT(cmp.rmse, last) << "step " << step;
        last = cmp.rmse;
        if (step < 0.1) {
            EXPECT_LE(cmp.maxAbs, 3.0 / 255.0);
        }
    }
}

TEST(Preintegration, AThinShellIsDrawnAtACoarseStep) {
    auto spec = test::realScan("headsq");
    if (!spec) return test::missingData("scan headsq");
    auto t = test::ingestSpec(*spec, {32, 2, 8});
    // A shell a few values wide (an iso-surface made of a transfer function).
    const auto tf =
        TransferFunction::fromPoints({{Placement::Percentile, 93.5, {0.9f, 0.85f, 0.75f, 0.0f}},
                                      {Placement::Percentile, 94.0, {0.95f, 0.9f, 0.8f, 0.9f}},
                                      {Placement::Percentile, 94.5, {0.9f, 0.85f, 0.75f, 0.0f}}},
                                     "shell", t->stats);
    const Camera c = Camera::orbit(LevelGeometry::of(*t->store, 0).box, 30, 20);
    RenderOptions fine = pre(64, 1.0 / 32.0);
    fine.preintegrate = false;
    const Image truth = cpu(*t, tf, c, fine);
    RenderOptions plain = pre(64, 0.5), coarse = pre(64, 2.0);
    plain.preintegrate = false;
    const auto cp = compareImages(cpu(*t, tf, c, plain), truth);
    const auto cq = compareImages(cpu(*t, tf, c, coarse), truth);
    test::printComparison("headsq shell, plain step 0.5 vs step 1/32", cp);
    test::printComparison("headsq shell, pre-integrated step 2 vs step 1/32", cq);
    EXPECT_GT(cq.psnrDb, cp.psnrDb); // four times fewer samples, and closer
}

TEST(Preintegration, RenderersWithoutItRefuseIt) {
    auto phantom = brickstore::makeSynthetic(brickstore::SynthKind::Phantom, {32, 32, 32}, 3);
    auto t = test::ingestStore(*phantom, {16, 2, 8});
    const auto tf = TransferFunction::preset("ct-skin", t->stats);
    const Camera c = Camera::orbit(LevelGeometry::of(*t->store, 0).box, 30, 20);
    HybridSplatter splat;
    FrameStats s;
    try {
        (void)splat.render(*t->store, *t->cache, tf, c, pre(32), s);
        ADD_FAILURE() << "the splatter drew a pre-integrated frame";
    } catch (const std::invalid_argument& e) {
        EXPECT_NE(std::string(e.what()).find("preintegrate"), std::string::npos) << e.what();
    }
}

} // namespace
} // namespace bc::render
