// The CPU raycaster: the GPU raycaster's optical model in float on the CPU. It must match the
// double-precision reference, agree with the GPU frame, and keep the skipping invariants.
#include "render/CpuRaycaster.h"
#include "RenderTestSupport.h"

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
    Raycaster gpu;
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
