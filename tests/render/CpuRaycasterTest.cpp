// The CPU raycaster: the GPU raycaster's optical model in float on the CPU. It must match the
// double-precision reference, agree with the GPU frame, and keep the skipping invariants.
#include "render/CpuRaycaster.h"
#include "RenderTestSupport.h"
#include "render/detail/CpuRay.h"

#include <random>

namespace bc::render {
namespace {

using test::TestStore;

struct Scan {
    std::string name, preset;
};

RenderOptions options(std::uint32_t edge = 128) {
    RenderOptions o;
    o.width = o.height = edge;
    o.earlyTermination = false;
    return o;
}

Image cpuFrame(TestStore& t, CpuRaycaster& r, const TransferFunction& tf, const Camera& c,
               const RenderOptions& o, FrameStats* stats = nullptr) {
    FrameStats s;
    Image image = r.render(*t.store, *t.cache, tf, c, o, s);
    if (stats) *stats = s;
    return image;
}

class CpuVersusReference : public ::testing::TestWithParam<Scan> {};

TEST_P(CpuVersusReference, MatchesTheDoublePrecisionReferenceAndTheGpuFrame) {
    const Scan scan = GetParam();
    auto spec = test::realScan(scan.name);
    if (!spec) return test::missingData("scan " + scan.name);
    auto t = test::ingestSpec(*spec, {32, 2, 8});
    const auto tf = TransferFunction::preset(scan.preset, t->stats);
    const Camera camera = Camera::orbit(LevelGeometry::of(*t->store, 0).box, 30, 20);
    CpuRaycaster cpu;
    FrameStats s;
    const Image image = cpuFrame(*t, cpu, tf, camera, options(), &s);
    const Image ref = test::referenceFrame(*t, tf, camera, options());
    const auto c = compareImages(image, ref);
    test::printComparison(scan.name + " " + scan.preset + " CPU raycaster vs reference", c);
    EXPECT_TRUE(test::allFinite(image));
    EXPECT_GE(c.psnrDb, 60.0);
    EXPECT_GE(c.ssim, 0.999);
    EXPECT_GT(s.samples, 0u);
    double alpha = 0;
    for (std::size_t i = 3; i < ref.rgba.size(); i += 4)
        alpha += ref.rgba[i];
    EXPECT_GT(alpha, 0.01 * 128 * 128) << "the view shows almost nothing, so proves nothing";
    // The GPU raycaster draws the same samples: the two agree to rounding.
    test::glContext();
    GpuRaycaster gpu;
    const Image g = test::gpuFrame(*t, gpu, tf, camera, options());
    const auto cg = compareImages(image, g);
    test::printComparison(scan.name + " CPU vs GPU raycaster", cg);
    EXPECT_LE(cg.maxAbs, 2.0 / 255.0);
}

INSTANTIATE_TEST_SUITE_P(RealScans, CpuVersusReference,
                         ::testing::Values(Scan{"cthead", "ct-skin"}, Scan{"CT_AVM", "vessels"},
                                           Scan{"frog", "mr"}, Scan{"pancreas", "ct-bone"},
                                           Scan{"hydrogen", "smoke"},
                                           Scan{"gaffer_smoke", "smoke"}),
                         [](const auto& info) {
                             std::string s = info.param.name + "_" + info.param.preset;
                             for (char& ch : s)
                                 if (ch == '-') ch = '_';
                             return s;
                         });

// Bricks and octrees change no pixel; early termination keeps its bound.
TEST(CpuRaycaster, SkippingIsExactAndEarlyTerminationKeepsItsBound) {
    auto spec = test::realScan("CT_AVM");
    if (!spec) return test::missingData("scan CT_AVM");
    auto t = test::ingestSpec(*spec, {32, 2, 8});
    const auto tf = TransferFunction::preset("vessels", t->stats);
    const Camera camera = Camera::orbit(LevelGeometry::of(*t->store, 0).box, 120, 15);
    CpuRaycaster none, bricks, all;
    RenderOptions on = options(), ob = options(), oa = options();
    on.skip = SkipMode::None;
    ob.skip = SkipMode::Bricks;
    oa.skip = SkipMode::All;
    FrameStats sn, sb, sa;
    const Image a = cpuFrame(*t, none, tf, camera, on, &sn);
    const Image b = cpuFrame(*t, bricks, tf, camera, ob, &sb);
    const Image c = cpuFrame(*t, all, tf, camera, oa, &sa);
    EXPECT_EQ(compareImages(a, b).maxAbs, 0.0);
    EXPECT_EQ(compareImages(a, c).maxAbs, 0.0);
    EXPECT_LT(sb.samples, sn.samples);
    EXPECT_LT(sa.samples, sb.samples);
    EXPECT_GT(sa.octreeLeaps, 0u);
    RenderOptions ert = oa;
    ert.earlyTermination = true;
    ert.ertThreshold = 0.9;
    const Image e = cpuFrame(*t, all, tf, camera, ert);
    EXPECT_LE(compareImages(a, e).maxAbs, (1.0 - 0.9) + 1.0 / 255.0);
}

// The box of sampled leaves (OccupancyTrees::sampledBoxes) narrows a ray's samples in a brick
// before the octree walk: every sample it leaves out lies in a leaf outside the box (or within
// rounding of one of its faces), and the first and last it keeps lie inside. Random boxes and
// rays, with axis-parallel, grazing and far-away ones, at several steps.
TEST(CpuRaycaster, SampledBoxClipLeavesOutOnlySamplesOutsideTheBox) {
    detail::Frame f;
    f.leaf = 8.0f;
    f.leafAxis = 8;
    std::mt19937 rng(7);
    std::uniform_real_distribution<float> unit(-1.0f, 1.0f);
    std::uniform_int_distribution<std::uint32_t> leafOf(0, 7);
    std::uint64_t leftOut = 0, kept = 0;
    for (int trial = 0; trial < 4000; ++trial) {
        f.stepMm = std::array{0.05f, 0.3f, 1.0f, 2.7f}[trial % 4];
        SampledBox box;
        for (int a = 0; a < 3; ++a) {
            const std::uint32_t i = leafOf(rng), j = leafOf(rng);
            box.lo[a] = std::min(i, j);
            box.hi[a] = std::max(i, j);
        }
        glm::vec3 dir(unit(rng), unit(rng), unit(rng));
        if (trial % 5 == 1) dir[trial % 3] = 0.0f;              // in an axis plane
        if (trial % 7 == 2) dir = glm::vec3(1.0f, 1e-6f, 0.0f); // grazing
        if (glm::length(dir) == 0.0f) dir = glm::vec3(0.0f, 0.0f, 1.0f);
        dir = glm::normalize(dir);
        const float far = trial % 11 == 3 ? 1.0e5f : 100.0f;
        const glm::vec3 target(32.0f + 40.0f * unit(rng), 32.0f + 40.0f * unit(rng),
                               32.0f + 40.0f * unit(rng));
        const glm::vec3 local = target - dir * far;
        const float t0 = far - 80.0f;
        const int kEnd0 = int(160.0f / f.stepMm);
        int k = 0, kEnd = kEnd0;
        const bool some =
            detail::clipToSampled(f, box, local, dir, 1.0f / dir, 1.0f / f.stepMm, t0, k, kEnd);
        // Sample j: in a leaf inside the box, outside it, or within rounding of a face (a
        // face on the brick's boundary is none: the box reaches past it).
        enum class Where { Inside, Outside, Face };
        auto where = [&](int j) {
            const float t = t0 + (float(j) + 0.5f) * f.stepMm;
            const glm::vec3 p = local + dir * t;
            const float eps = 1e-5f * (std::abs(t) + glm::length(local)) + 1e-4f;
            bool inside = true, face = false;
            for (int a = 0; a < 3; ++a) {
                const int leaf = std::clamp(int(std::floor(p[a] / f.leaf)), 0, f.leafAxis - 1);
                inside = inside && leaf >= int(box.lo[a]) && leaf <= int(box.hi[a]);
                const float lo = float(box.lo[a]) * f.leaf, hi = float(box.hi[a] + 1) * f.leaf;
                face = face || (box.lo[a] > 0 && std::abs(p[a] - lo) <= eps) ||
                       (int(box.hi[a]) < f.leafAxis - 1 && std::abs(p[a] - hi) <= eps);
            }
            return face ? Where::Face : inside ? Where::Inside : Where::Outside;
        };
        for (int j = 0; j < kEnd0; ++j) {
            if (some && j >= k && j < kEnd) {
                ++kept;
                continue;
            }
            ++leftOut;
            ASSERT_NE(where(j), Where::Inside)
                << "trial " << trial << ": sample " << j << " left out inside the box";
        }
        if (some) {
            EXPECT_NE(where(k), Where::Outside) << "trial " << trial << ": first kept sample";
            EXPECT_NE(where(kEnd - 1), Where::Outside) << "trial " << trial << ": last kept";
        }
    }
    EXPECT_GT(leftOut, 0u);
    EXPECT_GT(kept, 0u);
    // No leaf sampled: nothing is kept.
    int k = 0, kEnd = 10;
    const SampledBox none{{8, 8, 8}, {0, 0, 0}};
    EXPECT_FALSE(detail::clipToSampled(f, none, glm::vec3(0.0f), glm::vec3(1.0f, 0.0f, 0.0f),
                                       glm::vec3(1.0f), 1.0f, 0.0f, k, kEnd));
}

// Rays that start inside the volume, orthographic rays, and float data.
TEST(CpuRaycaster, CameraInsideOrthographicAndFloatDataMatchTheReference) {
    auto head = test::realScan("headsq");
    auto hydrogen = test::realScan("hydrogen");
    if (!head || !hydrogen) return test::missingData("scan headsq or hydrogen");
    auto t = test::ingestSpec(*head, {32, 2, 8});
    const auto tf = TransferFunction::preset("mr", t->stats);
    const Box box = LevelGeometry::of(*t->store, 0).box;
    Camera inside;
    inside.eye = box.centre() + glm::dvec3(0.0, -0.2 * box.size().y, 0.0);
    inside.target = box.centre() + glm::dvec3(0.0, 1.0, 0.0) * box.size().y;
    inside.up = {0, 0, 1};
    inside.fovYDeg = 60;
    Camera ortho = Camera::orbit(box, 45, 30);
    ortho.orthographic = true;
    ortho.orthoHeight = 2.0 * box.radius();
    CpuRaycaster cpu;
    for (const Camera& c : {inside, ortho}) {
        const auto cmp = compareImages(cpuFrame(*t, cpu, tf, c, options(96)),
                                       test::referenceFrame(*t, tf, c, options(96)));
        test::printComparison("headsq CPU raycaster (inside / ortho) vs reference", cmp);
        EXPECT_GE(cmp.psnrDb, 55.0);
    }
    auto h = test::ingestSpec(*hydrogen, {16, 2, 4});
    const auto smoke = TransferFunction::preset("smoke", h->stats);
    const Camera c = Camera::orbit(LevelGeometry::of(*h->store, 0).box, 10, 50);
    const auto cmp = compareImages(cpuFrame(*h, cpu, smoke, c, options(96)),
                                   test::referenceFrame(*h, smoke, c, options(96)));
    EXPECT_GE(cmp.psnrDb, 60.0);
}

} // namespace
} // namespace bc::render
