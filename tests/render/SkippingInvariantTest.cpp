// The skipping invariant: the image with any combination of accelerations equals the image
// with none within max abs 2/255, over a 36-frame orbit (early termination off on both sides:
// it keeps its own bound) and over 30 random camera jumps (early termination on on both sides,
// as sessions draw), on every real dataset and preset. Small images (64^2) keep llvmpipe fast
// enough for CI; so do the frame counts (10 degrees between orbit frames).
#include "RenderTestSupport.h"

#include <random>

namespace bc::render {
namespace {

using test::TestStore;

constexpr double kTolerance = 2.0 / 255.0;

struct Case {
    std::string scan, preset;
    double orbitDistance = 1.0; ///< the frustum orbit's distance factor (Camera::orbit)
    /// Early termination on both sides of the frustum check: it ends rays, frustums start them,
    /// so the images must still agree (the 64^2 orbit checks frustums with it off); it keeps
    /// the 128^2 orbits, and the dense close-up ones of the large scans, affordable in CI.
    bool ert = true;
    int orbitFrames = 36; ///< frames of the frustum orbit (the 64^2 invariant always has 36)
};

// Test names and failure messages show the case, not its bytes.
void PrintTo(const Case& c, std::ostream* os) {
    *os << c.scan << " " << c.preset;
}

/// Every technique set of the benchmark except early termination, against plain.
struct Technique {
    const char* name;
    SkipMode skip;
    bool frustums;
};
constexpr Technique kTechniques[] = {{"bricks", SkipMode::Bricks, false},
                                     {"bricks+octree", SkipMode::All, false},
                                     {"bricks+frustums", SkipMode::Bricks, true},
                                     {"bricks+octree+frustums", SkipMode::All, true}};

std::uint32_t gEdge = 64; // image edge of the invariant paths

RenderOptions options(SkipMode skip, bool frustums = false, bool ert = false) {
    RenderOptions o;
    o.width = o.height = gEdge;
    o.earlyTermination = ert;
    o.skip = skip;
    o.occlusionFrustums = frustums;
    // The invariant is about the images: keep the timing policy from switching frustums off.
    o.occlusion.offFrames = 0;
    o.occlusion.probeEvery = 1u << 30;
    return o;
}

/// Renders `cameras` with plain raycasting and each technique set (one raycaster each, so
/// every one keeps its own pool and octrees across the path, as a session would), and checks
/// every frame against plain. Returns the technique sets' samples summed over the path.
std::vector<std::uint64_t> checkPath(TestStore& t, const TransferFunction& tf,
                                     const std::vector<Camera>& cameras, const std::string& what,
                                     bool ert = false) {
    GpuRaycaster plain;
    std::vector<std::unique_ptr<GpuRaycaster>> accelerated;
    for (std::size_t i = 0; i < std::size(kTechniques); ++i)
        accelerated.push_back(std::make_unique<GpuRaycaster>());
    std::vector<std::uint64_t> samples(std::size(kTechniques) + 1, 0);
    std::vector<double> worst(std::size(kTechniques), 0.0);
    std::vector<int> frustumFrames(std::size(kTechniques), 0);
    for (std::size_t f = 0; f < cameras.size(); ++f) {
        FrameStats s;
        const Image reference =
            test::gpuFrame(t, plain, tf, cameras[f], options(SkipMode::None, false, ert), &s);
        samples[0] += s.samples;
        for (std::size_t i = 0; i < std::size(kTechniques); ++i) {
            const Image image =
                test::gpuFrame(t, *accelerated[i], tf, cameras[f],
                               options(kTechniques[i].skip, kTechniques[i].frustums, ert), &s);
            samples[i + 1] += s.samples;
            frustumFrames[i] += s.occlusionUsed;
            const double maxAbs = compareImages(image, reference).maxAbs;
            worst[i] = std::max(worst[i], maxAbs);
            EXPECT_LE(maxAbs, kTolerance) << what << " frame " << f << ", " << kTechniques[i].name;
        }
    }
    for (std::size_t i = 0; i < std::size(kTechniques); ++i)
        std::printf("[invariant] %-36s %-22s worst max abs %.1f/255, samples %.3f of plain, "
                    "frustums used in %d of %zu frames\n",
                    what.c_str(), kTechniques[i].name, worst[i] * 255.0,
                    double(samples[i + 1]) / double(std::max<std::uint64_t>(samples[0], 1)),
                    frustumFrames[i], cameras.size());
    return samples;
}

/// The store of a case's scan (32^3 bricks), or nullptr when the scan is missing.
std::unique_ptr<TestStore> caseStore(const Case& c) {
    auto spec = test::realScan(c.scan);
    if (!spec) return nullptr;
    test::glContext();
    return test::ingestSpec(*spec, {32, 2, 8});
}

std::string caseName(const ::testing::TestParamInfo<Case>& info) {
    std::string s = info.param.scan + "_" + info.param.preset;
    for (char& ch : s)
        if (ch == '-') ch = '_';
    return s;
}

class SkippingInvariant : public ::testing::TestWithParam<Case> {};

TEST_P(SkippingInvariant, EveryTechniqueMatchesPlainOverA36FrameOrbit) {
    const Case c = GetParam();
    auto t = caseStore(c);
    if (!t) return test::missingData("scan " + c.scan);
    const auto tf = TransferFunction::preset(c.preset, t->stats);
    const Box box = LevelGeometry::of(*t->store, 0).box;
    std::vector<Camera> path;
    for (int f = 0; f < 36; ++f)
        path.push_back(Camera::orbit(box, 10.0 * f, 20.0 + 10.0 * std::sin(f * 0.2)));
    const auto samples = checkPath(*t, tf, path, c.scan + " " + c.preset + " orbit");
    EXPECT_LE(samples[2], samples[1]) << "octrees sampled more than bricks alone";
}

TEST_P(SkippingInvariant, EveryTechniqueMatchesPlainOver30RandomJumps) {
    const Case c = GetParam();
    auto t = caseStore(c);
    if (!t) return test::missingData("scan " + c.scan);
    const auto tf = TransferFunction::preset(c.preset, t->stats);
    const Box box = LevelGeometry::of(*t->store, 0).box;
    std::mt19937 rng(20261201);
    std::uniform_real_distribution<double> az(0, 360), el(-80, 80), dist(0.35, 1.6);
    std::vector<Camera> path;
    for (int f = 0; f < 30; ++f) // distances below ~0.5 put the eye inside the volume
        path.push_back(Camera::orbit(box, az(rng), el(rng), dist(rng)));
    // Early termination on both sides, as a session draws: the orbit above checks every sample
    // behind the surfaces with it off, the jumps check the accelerations with it on.
    checkPath(*t, tf, path, c.scan + " " + c.preset + " jumps", true);
}

std::vector<Case> invariantCases() {
    std::vector<Case> cases;
    for (const test::ScanPreset& s : test::invariantScans())
        cases.push_back(Case{s.scan, s.preset});
    return cases;
}

INSTANTIATE_TEST_SUITE_P(RealScans, SkippingInvariant, ::testing::ValuesIn(invariantCases()),
                         caseName);

// Octrees leap over the empty space inside non-empty bricks of sparse angiography: fewer
// samples than brick skipping alone, the same image.
TEST(OctreeSkipping, LeapsInsideBricksOfSparseAngiographyWithoutChangingAPixel) {
    auto spec = test::realScan("CT_AVM");
    if (!spec) return test::missingData("scan CT_AVM");
    test::glContext();
    auto t = test::ingestSpec(*spec, {64, 2, 8});
    const auto tf = TransferFunction::preset("vessels", t->stats);
    const Camera camera = Camera::orbit(LevelGeometry::of(*t->store, 0).box, 120, 15);
    GpuRaycaster bricksOnly, octree;
    RenderOptions b = options(SkipMode::Bricks), a = options(SkipMode::All);
    b.width = b.height = a.width = a.height = 128;
    FrameStats sb, sa;
    const Image ib = test::gpuFrame(*t, bricksOnly, tf, camera, b, &sb);
    const Image ia = test::gpuFrame(*t, octree, tf, camera, a, &sa);
    const auto c = compareImages(ia, ib);
    test::printComparison("CT_AVM octree vs bricks", c);
    std::printf("[octree] samples %llu -> %llu, %llu leaps, rebuild %.2f ms (%llu bricks)\n",
                (unsigned long long)sb.samples, (unsigned long long)sa.samples,
                (unsigned long long)sa.octreeLeaps, sa.octreeRebuildMs,
                (unsigned long long)sa.octreeBricksRebuilt);
    EXPECT_LE(c.maxAbs, kTolerance);
    EXPECT_GT(sa.octreeLeaps, 0u);
    EXPECT_LT(double(sa.samples), 0.8 * double(sb.samples));
    EXPECT_GT(sa.octreeBricksRebuilt, 0u);
    // The same TF again: the octrees are reused, not rebuilt.
    test::gpuFrame(*t, octree, tf, camera, a, &sa);
    EXPECT_EQ(sa.octreeBricksRebuilt, 0u);
}

} // namespace
} // namespace bc::render

namespace bc::render {
namespace {

// Occlusion frustums need rays denser than half an octree leaf (the policy refuses otherwise),
// so their invariant runs at 128^2, on every real dataset: the large scans (frog, pancreas)
// orbit closer, where the rays are dense enough, with much of the volume outside the view so
// the box-minus-view pieces carry most of it.
class FrustumInvariant : public ::testing::TestWithParam<Case> {};

constexpr int kFrustumJumps = 12; ///< random jumps after the frustum orbit

TEST_P(FrustumInvariant, FrustumsOnTopOfOctreesMatchPlainOverAnOrbitAndJumpsAt128) {
    const Case c = GetParam();
    auto t = caseStore(c);
    if (!t) return test::missingData("scan " + c.scan);
    const auto tf = TransferFunction::preset(c.preset, t->stats);
    const Box box = LevelGeometry::of(*t->store, 0).box;
    gEdge = 128;
    GpuRaycaster plain, octree, frustums;
    std::mt19937 rng(7);
    std::uniform_real_distribution<double> az(0, 360), el(-80, 80), dist(0.35, 1.6);
    std::uint64_t sPlain = 0, sOctree = 0, sFrustums = 0;
    int used = 0;
    double worst = 0.0;
    const int frames = c.orbitFrames + kFrustumJumps;
    for (int f = 0; f < frames; ++f) {
        // the orbit, then the random jumps
        const Camera camera =
            f < c.orbitFrames ? Camera::orbit(box, 360.0 * f / c.orbitFrames, 20.0, c.orbitDistance)
                              : Camera::orbit(box, az(rng), el(rng), dist(rng));
        FrameStats sp, so, sf;
        RenderOptions po = options(SkipMode::None), oo = options(SkipMode::All),
                      fo = options(SkipMode::All, true);
        po.earlyTermination = oo.earlyTermination = fo.earlyTermination = c.ert;
        const Image a = test::gpuFrame(*t, plain, tf, camera, po, &sp);
        test::gpuFrame(*t, octree, tf, camera, oo, &so);
        const Image b = test::gpuFrame(*t, frustums, tf, camera, fo, &sf);
        sPlain += sp.samples;
        sOctree += so.samples;
        sFrustums += sf.samples;
        used += sf.occlusionUsed;
        const double maxAbs = compareImages(a, b).maxAbs;
        worst = std::max(worst, maxAbs);
        EXPECT_LE(maxAbs, kTolerance) << c.scan << " frame " << f << " (frustums "
                                      << (sf.occlusionUsed ? "used" : sf.occlusionReason) << ")";
    }
    gEdge = 64;
    std::printf("[frustums] %s %s: worst max abs %.1f/255; samples octree %.3f, +frustums %.3f "
                "of plain; frustums used in %d of %d frames\n",
                c.scan.c_str(), c.preset.c_str(), worst * 255.0, double(sOctree) / double(sPlain),
                double(sFrustums) / double(sPlain), used, frames);
    EXPECT_GT(used, c.orbitFrames / 2) << "the policy refused the frustums on most of the orbit";
    // A ray that starts inside a brick walks its octree from there and can take a sample the
    // walk from the brick's face would have leapt: allow a few in a hundred million.
    EXPECT_LE(double(sFrustums), double(sOctree) * (1.0 + 1e-7));
}

INSTANTIATE_TEST_SUITE_P(RealScans, FrustumInvariant,
                         ::testing::Values(Case{"cthead", "ct-skin"}, Case{"CT_AVM", "vessels"},
                                           Case{"frog", "mr", 0.42, true, 24},
                                           Case{"pancreas", "ct-bone", 0.28, true, 24},
                                           Case{"Iguana", "ct-bone"}, Case{"gaffer_smoke", "smoke"},
                                           Case{"hydrogen", "smoke"}, Case{"headsq", "mr"}),
                         caseName);

} // namespace
} // namespace bc::render

namespace bc::render {
namespace {

// The paper's "new incoming object" problem: a second object lies outside the first frame's
// view frustum, and the camera pans until it is in view. Frustums built from earlier frames
// know nothing of it; the box-minus-view pieces must bring it in, frame by frame.
TEST(FrustumInvariant, ObjectEnteringFromOutsideThePreviousViewIsNeverLost) {
    test::TempDir dir;
    const std::uint64_t nx = 128, ny = 64, nz = 64;
    std::vector<std::uint8_t> voxels(nx * ny * nz, 0);
    auto cube = [&](std::uint64_t x0, std::uint64_t x1) {
        for (std::uint64_t z = 20; z < 44; ++z)
            for (std::uint64_t y = 20; y < 44; ++y)
                for (std::uint64_t x = x0; x < x1; ++x)
                    voxels[(z * ny + y) * nx + x] = std::uint8_t(120 + (x * 7 + y * 3 + z) % 100);
    };
    cube(12, 36);  // in view from the start
    cube(92, 116); // outside the first view
    const std::string raw = dir.file("blocks_128x64x64_uint8.raw");
    test::writeFile(raw, voxels.data(), voxels.size());
    brickstore::SourceSpec spec;
    spec.input = raw;
    test::glContext();
    auto t = test::ingestSpec(spec, {16, 2, 4});
    const auto tf = TransferFunction::preset("ct-bone", t->stats);
    GpuRaycaster plain, frustums;
    RenderOptions a = options(SkipMode::None), b = options(SkipMode::All, true);
    a.width = a.height = b.width = b.height = 96;
    int used = 0;
    double rightmostAlpha = 0.0;
    for (int f = 0; f <= 10; ++f) {
        Camera c;
        c.target = {24.0 + 8.0 * f, 32.0, 32.0};
        c.eye = {24.0 + 8.0 * f, -200.0, 60.0};
        c.up = {0, 0, 1};
        c.fovYDeg = 10.0; // about 40 mm across at the cubes: the second cube starts unseen
        FrameStats sa, sb;
        const Image ia = test::gpuFrame(*t, plain, tf, c, a, &sa);
        const Image ib = test::gpuFrame(*t, frustums, tf, c, b, &sb);
        if (f == 0) {
            double alpha = 0; // the first view shows the first cube only
            for (std::size_t i = 3; i < ia.rgba.size(); i += 4)
                alpha += ia.rgba[i];
            EXPECT_GT(alpha, 1.0);
        }
        used += sb.occlusionUsed;
        const auto cmp = compareImages(ia, ib);
        EXPECT_LE(cmp.maxAbs, kTolerance)
            << "frame " << f << " (frustums " << (sb.occlusionUsed ? "used" : sb.occlusionReason)
            << ")";
        if (f == 10)
            for (std::size_t i = 3; i < ib.rgba.size(); i += 4)
                rightmostAlpha += ib.rgba[i];
    }
    EXPECT_GE(used, 8) << "the frustums were hardly used: the test proves little";
    EXPECT_GT(rightmostAlpha, 1.0) << "the second cube never came into view";
}

} // namespace
} // namespace bc::render
