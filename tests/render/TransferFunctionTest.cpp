// Transfer functions: the file format and its errors, placement, the exact function, the
// table both renderers classify through (narrow peaks, range maxima, opacity correction), and
// the presets on the real scans' value statistics.
#include "render/TransferFunction.h"
#include "../TestSupport.h"
#include "brickstore/Readers.h"
#include "brickstore/VoxelType.h"
#include "render/Error.h"

#include <algorithm>
#include <cmath>
#include <cstdio>
#include <fstream>
#include <limits>
#include <map>
#include <sstream>

namespace bc::render {
namespace {

VolumeValueStats rangeStats(double lo, double hi, std::vector<std::uint64_t> histogram = {}) {
    return VolumeValueStats{lo, hi, std::move(histogram)};
}

/// A document of the given points, e.g. R"({"value": 1, "rgba": [1,1,1,1]})".
std::string doc(const std::string& points) {
    return R"({"name": "t", "points": [)" + points + "]}";
}

std::string point(const std::string& placement, double x, std::array<float, 4> c) {
    std::ostringstream s;
    s.precision(17);
    s << R"({")" << placement << R"(": )" << x << R"(, "rgba": [)" << c[0] << ", " << c[1] << ", "
      << c[2] << ", " << c[3] << "]}";
    return s.str();
}

/// Parses `json` expecting a RenderInputError that names `field` and says something with `why`.
void expectInputError(const std::string& json, const std::string& field, const std::string& why,
                      const VolumeValueStats& stats = rangeStats(0, 255, {10, 5, 5, 5})) {
    try {
        TransferFunction::parse(json, "bad.json", stats);
        ADD_FAILURE() << "accepted: " << json;
    } catch (const RenderInputError& e) {
        EXPECT_EQ(e.file(), "bad.json");
        EXPECT_EQ(e.field(), field) << e.what();
        EXPECT_NE(std::string(e.what()).find(why), std::string::npos) << e.what();
    }
}

const std::string kRgba = R"("rgba": [1, 1, 1, 1])";

TEST(TransferFunctionTest, RefusesEveryBadDocumentNamingTheField) {
    expectInputError("[1, 2]", "(document)", "expected an object");
    expectInputError(R"({"name": "x"})", "points", "missing");
    expectInputError(R"({"points": []})", "points", "empty");
    expectInputError(R"({"points": {"value": 1}})", "points", "expected an array");
    expectInputError(R"({"colour": 1, "points": [{"value": 1, )" + kRgba + "}]}", "colour",
                     "unknown key");
    expectInputError(R"({"name": 3, "points": [{"value": 1, )" + kRgba + "}]}", "name",
                     "expected a string");
    expectInputError(R"({"shading": "yes", "points": [{"value": 1, )" + kRgba + "}]}", "shading",
                     "expected a boolean");
    expectInputError(doc(R"({"value": 1, )" + kRgba + "}, 7"), "points[1]", "expected an object");
    expectInputError(doc(R"({"value": 1, "opacity": 1, )" + kRgba + "}"), "points[0].opacity",
                     "unknown key");
    expectInputError(doc("{" + kRgba + "}"), "points[0]", "not placed");
    expectInputError(doc(R"({"value": 1, "fraction": 0.5, )" + kRgba + "}"), "points[0]",
                     "placed twice");
    expectInputError(doc(R"({"value": 1})"), "points[0].rgba", "missing");
    expectInputError(doc(R"({"value": 1, "rgba": [1, 1, 1]})"), "points[0].rgba", "4 numbers");
    expectInputError(doc(R"({"value": 1, "rgba": "red"})"), "points[0].rgba", "4 numbers");
    expectInputError(doc(R"({"value": 1, "rgba": [1, "x", 1, 1]})"), "points[0].rgba[1]",
                     "expected a number");
    expectInputError(doc(R"({"value": 1, "rgba": [1, 1, 1, true]})"), "points[0].rgba[3]",
                     "expected a number");
    const std::string ok = R"({"value": 1, )" + kRgba + "}, ";
    expectInputError(doc(ok + ok + ok + R"({"value": 1, "rgba": [0, 1.5, 0, 0]})"),
                     "points[3].rgba[1]", "outside [0, 1]");
    expectInputError(doc(R"({"value": 1, "rgba": [0, 0, -0.1, 0]})"), "points[0].rgba[2]",
                     "outside [0, 1]");
    expectInputError(doc(R"({"value": "1", )" + kRgba + "}"), "points[0].value",
                     "expected a number");
    expectInputError(doc(R"({"percentile": 100.5, )" + kRgba + "}"), "points[0].percentile",
                     "[0, 100]");
    expectInputError(doc(R"({"percentile": -1, )" + kRgba + "}"), "points[0].percentile",
                     "[0, 100]");
    expectInputError(doc(R"({"fraction": 1.01, )" + kRgba + "}"), "points[0].fraction",
                     "outside [0, 1]");
    expectInputError(doc(R"({"percentile": 50, )" + kRgba + "}"), "points[0].percentile",
                     "histogram", rangeStats(0, 255));
}

TEST(TransferFunctionTest, RefusesJsonSyntaxErrorsAndNonFiniteNumbersWithTheParserMessage) {
    expectInputError(R"({"points": [)", "(json)", "byte 13");
    expectInputError(R"({"points": [)", "(json)", "parse error");
    expectInputError(doc(R"({"value": NaN, )" + kRgba + "}"), "(json)", "syntax error");
    expectInputError(doc(R"({"value": 1e999, )" + kRgba + "}"), "(json)", "not a finite number");
    expectInputError(doc(R"({"value": 1, "rgba": [1, 1, 1, -1e999]})"), "(json)",
                     "not a finite number");
}

TEST(TransferFunctionTest, PresetsAreLookedUpByNameOnlyAndUnknownNamesAreNotEchoed) {
    const auto stats = rangeStats(0, 255, {10, 5, 5, 5});
    EXPECT_TRUE(TransferFunction::isPreset("ct-bone"));
    const std::vector<std::string> hostile{
        "no-such-preset",     "../../etc/passwd", "/etc/hostname", "x.json", "ct-bone/../x", "",
        std::string(64, '/'), "ct-bone.json"};
    for (const std::string& bad : hostile) {
        EXPECT_FALSE(TransferFunction::isPreset(bad)) << bad;
        try {
            TransferFunction::preset(bad, stats);
            ADD_FAILURE() << "accepted preset '" << bad << "'";
        } catch (const RenderInputError& e) {
            EXPECT_EQ(e.file(), "presets");
            EXPECT_EQ(e.field(), "name");
            const std::string what = e.what();
            EXPECT_NE(what.find("ct-bone, ct-skin, grey, mr, smoke, vessels"), std::string::npos)
                << what;
            if (!bad.empty()) {
                EXPECT_EQ(what.find(bad), std::string::npos) << what;
            }
        }
    }
}

TEST(TransferFunctionTest, FromPointsChecksEachPointAndMatchesTheParser) {
    const auto stats = rangeStats(0, 255, {10, 5, 5, 5});
    const std::vector<PointSpec> points{{Placement::Fraction, 0.5, {1, 0, 0, 0.5f}},
                                        {Placement::Value, 10, {0, 1, 0, 0.25f}},
                                        {Placement::Percentile, 50, {0, 0, 1, 1}}};
    const auto a = TransferFunction::fromPoints(points, "msg", stats, "m", true);
    const auto b = TransferFunction::parse(doc(point("fraction", 0.5, {1, 0, 0, 0.5f}) + ", " +
                                               point("value", 10, {0, 1, 0, 0.25f}) + ", " +
                                               point("percentile", 50, {0, 0, 1, 1})),
                                           "doc.json", stats);
    EXPECT_TRUE(a.sameFunction(b));
    EXPECT_EQ(a.contentHash(), b.contentHash());
    ASSERT_EQ(a.points().size(), 3u);
    EXPECT_EQ(a.points()[0].value, 10.0); // sorted by value
    EXPECT_EQ(a.shading(), std::optional<bool>(true));

    const double nan = std::numeric_limits<double>::quiet_NaN();
    const double inf = std::numeric_limits<double>::infinity();
    const float fnan = std::numeric_limits<float>::quiet_NaN();
    const float finf = std::numeric_limits<float>::infinity();
    struct Bad {
        std::vector<PointSpec> points;
        std::string field;
    };
    const std::vector<Bad> bad{
        {{}, "points"},
        {std::vector<PointSpec>(TransferFunction::kMaxPoints + 1, points[1]), "points"},
        {{{Placement::Value, nan, {1, 1, 1, 1}}}, "points[0].value"},
        {{points[1], {Placement::Value, inf, {1, 1, 1, 1}}}, "points[1].value"},
        {{{Placement::Value, 1, {1, fnan, 1, 1}}}, "points[0].rgba[1]"},
        {{{Placement::Value, 1, {1, 1, 1, finf}}}, "points[0].rgba[3]"},
        {{{Placement::Value, 1, {1, 1, -0.5f, 1}}}, "points[0].rgba[2]"},
        {{{Placement::Fraction, 1.5, {1, 1, 1, 1}}}, "points[0].fraction"},
        {{points[0], {Placement::Percentile, -1, {1, 1, 1, 1}}}, "points[1].percentile"},
    };
    for (const auto& c : bad) {
        try {
            TransferFunction::fromPoints(c.points, "SetTransferFunction", stats);
            ADD_FAILURE() << "accepted points; expected an error on " << c.field;
        } catch (const RenderInputError& e) {
            EXPECT_EQ(e.file(), "SetTransferFunction");
            EXPECT_EQ(e.field(), c.field) << e.what();
        }
    }
}

TEST(TransferFunctionTest, SameFunctionComparesPlacedPointsAndDomainNotNames) {
    const auto stats = rangeStats(0, 255, {10, 5, 5, 5});
    const auto a = TransferFunction::parse(doc(point("value", 7, {1, 0, 0, 0.5f})), "a", stats);
    auto renamed = TransferFunction::fromPoints({{Placement::Value, 7, {1, 0, 0, 0.5f}}}, "b",
                                                stats, "other name", false);
    EXPECT_TRUE(a.sameFunction(renamed));
    const auto moved =
        TransferFunction::fromPoints({{Placement::Value, 8, {1, 0, 0, 0.5f}}}, "c", stats);
    EXPECT_FALSE(a.sameFunction(moved));
    EXPECT_NE(a.contentHash(), moved.contentHash());
    const auto recoloured =
        TransferFunction::fromPoints({{Placement::Value, 7, {1, 0, 0, 0.25f}}}, "d", stats);
    EXPECT_FALSE(a.sameFunction(recoloured));
    const auto otherVolume = TransferFunction::parse(doc(point("value", 7, {1, 0, 0, 0.5f})), "e",
                                                     rangeStats(0, 4095, {10, 5, 5, 5}));
    EXPECT_FALSE(a.sameFunction(otherVolume)); // another domain: another table
}

TEST(TransferFunctionTest, PercentilesCountOnlyTheVoxelsAboveTheMostPopulatedBin) {
    // 10 bins of width 10; bin 0 is the background; 100 voxels lie above it.
    const auto stats = rangeStats(0, 100, {1000, 0, 10, 10, 20, 0, 40, 10, 5, 5});
    EXPECT_EQ(stats.modeBin(), 0u);
    EXPECT_DOUBLE_EQ(stats.percentile(0), 20.0); // first non-empty bin above the mode
    EXPECT_DOUBLE_EQ(stats.percentile(10), 30.0);
    EXPECT_DOUBLE_EQ(stats.percentile(30), 45.0);
    EXPECT_DOUBLE_EQ(stats.percentile(50), 62.5);
    EXPECT_DOUBLE_EQ(stats.percentile(100), 100.0);
    // A mode in the middle: only what lies above it counts.
    const auto middle = rangeStats(0, 100, {5, 5, 100, 10, 10});
    EXPECT_DOUBLE_EQ(middle.percentile(0), 60.0);
    EXPECT_DOUBLE_EQ(middle.percentile(50), 80.0);
    // Nothing above the mode: every voxel counts.
    const auto top = rangeStats(0, 40, {10, 0, 0, 90});
    EXPECT_DOUBLE_EQ(top.percentile(5), 5.0);
    EXPECT_NEAR(top.percentile(50), 30.0 + 40.0 / 90.0 * 10.0, 1e-12);
    EXPECT_THROW(rangeStats(0, 1).percentile(50), std::invalid_argument);
    EXPECT_THROW(rangeStats(0, 1, {0, 0}).percentile(50), std::invalid_argument);
}

TEST(TransferFunctionTest, PlacesByValueFractionAndPercentileThenSortsStably) {
    const auto stats = rangeStats(-1000, 1988, {1000, 0, 10, 10, 20, 0, 40, 10, 5, 5});
    const auto tf = TransferFunction::parse(doc(point("percentile", 50, {0, 0, 0, 0.1f}) + ", " +
                                                point("fraction", 0.25, {0, 0, 0, 0.2f}) + ", " +
                                                point("value", 1200, {0, 0, 0, 0.3f}) + ", " +
                                                point("value", -253, {0, 0, 0, 0.4f})),
                                            "mixed.json", stats);
    ASSERT_EQ(tf.points().size(), 4u);
    EXPECT_DOUBLE_EQ(tf.points()[0].value,
                     -253.0); // fraction 0.25: placed first in the file...
    EXPECT_EQ(tf.points()[0].rgba[3], 0.2f);
    EXPECT_DOUBLE_EQ(tf.points()[1].value, -253.0); // ...so it stays before the equal value
    EXPECT_EQ(tf.points()[1].rgba[3], 0.4f);
    EXPECT_NEAR(tf.points()[2].value, -1000 + 62.5 / 100 * 2988, 1e-9); // percentile 50
    EXPECT_DOUBLE_EQ(tf.points()[3].value, 1200.0);
    EXPECT_EQ(tf.domainMin(), -1000.0);
    EXPECT_EQ(tf.domainMax(), 1988.0);
}

TEST(TransferFunctionTest, EvaluatesLinearlyBetweenPointsWithStepsAndClamping) {
    const auto tf = TransferFunction::parse(doc(point("value", 10, {0, 0, 0, 0}) + ", " +
                                                point("value", 20, {1, 0.5f, 0, 0.8f}) + ", " +
                                                point("value", 30, {0, 1, 0, 0.2f}) + ", " +
                                                point("value", 30, {0, 0, 1, 0.6f})),
                                            "t.json", rangeStats(0, 100));
    using A = std::array<float, 4>;
    EXPECT_EQ(tf.evaluate(-5), (A{0, 0, 0, 0}));
    EXPECT_EQ(tf.evaluate(10), (A{0, 0, 0, 0}));
    EXPECT_EQ(tf.evaluate(20), (A{1, 0.5f, 0, 0.8f}));
    const auto mid = tf.evaluate(15);
    EXPECT_FLOAT_EQ(mid[0], 0.5f);
    EXPECT_FLOAT_EQ(mid[1], 0.25f);
    EXPECT_FLOAT_EQ(mid[3], 0.4f);
    EXPECT_FLOAT_EQ(tf.evaluate(27.5)[3], 0.35f);
    EXPECT_NEAR(tf.evaluate(std::nextafter(30.0, 0.0))[3], 0.2f, 1e-6); // left of the step
    EXPECT_EQ(tf.evaluate(30), (A{0, 0, 1, 0.6f}));                     // at and right of it
    EXPECT_EQ(tf.evaluate(1e9), (A{0, 0, 1, 0.6f}));
    const auto single = TransferFunction::parse(doc(point("value", 5, {0.1f, 0.2f, 0.3f, 0.4f})),
                                                "s.json", rangeStats(0, 1));
    EXPECT_EQ(single.evaluate(-1), (A{0.1f, 0.2f, 0.3f, 0.4f}));
    EXPECT_EQ(single.evaluate(99), (A{0.1f, 0.2f, 0.3f, 0.4f}));
}

bool near(const float* a, const std::array<float, 4>& b) {
    for (int c = 0; c < 4; ++c)
        if (std::abs(a[c] - b[c]) > 1e-6f) return false;
    return true;
}

/// True when entry `i` holds the RGBA of a point within half a cell that is more opaque than
/// the function at the entry: the peak rule's copy.
bool isSnapped(const TransferFunction& tf, const TransferFunctionTable& t, std::uint32_t i,
               double v) {
    for (const auto& p : tf.points()) {
        const double u = (p.value - t.domainMin) / (t.domainMax - t.domainMin) * (t.entries - 1);
        if (std::abs(u - double(i)) <= 0.5 && near(&t.rgba[4 * i], p.rgba) &&
            p.rgba[3] > tf.evaluate(v)[3])
            return true;
    }
    return false;
}

TEST(TransferFunctionTest, TableEntriesAreTheFunctionAtTheirValuesAndLookupInterpolatesThem) {
    const auto tf = TransferFunction::parse(doc(point("value", 12.3, {0, 0, 0, 0}) + ", " +
                                                point("value", 40.7, {1, 0.5f, 0, 0.8f}) + ", " +
                                                point("value", 61, {0, 1, 0, 0.2f}) + ", " +
                                                point("value", 61, {0, 0, 1, 0.6f}) + ", " +
                                                point("value", 90, {0.5f, 0.5f, 0.5f, 0.3f})),
                                            "t.json", rangeStats(0, 100));
    const auto t = tf.table(1.0, 257);
    EXPECT_EQ(t.entries, 257u);
    ASSERT_EQ(t.rgba.size(), 257u * 4);
    int snapped = 0;
    for (std::uint32_t i = 0; i < t.entries; ++i) {
        const double v = 100.0 * i / 256.0;
        const auto exact = tf.evaluate(v);
        if (!near(&t.rgba[4 * i], exact)) {
            EXPECT_TRUE(isSnapped(tf, t, i, v)) << "entry " << i;
            ++snapped;
        }
        const auto looked = t.lookup(v);
        EXPECT_TRUE(near(looked.data(),
                         {t.rgba[4 * i], t.rgba[4 * i + 1], t.rgba[4 * i + 2], t.rgba[4 * i + 3]}))
            << "entry " << i;
    }
    // The peak at 40.7 and the step's upper side at 61 lie between entries, above both.
    EXPECT_EQ(snapped, 2);
    const auto half = t.lookup(100.0 * 10.5 / 256.0), a = t.lookup(100.0 * 10 / 256.0),
               b = t.lookup(100.0 * 11 / 256.0);
    for (int c = 0; c < 4; ++c)
        EXPECT_NEAR(half[c], 0.5 * (a[c] + b[c]), 1e-6);
    EXPECT_EQ(t.lookup(-1e30), t.lookup(0));
    EXPECT_EQ(t.lookup(1e30), t.lookup(100));
    EXPECT_EQ(t.lookup(std::nan("")), t.lookup(0));
}

TEST(TransferFunctionTest, ConstantVolumeWidensTheDomainByOne) {
    const auto tf = TransferFunction::parse(doc(point("value", 7, {1, 1, 1, 0.5f})), "c.json",
                                            rangeStats(7, 7, {9}));
    EXPECT_EQ(tf.domainMin(), 7.0);
    EXPECT_EQ(tf.domainMax(), 8.0);
    const auto t = tf.table(1.0);
    EXPECT_FLOAT_EQ(t.lookup(7)[3], 0.5f);
    EXPECT_FALSE(t.transparent(7, 7));
}

TEST(TransferFunctionTest, OneValueWidePeakBetweenTwoEntriesSurvivesInTheTable) {
    // u16 domain, 4096 entries: a cell is ~16 values wide; the peak is 1 wide, off the grid.
    const double centre = 1000.3;
    const auto tf = TransferFunction::parse(doc(point("value", centre - 0.5, {1, 0, 0, 0}) + ", " +
                                                point("value", centre, {1, 0.2f, 0.1f, 0.8f}) +
                                                ", " + point("value", centre + 0.5, {1, 0, 0, 0})),
                                            "peak.json", rangeStats(0, 65535));
    const auto t = tf.table(1.0);
    const double cell = 65535.0 / 4095.0;
    const double u = centre / cell;
    ASSERT_GT(u - std::floor(u), 0.1); // strictly between two entries, not near either
    ASSERT_LT(u - std::floor(u), 0.9);
    const auto nearest = std::uint32_t(std::lround(u));
    EXPECT_FLOAT_EQ(t.rgba[4 * nearest + 3], 0.8f);
    EXPECT_FLOAT_EQ(t.rgba[4 * nearest + 1], 0.2f);
    EXPECT_GT(t.lookup(centre)[3], 0.0f);
    EXPECT_GT(t.maxOpacity(centre - 0.1, centre + 0.1), 0.0);
    EXPECT_GE(t.maxOpacity(centre, centre), 0.8f);
    EXPECT_TRUE(t.transparent(0, centre - 2 * cell));
    EXPECT_TRUE(t.transparent(centre + 2 * cell, 65535));
}

/// Exact maximum of the corrected opacity of `tf` over [lo, hi]: the function is linear
/// between points, so the ends and the points inside are enough; plus even samples.
double bruteForceMaxOpacity(const TransferFunction& tf, double lo, double hi, double step) {
    double best = 0;
    auto visit = [&](double v) {
        best = std::max<double>(best, TransferFunction::correctOpacity(tf.evaluate(v)[3], step));
    };
    visit(lo);
    visit(hi);
    for (const auto& p : tf.points()) {
        if (p.value < lo || p.value > hi) continue;
        visit(p.value);
        visit(std::nextafter(p.value, lo)); // the left side of a step
    }
    for (int i = 1; i < 64; ++i)
        visit(lo + (hi - lo) * i / 64.0);
    return best;
}

/// maxOpacity by a plain scan of entries floor(u(lo)) .. ceil(u(hi)).
double scanMaxOpacity(const TransferFunctionTable& t, double lo, double hi) {
    const auto u = [&](double v) {
        return std::clamp((v - t.domainMin) / (t.domainMax - t.domainMin) * (t.entries - 1), 0.0,
                          double(t.entries - 1));
    };
    float best = 0;
    for (auto i = std::uint32_t(std::floor(u(std::min(lo, hi))));
         i <= std::uint32_t(std::ceil(u(std::max(lo, hi)))); ++i)
        best = std::max(best, t.rgba[4 * i + 3]);
    return best;
}

TEST(TransferFunctionTest, MaxOpacityNeverMissesANarrowPeakRandomised) {
    std::mt19937_64 rng(20240607);
    std::uniform_real_distribution<double> unit(0.0, 1.0);
    for (int trial = 0; trial < 300; ++trial) {
        const double lo = -1000 + 2000 * unit(rng), span = std::pow(10.0, 4 * unit(rng) - 1);
        const auto entries = std::uint32_t(2 + rng() % 300);
        std::string points = point("value", lo - 1, {0, 0, 0, 0});
        for (int k = 0, n = int(1 + rng() % 5); k < n; ++k) {
            const double c = lo + span * unit(rng),
                         w = span / entries * std::pow(10.0, -3 * unit(rng));
            const float a = float(unit(rng) < 0.2 ? 1e-7 : unit(rng));
            points += ", " + point("value", c - w, {0, 0, 0, 0}) + ", " +
                      point("value", c, {1, 1, 1, a}) + ", " + point("value", c + w, {0, 0, 0, 0});
        }
        const auto tf =
            TransferFunction::parse(doc(points), "random.json", rangeStats(lo, lo + span));
        const double step = 0.25 + 2 * unit(rng);
        const auto t = tf.table(step, entries);
        for (int q = 0; q < 200; ++q) {
            double a = lo + span * (1.2 * unit(rng) - 0.1),
                   b = a + span * std::pow(10.0, -5 * unit(rng));
            if (q % 2) std::swap(a, b);
            const double exact = bruteForceMaxOpacity(tf, std::min(a, b), std::max(a, b), step);
            const double bound = t.maxOpacity(a, b);
            ASSERT_GE(bound, exact * (1 - 1e-6))
                << "trial " << trial << " [" << a << ", " << b << "]";
            if (exact > 0) {
                ASSERT_GT(bound, 0.0);
            }
            ASSERT_EQ(bound, scanMaxOpacity(t, a, b)); // the sparse table answers as a scan would
        }
    }
}

TEST(TransferFunctionTest, OpacityCorrectionComposesNSamplesAtStepOneOverNIntoOneUnitStep) {
    for (const float a : {1e-6f, 0.01f, 0.3f, 0.9f, 0.999f}) {
        for (const int n : {1, 2, 3, 7, 64, 1000}) {
            const double aN = TransferFunction::correctOpacity(a, 1.0 / n);
            double transmitted = 1.0;
            for (int i = 0; i < n; ++i)
                transmitted *= 1.0 - aN;
            EXPECT_NEAR(1.0 - transmitted, a, 1e-5) << "a " << a << " n " << n;
        }
    }
    // The same through tables at two steps.
    const auto tf = TransferFunction::parse(
        doc(point("value", 0, {1, 1, 1, 0}) + ", " + point("value", 1, {1, 1, 1, 0.7f})),
        "ramp.json", rangeStats(0, 1));
    const auto one = tf.table(1.0), quarter = tf.table(0.25);
    for (const double v : {0.1, 0.5, 0.77, 1.0}) {
        const double aq = quarter.lookup(v)[3];
        EXPECT_NEAR(1.0 - std::pow(1.0 - aq, 4), one.lookup(v)[3], 2e-3)
            << v; // linear between entries
    }
    EXPECT_EQ(TransferFunction::correctOpacity(0.0f, 0.5), 0.0f);
    EXPECT_EQ(TransferFunction::correctOpacity(1.0f, 0.01), 1.0f);
    EXPECT_GT(TransferFunction::correctOpacity(1e-30f, 1e-6), 0.0f);
    for (const double bad : {0.0, -1.0, std::nan(""), std::numeric_limits<double>::infinity()})
        EXPECT_THROW(tf.table(bad), std::invalid_argument) << bad;
    EXPECT_THROW(tf.table(1.0, 1), std::invalid_argument);
}

TEST(TransferFunctionTest, PresetsAreEmbeddedFromConfigsTf) {
    const std::vector<std::string> expected{"ct-bone", "ct-skin", "grey", "mr", "smoke", "vessels"};
    EXPECT_EQ(TransferFunction::presetNames(), expected);
    const auto stats = rangeStats(0, 255, {100, 5, 5, 5, 5, 5, 5, 5});
    for (const auto& name : expected) {
        const auto embedded = TransferFunction::preset(name, stats);
        const std::string path = std::string(BC_CONFIGS_DIR) + "/tf/" + name + ".json";
        const auto bytes = test::readFile(path);
        const auto file =
            TransferFunction::parse(std::string(bytes.begin(), bytes.end()), path, stats);
        EXPECT_EQ(embedded.name(), name);
        EXPECT_EQ(embedded.name(), file.name());
        EXPECT_EQ(embedded.description(), file.description());
        ASSERT_EQ(embedded.points().size(), file.points().size()) << name;
        for (std::size_t i = 0; i < file.points().size(); ++i) {
            EXPECT_EQ(embedded.points()[i].value, file.points()[i].value);
            EXPECT_EQ(embedded.points()[i].rgba, file.points()[i].rgba);
        }
    }
}

// ---- Presets on the real scans -----------------------------------------------------------

struct Scan {
    const char* name;
    const char* input; ///< in ../shared/data
    const char* grid;
};
const Scan kScans[] = {
    {"cthead", "stanford_cthead_256x256x113_uint16.raw", ""},
    {"CT_AVM", "CT_AVM_256x242x154_uint8.raw", ""},
    {"frog", "frog_500x470x136_uint8.raw", ""},
    {"pancreas", "tcia_pancreas_ct_dicom", ""},
    {"Iguana", "Iguana.nii.gz", ""},
    {"gaffer_smoke", "gaffer_smoke.vdb", "density"},
    {"hydrogen", "hydrogen_64x64x64_float32.raw", ""},
    {"headsq", "vtk_headsq_quarter_64x64x93_uint16.raw", ""},
};

void PrintTo(const Scan& scan, std::ostream* os) {
    *os << scan.name;
}

/// Calls `f` with every voxel of the scan, as read by the ingest readers.
template <class F> void forEachVoxel(const Scan& scan, F&& f) {
    brickstore::SourceSpec spec;
    spec.input = test::dataPath(scan.input);
    spec.gridName = scan.grid;
    auto source = brickstore::openSource(spec);
    const auto& info = source->info();
    std::vector<std::byte> slice(info.sliceBytes());
    for (std::uint64_t z = 0; z < info.dims[2]; ++z) {
        source->readSlices(1, slice);
        for (std::uint64_t i = 0; i < info.dims[0] * info.dims[1]; ++i)
            f(brickstore::voxelAsDouble(info.type, slice.data(), i));
    }
}

/// The stats a store of the scan would carry: value range and 256-bin level-0 histogram.
VolumeValueStats scanStats(const Scan& scan) {
    double lo = std::numeric_limits<double>::infinity(), hi = -lo;
    forEachVoxel(scan, [&](double v) { lo = std::min(lo, v), hi = std::max(hi, v); });
    VolumeValueStats stats{lo, hi, std::vector<std::uint64_t>(256, 0)};
    forEachVoxel(scan, [&](double v) {
        const double f = hi > lo ? (v - lo) / (hi - lo) * 256.0 : 0.0;
        ++stats.histogram[f > 0 ? std::min<std::size_t>(std::size_t(f), 255) : 0];
    });
    return stats;
}

class TransferFunctionPresetTest : public ::testing::TestWithParam<Scan> {};

TEST_P(TransferFunctionPresetTest, EveryPresetLeavesTheBackgroundBinTransparentAndShowsSomething) {
    const Scan& scan = GetParam();
    if (!test::haveData(scan.input)) return test::missingData(scan.input);
    const auto stats = scanStats(scan);
    const std::size_t mode = stats.modeBin();
    const double binWidth = (stats.valueMax - stats.valueMin) / double(stats.histogram.size());
    const double modeLo = stats.valueMin + binWidth * double(mode), modeHi = modeLo + binWidth;
    for (const auto& name : TransferFunction::presetNames()) {
        // The projections' window (render/MODES.md) is opaque by design: a maximum or a mean
        // through it is a grey level, and the background's is black.
        if (name == "grey") continue;
        const auto tf = TransferFunction::preset(name, stats);
        // Exact: the function is linear between points, so its ends and points suffice.
        auto maxAlpha = [&](double lo, double hi) {
            float a = std::max(tf.evaluate(lo)[3], tf.evaluate(hi)[3]);
            for (const auto& p : tf.points())
                if (p.value >= lo && p.value <= hi) a = std::max(a, p.rgba[3]);
            return a;
        };
        EXPECT_EQ(maxAlpha(modeLo, modeHi), 0.0f)
            << name << " on " << scan.name << ": background bin visible";
        EXPECT_GT(maxAlpha(stats.valueMin, stats.valueMax), 0.0f) << name << " on " << scan.name;
        const auto table = tf.table(1.0);
        EXPECT_TRUE(table.transparent(stats.valueMin, 0.5 * (modeLo + modeHi)))
            << name << " on " << scan.name;
        EXPECT_GT(table.maxOpacity(stats.valueMin, stats.valueMax), 0.0)
            << name << " on " << scan.name;
        double first = stats.valueMax, last = stats.valueMin;
        for (const auto& p : tf.points())
            if (p.rgba[3] > 0) first = std::min(first, p.value), last = std::max(last, p.value);
        std::printf(
            "[tf] %-12s %-8s range [%g, %g], mode bin [%g, %g), opaque points from %g to %g\n",
            scan.name, name.c_str(), stats.valueMin, stats.valueMax, modeLo, modeHi, first, last);
    }
}

INSTANTIATE_TEST_SUITE_P(RealScans, TransferFunctionPresetTest, ::testing::ValuesIn(kScans),
                         [](const ::testing::TestParamInfo<Scan>& info) {
                             return std::string(info.param.name);
                         });

} // namespace
} // namespace bc::render
