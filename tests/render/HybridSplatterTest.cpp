// The hybrid splatter against the CPU reference on real scans, on a uniform block
// (no holes between splats), on a minified checkerboard (aliasing against a supersampled
// raycaster), and with occlusion culling on and off. No GL.
#include "render/HybridSplatter.h"
#include "RenderTestSupport.h"
#include "render/CpuRaycaster.h"

#include <chrono>
#include <cmath>
#include <utility>
#include <vector>

namespace bc::render {
namespace {

using test::TestStore;

RenderOptions options(std::uint32_t edge, bool ert = false) {
    RenderOptions o;
    o.width = o.height = edge;
    o.earlyTermination = ert;
    return o;
}

Image splatFrame(TestStore& t, HybridSplatter& s, const TransferFunction& tf, const Camera& c,
                 const RenderOptions& o, double* ms = nullptr) {
    FrameStats stats;
    const auto start = std::chrono::steady_clock::now();
    Image image = s.render(*t.store, *t.cache, tf, c, o, stats);
    if (ms)
        *ms = std::chrono::duration<double, std::milli>(std::chrono::steady_clock::now() - start)
                  .count();
    EXPECT_EQ(stats.samples, s.lastFrame().points + s.lastFrame().splats);
    return image;
}

double alphaSum(const Image& image) {
    double a = 0;
    for (std::size_t i = 3; i < image.rgba.size(); i += 4)
        a += image.rgba[i];
    return a;
}

/// Box filter of `image` by `factor` along both axes.
Image downsample(const Image& image, std::uint32_t factor) {
    Image out(image.width / factor, image.height / factor);
    for (std::uint32_t y = 0; y < out.height; ++y)
        for (std::uint32_t x = 0; x < out.width; ++x)
            for (std::uint32_t j = 0; j < factor * factor; ++j)
                for (int c = 0; c < 4; ++c)
                    out.pixel(x, y)[c] +=
                        image.pixel(x * factor + j % factor, y * factor + j / factor)[c] /
                        float(factor * factor);
    return out;
}

TransferFunction flatTf(double lo, double hi, float opacity, const VolumeValueStats& stats) {
    const std::string a = std::to_string(opacity);
    const std::string json = R"({"name":"flat","points":[{"value":)" + std::to_string(lo) +
                             R"(,"rgba":[1,0.8,0.6,)" + a + R"(]},{"value":)" + std::to_string(hi) +
                             R"(,"rgba":[1,0.8,0.6,)" + a + R"(]}]})";
    return TransferFunction::parse(json, "<flat>", stats);
}

struct Scan {
    std::string name, preset;
    double distance;  ///< Camera::orbit distance factor: 1 splats only, 2.5 points only
    double minPsnrDb; ///< at 64^2, a little below what was measured
    bool mixed;       ///< the view draws both points and splats
};

class SplatVersusReference : public ::testing::TestWithParam<Scan> {};

TEST_P(SplatVersusReference, IsWithinAStatedPsnrOfTheCpuReference) {
    const Scan scan = GetParam();
    auto spec = test::realScan(scan.name);
    if (!spec) return test::missingData("scan " + scan.name);
    auto t = test::ingestSpec(*spec, {32, 2, 8});
    const auto tf = TransferFunction::preset(scan.preset, t->stats);
    const Camera camera = Camera::orbit(LevelGeometry::of(*t->store, 0).box, 30, 20, scan.distance);
    for (std::uint32_t edge : {64u, 128u}) {
        HybridSplatter splatter;
        double ms = 0;
        const Image image = splatFrame(*t, splatter, tf, camera, options(edge), &ms);
        const Image ref = test::referenceFrame(*t, tf, camera, options(edge));
        const auto c = compareImages(image, ref);
        const auto& n = splatter.lastFrame();
        const std::string what = scan.name + " " + scan.preset + " x" +
                                 std::to_string(scan.distance).substr(0, 3) + " splat " +
                                 std::to_string(edge);
        test::printComparison(what + " vs reference", c);
        std::printf("[splat] %s %u^2: %.1f ms, %llu splats, %llu points, %llu leaves skipped\n",
                    scan.name.c_str(), edge, ms, (unsigned long long)n.splats,
                    (unsigned long long)n.points, (unsigned long long)n.leavesSkipped);
        EXPECT_TRUE(test::allFinite(image));
        EXPECT_GT(alphaSum(ref), 0.01 * edge * edge) << "the view shows almost nothing";
        if (edge == 64) {
            EXPECT_GE(c.psnrDb, scan.minPsnrDb);
            if (scan.mixed) {
                EXPECT_GT(n.points, 0u);
                EXPECT_GT(n.splats, 0u);
            }
        }
    }
}

INSTANTIATE_TEST_SUITE_P(RealScans, SplatVersusReference,
                         ::testing::Values(Scan{"headsq", "mr", 1.0, 33.5, false},
                                           Scan{"headsq", "mr", 1.6, 33.5, true},
                                           Scan{"hydrogen", "smoke", 1.0, 58.0, false},
                                           Scan{"hydrogen", "smoke", 2.5, 52.5, false}),
                         [](const auto& info) {
                             return info.param.name + "_" + info.param.preset + "_x" +
                                    std::to_string(int(info.param.distance * 10));
                         });

std::unique_ptr<TestStore> checkerStore() {
    auto source = brickstore::makeSynthetic(brickstore::SynthKind::Checker, {64, 64, 64}, 1);
    return test::ingestStore(*source, {16, 2, 8});
}

// Every voxel equally opaque: overlapping splats reconstruct a constant, so the face-on image
// of the block is flat inside (no holes, no ripple) and as opaque as the reference says.
TEST(HybridSplatter, UniformBlockRendersWithoutHoles) {
    auto t = checkerStore();
    const auto tf = flatTf(t->store->info().valueMin, t->store->info().valueMax, 0.02f, t->stats);
    const Box box = LevelGeometry::of(*t->store, 0).box;
    Camera camera;
    camera.orthographic = true;
    camera.target = box.centre();
    camera.eye = box.centre() + glm::dvec3(0, 0, 4.0 * box.size().z);
    camera.orthoHeight = 1.5 * box.size().y;
    RenderOptions o = options(64);
    o.shading = false;
    HybridSplatter splatter;
    const Image image = splatFrame(*t, splatter, tf, camera, o);
    const Image ref = test::referenceFrame(*t, tf, camera, o);
    // The block covers the middle 2/3 of the view; look 3 pixels inside its edge.
    double lo = 1, hi = 0, refMid = ref.pixel(32, 32)[3];
    for (std::uint32_t y = 14; y < 50; ++y)
        for (std::uint32_t x = 14; x < 50; ++x) {
            lo = std::min<double>(lo, image.pixel(x, y)[3]);
            hi = std::max<double>(hi, image.pixel(x, y)[3]);
        }
    std::printf("[splat] uniform block alpha inside: %.5f .. %.5f, reference %.5f\n", lo, hi,
                refMid);
    EXPECT_GT(splatter.lastFrame().splats, 0u);
    EXPECT_LE(hi - lo, 0.01 * hi);
    EXPECT_NEAR(0.5 * (lo + hi), refMid, 0.03);
}

double checkerRmse(TestStore& t, const TransferFunction& tf, const Camera& camera,
                   const std::string& what) {
    RenderOptions o = options(64), big = options(256);
    o.shading = big.shading = false;
    CpuRaycaster raycaster;
    FrameStats s;
    const Image super = downsample(raycaster.render(*t.store, *t.cache, tf, camera, big, s), 4);
    const Image cast = raycaster.render(*t.store, *t.cache, tf, camera, o, s);
    HybridSplatter splatter;
    double ms = 0;
    const Image splat = splatFrame(t, splatter, tf, camera, o, &ms);
    const auto cs = compareImages(splat, super), cr = compareImages(cast, super);
    test::printComparison(what + ": splatter vs 4x supersampled raycast", cs);
    test::printComparison(what + ": raycaster vs 4x supersampled raycast", cr);
    std::printf("[splat] %s: %llu points, %llu splats, %.1f ms\n", what.c_str(),
                (unsigned long long)splatter.lastFrame().points,
                (unsigned long long)splatter.lastFrame().splats, ms);
    EXPECT_GT(alphaSum(super), 0.01 * 64 * 64);
    return cs.rmse / cr.rmse;
}

TransferFunction checkerTf(const VolumeValueStats& stats) {
    const std::string json = R"({"name":"checker","points":[{"value":0,"rgba":[1,0.2,0.2,0.05]},)"
                             R"({"value":255,"rgba":[0.9,0.9,1,0.5]}]})";
    return TransferFunction::parse(json, "<checker>", stats);
}

// A checkerboard plate seen from far away, its 8-voxel cells about half a pixel wide (a
// quarter of the Nyquist period): the raycaster point-samples it into a moire; the splatter's
// points are filtered on screen and summed by coverage. Both against a 4x supersampled raycast.
TEST(HybridSplatter, MinifiedCheckerboardAliasesLessThanTheRaycaster) {
    auto source = brickstore::makeSynthetic(brickstore::SynthKind::Checker, {1024, 1024, 2}, 1);
    auto t = test::ingestStore(*source, {32, 2, 8});
    const auto tf = checkerTf(t->stats);
    const Box box = LevelGeometry::of(*t->store, 0).box;
    Camera camera;
    camera.target = box.centre();
    const double tilt = 25.0 * 3.14159265358979 / 180.0;
    camera.eye = box.centre() + 1800.0 * glm::dvec3(0, -std::sin(tilt), std::cos(tilt));
    const double ratio = checkerRmse(*t, tf, camera, "checker plate far");
    EXPECT_LT(ratio, 0.5); // measured 0.161 (RMSE 0.0455 vs 0.2822)
}

// The 64^3 checker cube at 2.5x the framing distance: cells about 2.4 pixels, barely
// minified. Reported, not asserted: there the splatter's wider kernel and larger silhouette
// (spheres reach past the box) cost as much as the raycaster's aliasing.
TEST(HybridSplatter, MildlyMinifiedCheckerCubeIsReported) {
    auto source = brickstore::makeSynthetic(brickstore::SynthKind::Checker, {64, 64, 64}, 1);
    auto t = test::ingestStore(*source, {16, 2, 8});
    const auto tf = checkerTf(t->stats);
    const Camera camera = Camera::orbit(LevelGeometry::of(*t->store, 0).box, 30, 20, 2.5);
    const double ratio = checkerRmse(*t, tf, camera, "checker cube 2.5x");
    std::printf("[splat] checker cube RMSE ratio splatter / raycaster %.3f\n", ratio);
}

// Culling skips only voxels whose pixels take no more colour: the same image, fewer voxels.
TEST(HybridSplatter, OcclusionCullingKeepsTheImageAndDrawsFewerVoxels) {
    auto spec = test::realScan("headsq");
    if (!spec) return test::missingData("scan headsq");
    auto t = test::ingestSpec(*spec, {32, 2, 8});
    const auto tf = TransferFunction::preset("ct-skin", t->stats);
    const Camera camera = Camera::orbit(LevelGeometry::of(*t->store, 0).box, 150, 10);
    HybridSplatterConfig off;
    off.occlusionCulling = false;
    HybridSplatter culling, plain(off);
    const Image a = splatFrame(*t, culling, tf, camera, options(64, true));
    const Image b = splatFrame(*t, plain, tf, camera, options(64, true));
    const auto c = compareImages(a, b);
    test::printComparison("headsq ct-skin culling on vs off", c);
    const auto& on = culling.lastFrame();
    const auto& all = plain.lastFrame();
    std::printf("[splat] culling: %llu drawn (%llu voxels, %llu bricks culled) vs %llu drawn\n",
                (unsigned long long)(on.points + on.splats), (unsigned long long)on.culled,
                (unsigned long long)on.bricksCulled, (unsigned long long)(all.points + all.splats));
    EXPECT_EQ(c.maxAbs, 0.0) << "culled voxels touch only pixels that take no more colour";
    EXPECT_GT(on.culled + on.bricksCulled, 0u);
    EXPECT_LT(on.points + on.splats, all.points + all.splats);
    EXPECT_EQ(all.culled, 0u);
}

// Points culled: slabs are cut as if nothing were culled, so every slab sums the same
// coverage and the image is the same to the bit (a 100^3 checker box, the paper's, seen far
// enough that every voxel is a point; its front faces saturate the pixels behind).
TEST(HybridSplatter, OcclusionCullingOfPointsKeepsEverySlabsSum) {
    auto source = brickstore::makeSynthetic(brickstore::SynthKind::Checker, {100, 100, 100}, 1);
    auto t = test::ingestStore(*source, {32, 2, 8});
    const auto tf = checkerTf(t->stats);
    const Camera camera = Camera::orbit(LevelGeometry::of(*t->store, 0).box, 30, 20, 2.1);
    HybridSplatterConfig off;
    off.occlusionCulling = false;
    HybridSplatter culling, plain(off);
    const Image a = splatFrame(*t, culling, tf, camera, options(128, true));
    const Image b = splatFrame(*t, plain, tf, camera, options(128, true));
    const auto& on = culling.lastFrame();
    std::printf("[splat] checker points: %llu drawn, %llu culled (%llu bricks), %llu slabs vs "
                "%llu slabs\n",
                (unsigned long long)on.points, (unsigned long long)on.culled,
                (unsigned long long)on.bricksCulled, (unsigned long long)on.slabs,
                (unsigned long long)plain.lastFrame().slabs);
    EXPECT_EQ(on.splats, 0u);
    EXPECT_GT(on.culled, 0u);
    EXPECT_LE(on.slabs, plain.lastFrame().slabs) << "bricks culled whole composite no slab";
    EXPECT_EQ(compareImages(a, b).maxAbs, 0.0); // was 0.0038 when culled points cut no slab
}

// An opaque block seen face-on: the front bricks make every pixel opaque, so the bricks
// behind them are skipped whole, unpinned, and the image does not change.
TEST(HybridSplatter, OcclusionCullingSkipsHiddenBricksWhole) {
    auto t = checkerStore();
    const auto tf = flatTf(t->store->info().valueMin, t->store->info().valueMax, 0.6f, t->stats);
    const Box box = LevelGeometry::of(*t->store, 0).box;
    Camera camera;
    camera.orthographic = true;
    camera.target = box.centre();
    camera.eye = box.centre() + glm::dvec3(0, 0, 4.0 * box.size().z);
    camera.orthoHeight = 0.8 * box.size().y;
    HybridSplatterConfig off;
    off.occlusionCulling = false;
    HybridSplatter culling, plain(off);
    const Image a = splatFrame(*t, culling, tf, camera, options(64, true));
    const Image b = splatFrame(*t, plain, tf, camera, options(64, true));
    const auto c = compareImages(a, b);
    test::printComparison("opaque block culling on vs off", c);
    const auto& on = culling.lastFrame();
    std::printf("[splat] opaque block: %llu drawn (%llu voxels, %llu bricks culled) vs %llu\n",
                (unsigned long long)(on.points + on.splats), (unsigned long long)on.culled,
                (unsigned long long)on.bricksCulled,
                (unsigned long long)(plain.lastFrame().points + plain.lastFrame().splats));
    EXPECT_EQ(c.maxAbs, 0.0) << "culled voxels touch only pixels that take no more colour";
    EXPECT_GT(on.bricksCulled, 0u);
    EXPECT_LT(on.points + on.splats, plain.lastFrame().points + plain.lastFrame().splats);
}

// The eye inside the volume: spheres that reach the eye plane have no ellipse and are left
// out; the rest still form a finite, non-empty picture close to the reference.
TEST(HybridSplatter, CameraInsideTheVolumeRendersFinite) {
    auto spec = test::realScan("headsq");
    if (!spec) return test::missingData("scan headsq");
    auto t = test::ingestSpec(*spec, {32, 2, 8});
    const auto tf = TransferFunction::preset("mr", t->stats);
    const Box box = LevelGeometry::of(*t->store, 0).box;
    Camera inside;
    inside.eye = box.centre() + glm::dvec3(0.0, -0.2 * box.size().y, 0.0);
    inside.target = box.centre() + glm::dvec3(0.0, 1.0, 0.0) * box.size().y;
    inside.up = {0, 0, 1};
    HybridSplatter splatter;
    double ms = 0;
    const Image image = splatFrame(*t, splatter, tf, inside, options(64), &ms);
    const Image ref = test::referenceFrame(*t, tf, inside, options(64));
    const auto c = compareImages(image, ref);
    test::printComparison("headsq camera inside: splat vs reference", c);
    std::printf("[splat] camera inside: %.1f ms, %llu splats\n", ms,
                (unsigned long long)splatter.lastFrame().splats);
    EXPECT_TRUE(test::allFinite(image));
    EXPECT_GT(alphaSum(image), 0.01 * 64 * 64);
    EXPECT_GE(c.psnrDb, 26.5); // measured 27.9
}

struct Variant {
    const char* what;
    bool exact, parallel;
};

bool sameCounts(const HybridSplatStats& a, const HybridSplatStats& b) {
    return a.points == b.points && a.splats == b.splats && a.culled == b.culled &&
           a.bricksCulled == b.bricksCulled && a.leavesSkipped == b.leavesSkipped &&
           a.slabs == b.slabs;
}

/// Renders `camera` with each acceleration on and off (culling and early termination on) and
/// checks them against the plain path: the paper's 2D table, drawn by one thread.
void expectAcceleratedMatchesPlain(TestStore& t, const TransferFunction& tf, const Camera& camera,
                                   std::uint32_t edge, const std::string& what) {
    const RenderOptions o = options(edge, true);
    const Variant variants[] = {{"paper table, serial (plain)", false, false},
                                {"paper table, parallel", false, true},
                                {"exact distance, serial", true, false},
                                {"exact distance, parallel", true, true}};
    std::vector<Image> images;
    std::vector<HybridSplatStats> counts;
    for (const Variant& v : variants) {
        HybridSplatterConfig config;
        config.exactDistanceFootprint = v.exact;
        config.parallelDraw = v.parallel;
        HybridSplatter splatter(config);
        double ms = 0;
        images.push_back(splatFrame(t, splatter, tf, camera, o, &ms));
        counts.push_back(splatter.lastFrame());
        const auto& n = counts.back();
        std::printf("[splat] %s, %s: %.1f ms, %llu points, %llu splats, %llu culled, %llu slabs\n",
                    what.c_str(), v.what, ms, (unsigned long long)n.points,
                    (unsigned long long)n.splats, (unsigned long long)n.culled,
                    (unsigned long long)n.slabs);
    }
    EXPECT_GT(alphaSum(images[0]), 0.01 * edge * edge) << "the view shows almost nothing";
    EXPECT_GT(counts[0].points, 0u);
    EXPECT_GT(counts[0].splats, 0u);
    // Bands of whole tiles see each pixel's operations in the serial order: the same bits.
    for (const auto& [serial, parallel] : {std::pair{0, 1}, std::pair{2, 3}}) {
        const auto c = compareImages(images[serial], images[parallel]);
        test::printComparison(what + ": " + variants[parallel].what + " vs serial", c);
        EXPECT_EQ(c.maxAbs, 0.0) << variants[parallel].what;
        EXPECT_TRUE(sameCounts(counts[serial], counts[parallel])) << variants[parallel].what;
    }
    // The exact distance differs from the paper's path by the 2D table's error (4e-5 of the
    // centre footprint, per splat): measured 7.7e-6 (headsq) and 1.3e-5 (checker box) max abs.
    const auto c = compareImages(images[3], images[0]);
    test::printComparison(what + ": accelerated vs plain", c);
    std::printf("[splat] %s: accelerated vs plain max abs %.2e, RMSE %.2e\n", what.c_str(),
                c.maxAbs, c.rmse);
    EXPECT_LE(c.maxAbs, 2e-4);
    EXPECT_EQ(counts[3].points, counts[0].points);
    EXPECT_EQ(counts[3].slabs, counts[0].slabs);
}

// The accelerations (the 1D footprint over the exact ray-centre distance, drawing in bands on
// every core) keep the image: on a real scan in a mixed view and on the paper's checker box.
TEST(HybridSplatter, AcceleratedDrawingKeepsThePlainImageOfARealScan) {
    auto spec = test::realScan("headsq");
    if (!spec) return test::missingData("scan headsq");
    auto t = test::ingestSpec(*spec, {32, 2, 8});
    const auto tf = TransferFunction::preset("mr", t->stats);
    const Camera camera = Camera::orbit(LevelGeometry::of(*t->store, 0).box, 30, 20, 1.6);
    expectAcceleratedMatchesPlain(*t, tf, camera, 64, "headsq mr x1.6 64^2");
}

TEST(HybridSplatter, AcceleratedDrawingKeepsThePlainImageOfTheCheckerBox) {
    auto source = brickstore::makeSynthetic(brickstore::SynthKind::Checker, {100, 100, 100}, 1);
    auto t = test::ingestStore(*source, {32, 2, 8});
    const auto tf = checkerTf(t->stats);
    const Camera camera = Camera::orbit(LevelGeometry::of(*t->store, 0).box, 30, 20, 1.8);
    expectAcceleratedMatchesPlain(*t, tf, camera, 128, "checker box x1.8 128^2");
}

TEST(HybridSplatter, RejectsABadConfigNamingTheField) {
    HybridSplatterConfig c;
    c.radiusVoxels = 0.1;
    try {
        HybridSplatter s(c);
        FAIL() << "no throw";
    } catch (const std::invalid_argument& e) {
        EXPECT_NE(std::string(e.what()).find("radiusVoxels"), std::string::npos);
    }
    c = {};
    c.tilePixels = 0;
    EXPECT_THROW(HybridSplatter{c}, std::invalid_argument);
    c = {};
    c.sigmaOverRadius = -1;
    EXPECT_THROW(HybridSplatter{c}, std::invalid_argument);
}

} // namespace
} // namespace bc::render
