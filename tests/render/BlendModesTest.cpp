// The other modes than composite (RenderOptions::mode, render/MODES.md): maximum, minimum and
// average projections and the isosurface. The skip tables keep every value a mode may need;
// on every shared scan the CPU raycaster draws the float64 reference's image (>= 50 dB at the
// same step) and skipping and early termination change no pixel; bad input names its field.
#include "RenderTestSupport.h"
#include "render/BrickPlan.h"
#include "render/CpuRaycaster.h"
#include "render/GpuRaycaster.h"
#include "render/ReferenceRenderer.h"
#include "render/detail/CpuRay.h"

#include <algorithm>
#include <cmath>
#include <cstdint>
#include <utility>
#include <vector>

namespace bc::render {
namespace {

using test::TestStore;

PointSpec at(double value, float a) {
    return {Placement::Value, value, {0.8f, 0.6f, 0.4f, a}};
}

/// A generated 32^3 phantom in bricks of 16.
std::unique_ptr<TestStore> phantom() {
    auto source = brickstore::makeSynthetic(brickstore::SynthKind::Phantom, {32, 32, 32}, 1);
    return test::ingestStore(*source, {16, 2, 4});
}

/// Visible from 300 to 600 only.
TransferFunction band() {
    return TransferFunction::fromPoints(
        {at(0, 0), at(300, 0), at(400, 0.5f), at(600, 0.5f), at(600.5, 0), at(1000, 0)}, "band",
        test::unitStats());
}

/// The table position of `value` in `t`.
double entryOf(const TransferFunctionTable& t, double value) {
    return (value - t.domainMin) / (t.domainMax - t.domainMin) * double(t.entries - 1);
}

TEST(SkipTables, EachModeKeepsTheValuesItMayNeed) {
    const TransferFunctionTable unit = band().table(1.0, kClassificationTableEntries);
    // Composite: the function itself.
    EXPECT_EQ(skipTableOf(unit, {}).rgba, unit.rgba);
    // Maximum: from the lowest visible value up; a range below it is transparent.
    const TransferFunctionTable mip = skipTableOf(unit, {BlendMode::Maximum, 0.0});
    EXPECT_TRUE(mip.transparent(0.0, 299.0));
    EXPECT_FALSE(mip.transparent(0.0, 301.0));
    EXPECT_FALSE(mip.transparent(900.0, 1000.0)) << "above the band a maximum still counts";
    // Minimum: up to the highest visible value; a range above it is transparent.
    const TransferFunctionTable minip = skipTableOf(unit, {BlendMode::Minimum, 0.0});
    EXPECT_TRUE(minip.transparent(602.0, 1000.0));
    EXPECT_FALSE(minip.transparent(599.0, 1000.0));
    EXPECT_FALSE(minip.transparent(0.0, 10.0));
    // Isosurface: at or above the value; below it nothing can be hit.
    const TransferFunctionTable iso = skipTableOf(unit, {BlendMode::Isosurface, 700.0});
    EXPECT_TRUE(iso.transparent(0.0, 699.0));
    EXPECT_FALSE(iso.transparent(0.0, 700.0));
    EXPECT_FALSE(iso.transparent(999.0, 1000.0));
    // The boundary's entry is kept: every entry a value at or above 700 reads is visible.
    for (auto i = std::uint32_t(std::floor(entryOf(iso, 700.0))); i < iso.entries; ++i)
        ASSERT_GT(iso.rgba[4 * std::size_t(i) + 3], 0.0f) << i;
    // Average keeps everything; colours are the function's.
    const TransferFunctionTable average = skipTableOf(unit, {BlendMode::Average, 0.0});
    EXPECT_FALSE(average.transparent(0.0, 1.0));
    EXPECT_EQ(average.rgba[0], unit.rgba[0]);
    // A function with nothing visible: the projections keep nothing.
    const auto none =
        TransferFunction::fromPoints({at(0, 0), at(1000, 0)}, "none", test::unitStats())
            .table(1.0, kClassificationTableEntries);
    EXPECT_TRUE(skipTableOf(none, {BlendMode::Maximum, 0.0}).transparent(0.0, 1000.0));
    EXPECT_TRUE(skipTableOf(none, {BlendMode::Minimum, 0.0}).transparent(0.0, 1000.0));
}

TEST(SkipTables, ModesGetTheirOwnClassificationsAndShareThem) {
    const auto t = phantom();
    const TransferFunction tf = TransferFunction::preset("ct-bone", t->stats);
    ClassificationCache cache;
    const OccupancyConfig octree;
    const auto composite = cache.get(*t->store, 0, tf, &octree);
    const auto mip = cache.get(*t->store, 0, tf, &octree, nullptr, {BlendMode::Maximum, 0.0});
    EXPECT_NE(composite, mip);
    bool built = true;
    EXPECT_EQ(cache.get(*t->store, 0, tf, &octree, &built, {BlendMode::Maximum, 0.0}), mip);
    EXPECT_FALSE(built) << "a second MIP frame builds nothing";
    const auto iso1 = cache.get(*t->store, 0, tf, &octree, nullptr, {BlendMode::Isosurface, 100});
    const auto iso2 = cache.get(*t->store, 0, tf, &octree, nullptr, {BlendMode::Isosurface, 900});
    EXPECT_NE(iso1, iso2) << "each iso value has its octrees";
}

// The isosurface's hit (detail::isoHit): on a field that is linear along the ray (trilinear of
// a ramp is exact), the bisected hit lies within a hundredth of a voxel of the true crossing
// for every step and iso value, far inside the 0.05 voxel asked for.
TEST(IsoHit, TheBisectedHitLiesWithinAHundredthOfAVoxelOfTheCrossing) {
    constexpr int kEdge = 20;
    std::vector<float> ramp(std::size_t(kEdge) * kEdge * kEdge);
    for (int z = 0; z < kEdge; ++z)
        for (int y = 0; y < kEdge; ++y)
            for (int x = 0; x < kEdge; ++x)
                ramp[(std::size_t(z) * kEdge + y) * kEdge + x] = 10.0f * float(x) + 3.0f;
    detail::Frame f;
    const glm::vec3 rel(0.0f, 7.3f, 9.6f), dv = glm::normalize(glm::vec3(1.0f, 0.21f, -0.13f));
    double worst = 0;
    for (const float step : {0.25f, 1.0f, 2.5f})
        for (const float iso : {40.0f, 77.7f, 123.45f, 160.0f}) {
            f.stepMm = step;
            f.iso = iso;
            auto at = [&](float u) { return detail::fetch(ramp.data(), kEdge, rel + dv * u); };
            // The first sample at or above the value, as the march finds it.
            int k = 0;
            while (at((float(k) + 0.5f) * step) < iso)
                ++k;
            ASSERT_GT(k, 0);
            const float hit = detail::isoHit(f, 0.0f, 0, k, (float(k) + 0.5f) * step, at);
            // Voxel x of the stored brick sits at q.x = x: the ramp crosses iso at q.x = (iso - 3)
            // / 10.
            const double crossing = (double(iso) - 3.0) / 10.0 / double(dv.x);
            const double error = std::abs(double(hit) - crossing); // dv is a unit vector
            worst = std::max(worst, error);
            EXPECT_LT(error, 0.01) << "step " << step << ", iso " << iso;
        }
    std::printf("[iso] worst hit error %.2g voxel\n", worst);
}

/// The value where a preset first becomes visible: a surface the scan has.
double isoOf(const TransferFunction& tf) {
    const TransferFunctionTable t = tf.table(1.0, kClassificationTableEntries);
    for (std::uint32_t i = 0; i < t.entries; ++i)
        if (t.rgba[4 * std::size_t(i) + 3] > 0.0f)
            return t.domainMin +
                   (t.domainMax - t.domainMin) * (double(i) + 1.0) / double(t.entries - 1);
    return 0.5 * (t.domainMin + t.domainMax);
}

struct ModeCase {
    BlendMode mode;
    const char* name;
};

/// The function a mode is looked at through, as a user would pick it: the scan's preset for
/// the maximum and the isosurface; for the minimum a grey ramp opaque at the lowest value and
/// transparent from the middle of the range up (dark structures, and bricks above the middle
/// to skip); for the average a grey ramp over the whole range.
TransferFunction modeFunction(const ModeCase& m, const std::string& preset,
                              const VolumeValueStats& stats) {
    const double lo = stats.valueMin, hi = stats.valueMax, mid = 0.5 * (lo + hi);
    auto grey = [](double v, float a) {
        return PointSpec{Placement::Value, v, {1.0f - a, 1.0f - a, 1.0f, a}};
    };
    if (m.mode == BlendMode::Minimum)
        return TransferFunction::fromPoints({grey(lo, 1), grey(mid, 0), grey(hi, 0)}, "low", stats);
    if (m.mode == BlendMode::Average) return test::greyRamp(stats);
    return TransferFunction::preset(preset, stats);
}

const ModeCase kModes[] = {{BlendMode::Maximum, "mip"},
                           {BlendMode::Minimum, "minip"},
                           {BlendMode::Average, "average"},
                           {BlendMode::Isosurface, "iso"}};

/// Every shared scan, one preset each.
std::vector<test::ScanPreset> modeScans() {
    return {{"cthead", "ct-bone"},   {"CT_AVM", "vessels"}, {"frog", "mr"},
            {"pancreas", "ct-bone"}, {"Iguana", "ct-bone"}, {"gaffer_smoke", "smoke"},
            {"hydrogen", "smoke"},   {"headsq", "mr"}};
}

// The running skip leaves out a leaf or brick whose bound (its value range widened for float
// rounding) cannot pass a ray's maximum or minimum: the bounds hold every interpolated value,
// and a cell of eight equal values interpolates to that value exactly (lerps of the form
// a + t (b - a)), which is what lets a range of one value be its own bound.
TEST(RunningSkip, TheBoundsHoldEveryInterpolatedValueOfTheirRange) {
    std::uint32_t state = 12345u;
    auto uniform = [&state] { // xorshift32 in [0, 1)
        state ^= state << 13;
        state ^= state >> 17;
        state ^= state << 5;
        return float(state >> 8) * (1.0f / 16777216.0f);
    };
    for (const auto& [lo, hi] : std::vector<std::pair<float, float>>{{0.0f, 4095.0f},
                                                                     {-1024.0f, 3071.0f},
                                                                     {-3.0e4f, 5.0f},
                                                                     {0.02f, 0.1f},
                                                                     {0.1f, 0.1f},
                                                                     {7.0f, 7.0f}}) {
        const float upper = interpolatedUpper(lo, hi), lower = interpolatedLower(lo, hi);
        EXPECT_LE(upper - hi, 1e-5f * std::max(std::abs(lo), std::abs(hi)) + 1e-30f);
        for (int i = 0; i < 200000; ++i) {
            float v[8];
            const bool flat = i % 2 == 0; // all eight at the top or bottom, else random
            for (float& x : v)
                x = flat ? (i % 4 == 0 ? hi : lo) : lo + (hi - lo) * uniform();
            const glm::vec3 q(0.5f + uniform(), 0.5f + uniform(), 0.5f + uniform());
            const float value = detail::fetch(v, 2, q - glm::vec3(0.5f)); // a 2^3 brick
            if (flat) {
                ASSERT_EQ(value, v[0]) << "eight corners of " << v[0] << " at " << q.x;
            }
            ASSERT_LE(value, upper) << lo << ".." << hi;
            ASSERT_GE(value, lower) << lo << ".." << hi;
        }
        if (lo == hi) {
            EXPECT_TRUE(upper == hi && lower == lo) << "a range of one value " << lo;
        }
    }
}

class ModesOnScans : public ::testing::TestWithParam<test::ScanPreset> {};

TEST_P(ModesOnScans, TheCpuRaycasterDrawsTheReferencesImageAndSkippingChangesNoPixel) {
    const auto t = test::ingestRealScan(GetParam().scan);
    if (!t) return test::missingData("scan " + GetParam().scan);
    const Box box = LevelGeometry::of(*t->store, 0).box;
    const Camera camera = Camera::orbit(box, 35.0, 25.0);
    ReferenceRenderer reference;
    for (const ModeCase& m : kModes) {
        SCOPED_TRACE(m.name);
        const TransferFunction tf = modeFunction(m, GetParam().preset, t->stats);
        RenderOptions o;
        o.width = o.height = 96;
        o.mode = m.mode;
        o.isoValue = m.mode == BlendMode::Isosurface ? isoOf(tf) : 0.0;
        FrameStats refStats;
        const Image ref = reference.render(*t->store, *t->cache, tf, camera, o, refStats);
        FrameStats fast;
        const Image cpu = test::cpuFrame(*t, tf, camera, o, &fast);
        const ImageComparison c = compareImages(cpu, ref);
        test::printComparison(GetParam().scan + " " + m.name + " cpu vs reference", c);
        EXPECT_GE(c.psnrDb, 50.0);
        EXPECT_GT(test::alphaSum(ref), 1.0) << "the view shows something";
        // Skipping and early termination off: the same image, to the bit.
        RenderOptions plain = o;
        plain.skip = SkipMode::None;
        plain.earlyTermination = false;
        FrameStats slow;
        const Image unskipped = test::cpuFrame(*t, tf, camera, plain, &slow);
        EXPECT_EQ(compareImages(cpu, unskipped).maxAbs, 0.0);
        for (const SkipMode skip : {SkipMode::Bricks, SkipMode::All}) {
            RenderOptions s = o;
            s.skip = skip;
            s.earlyTermination = false;
            EXPECT_EQ(compareImages(test::cpuFrame(*t, tf, camera, s), unskipped).maxAbs, 0.0)
                << toString(skip) << " without early termination";
        }
        if (m.mode != BlendMode::Average) {
            EXPECT_LE(fast.samples, slow.samples) << "skipping took more samples";
        }
        if (m.mode == BlendMode::Maximum || m.mode == BlendMode::Minimum) {
            EXPECT_GT(fast.samplesRaising, 0u);
            EXPECT_LE(fast.samplesRaising, fast.samples);
            RenderOptions still = o; // the running skip alone off
            still.runningSkip = false;
            FrameStats stillStats;
            EXPECT_EQ(compareImages(test::cpuFrame(*t, tf, camera, still, &stillStats), cpu).maxAbs,
                      0.0)
                << "without the running skip";
            EXPECT_LE(fast.samples, stillStats.samples) << "the running skip added samples";
        }
        // The packets of rays, one ray's samples a vector at a time and the scalar march: the
        // same image, to the bit.
        for (const bool alongRay : {false, true}) {
            RenderOptions other = o;
            other.simd = alongRay;
            other.packets = false;
            EXPECT_EQ(compareImages(test::cpuFrame(*t, tf, camera, other), cpu).maxAbs, 0.0)
                << (alongRay ? "SIMD along one ray" : "scalar march");
        }
        // Along an orbit and after jumps (close up, from below, far), at 48^2: skipping and
        // early termination on and off, the same image.
        for (const Camera& other :
             {Camera::orbit(box, 95.0, 10.0), Camera::orbit(box, 200.0, -60.0, 0.5),
              Camera::orbit(box, 310.0, 45.0, 2.0)}) {
            RenderOptions small = o;
            small.width = small.height = 48;
            RenderOptions unskippedSmall = plain;
            unskippedSmall.width = unskippedSmall.height = 48;
            EXPECT_EQ(compareImages(test::cpuFrame(*t, tf, other, small),
                                    test::cpuFrame(*t, tf, other, unskippedSmall))
                          .maxAbs,
                      0.0)
                << "another view";
        }
        std::printf("[modes] %s %s: %llu samples skipping, %llu without\n", GetParam().scan.c_str(),
                    m.name, (unsigned long long)fast.samples, (unsigned long long)slow.samples);
    }
}

INSTANTIATE_TEST_SUITE_P(RealScans, ModesOnScans, ::testing::ValuesIn(modeScans()),
                         [](const auto& info) { return info.param.scan; });

// The GPU raycaster (llvmpipe in CI, 64^2), on every shared scan: each mode, whole and cut, is
// the reference's image, and skipping and early termination change no pixel, nor does the
// running skip of a maximum or minimum, which leaves samples out.
class ModesGl : public ::testing::TestWithParam<test::ScanPreset> {};

TEST_P(ModesGl, TheGpuRaycasterDrawsTheReferencesImageWholeAndCutAndSkippingChangesNoPixel) {
    const test::ScanPreset& scan = GetParam();
    const auto t = test::ingestRealScan(scan.scan);
    if (!t) return test::missingData("scan " + scan.scan);
    test::glContext();
    const Box box = LevelGeometry::of(*t->store, 0).box;
    const Camera camera = Camera::orbit(box, 35.0, 25.0);
    Clip cut;
    cut.cropped = true;
    for (int a = 0; a < 3; ++a) {
        cut.cropMin[a] = box.min[a] + 0.1 * box.size()[a];
        cut.cropMax[a] = box.min[a] + 0.85 * box.size()[a];
    }
    cut.planeCount = 1;
    cut.planes[0] = {{0.3, 1.0, -0.2}, -0.5 * box.size().y};
    ReferenceRenderer reference;
    GpuRaycaster gpu, plainGpu;
    std::uint64_t withRunning = 0, withoutRunning = 0; // samples of the maxima and minima
    for (const ModeCase& m : kModes)
        for (const bool cropped : {false, true}) {
            SCOPED_TRACE(std::string(m.name) + (cropped ? " cut" : " whole"));
            const TransferFunction tf = modeFunction(m, scan.preset, t->stats);
            RenderOptions o;
            o.width = o.height = 64;
            o.mode = m.mode;
            o.isoValue = m.mode == BlendMode::Isosurface ? isoOf(tf) : 0.0;
            if (cropped) o.clip = cut;
            FrameStats stats, fastStats;
            const Image ref = reference.render(*t->store, *t->cache, tf, camera, o, stats);
            const Image fast = test::gpuFrame(*t, gpu, tf, camera, o, &fastStats);
            const ImageComparison c = compareImages(fast, ref);
            test::printComparison(
                scan.scan + " " + m.name + (cropped ? " cut" : "") + " gpu vs reference", c);
            EXPECT_GE(c.psnrDb, 50.0);
            RenderOptions plain = o;
            plain.skip = SkipMode::None;
            plain.earlyTermination = false;
            EXPECT_EQ(compareImages(test::gpuFrame(*t, plainGpu, tf, camera, plain), fast).maxAbs,
                      0.0);
            if (m.mode != BlendMode::Maximum && m.mode != BlendMode::Minimum) continue;
            // The running skip alone off: the same image, and it left samples out.
            RenderOptions still = o;
            still.runningSkip = false;
            FrameStats stillStats;
            EXPECT_EQ(
                compareImages(test::gpuFrame(*t, plainGpu, tf, camera, still, &stillStats), fast)
                    .maxAbs,
                0.0)
                << "without the running skip";
            EXPECT_LE(fastStats.samples, stillStats.samples) << "the running skip added samples";
            withRunning += fastStats.samples;
            withoutRunning += stillStats.samples;
            // Along an orbit and after jumps (close up, from below), at 48^2: the running skip
            // on and every skipping off, the same image.
            for (const Camera& other :
                 {Camera::orbit(box, 95.0, 10.0), Camera::orbit(box, 200.0, -60.0, 0.5)}) {
                RenderOptions small = o, none = plain;
                small.width = small.height = none.width = none.height = 48;
                EXPECT_EQ(compareImages(test::gpuFrame(*t, gpu, tf, other, small),
                                        test::gpuFrame(*t, plainGpu, tf, other, none))
                              .maxAbs,
                          0.0)
                    << "another view";
            }
            std::printf("[modes] %s %s%s gpu: %llu samples with the running skip, %llu without\n",
                        scan.scan.c_str(), m.name, cropped ? " cut" : "",
                        (unsigned long long)fastStats.samples,
                        (unsigned long long)stillStats.samples);
        }
    EXPECT_LT(withRunning, withoutRunning) << "the running skip skipped nothing";
}

INSTANTIATE_TEST_SUITE_P(RealScans, ModesGl, ::testing::ValuesIn(modeScans()),
                         [](const auto& info) { return info.param.scan; });

TEST(ModesBadInput, AnIsoValueOutsideTheVolumeOrNotFiniteIsRefusedNamingIso) {
    const auto t = phantom();
    const TransferFunction tf = TransferFunction::preset("ct-bone", t->stats);
    const Camera camera = Camera::orbit(LevelGeometry::of(*t->store, 0).box, 30.0, 20.0);
    RenderOptions o;
    o.width = o.height = 32;
    o.mode = BlendMode::Isosurface;
    for (double bad : {tf.domainMax() + 1.0, tf.domainMin() - 1.0, std::nan("")}) {
        o.isoValue = bad;
        try {
            test::cpuFrame(*t, tf, camera, o);
            ADD_FAILURE() << "iso " << bad << " was drawn";
        } catch (const std::invalid_argument& e) {
            EXPECT_NE(std::string(e.what()).find("iso"), std::string::npos) << e.what();
        }
    }
    EXPECT_THROW(parseBlendMode("max"), std::invalid_argument);
}

} // namespace
} // namespace bc::render
