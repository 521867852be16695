// The GPU hybrid splatter against the CPU one: the same model, so the same image up
// to float rounding (early termination off), within the unterminated tail (on), on real scans
// that draw only splats, both, and only points; a uniform block without holes; and the
// footprint texture against SplatFootprint::lookup. GL (llvmpipe in CI): small images.
#include "render/GpuSplatter.h"
#include "RenderTestSupport.h"
#include "render/HybridSplatter.h"
#include "render/SplatGeometry.h"

#include <chrono>
#include <cmath>

namespace bc::render {
namespace {

using test::TestStore;

// Early termination off, llvmpipe: max abs 1.7e-5 (headsq x1.0), 8.0e-6 (x1.6), 1.8e-7
// (hydrogen x2.5), 4.1e-6 (uniform block) at 64^2, 2.4e-5 at 256^2: float rounding in the
// shaders, and the CPU's (index, half angle) footprint table (4e-5 of the centre value off
// the GPU's) against the exact ray distance. The bound leaves room for other drivers' exp and
// normalize; a wrong blend order or a pixel offset costs far more (0.06 .. 0.39 measured).
constexpr double kMaxAbsBound = 1e-3;
// A pixel past ertThreshold takes no more colour on the CPU; on the GPU it takes at most
// (1 - ertThreshold) more opacity, of colour at most 1.25 (diffuse 1 + specular 0.25).
constexpr double kBrightestColour = 1.25;

RenderOptions options(std::uint32_t edge, bool ert = false) {
    RenderOptions o;
    o.width = o.height = edge;
    o.earlyTermination = ert;
    return o;
}

double msSince(std::chrono::steady_clock::time_point t) {
    return std::chrono::duration<double, std::milli>(std::chrono::steady_clock::now() - t).count();
}

template <class Splatter>
Image frame(TestStore& t, Splatter& s, const TransferFunction& tf, const Camera& c,
            const RenderOptions& o, double& ms, FrameStats* statsOut = nullptr) {
    FrameStats stats;
    const auto start = std::chrono::steady_clock::now();
    Image image = s.render(*t.store, *t.cache, tf, c, o, stats);
    ms = msSince(start);
    EXPECT_EQ(stats.samples, s.lastFrame().points + s.lastFrame().splats);
    if (statsOut) *statsOut = stats;
    return image;
}

HybridSplatterConfig noCulling() {
    HybridSplatterConfig c;
    c.occlusionCulling = false;
    return c;
}

enum class Mix { SplatsOnly, Both, PointsOnly };

struct Scan {
    std::string name, preset;
    double distance; ///< Camera::orbit distance factor
    Mix mix;
};

void PrintTo(const Scan& s, std::ostream* os) {
    *os << s.name << " " << s.preset << " x" << s.distance;
}

class GpuSplatterVersusCpu : public ::testing::TestWithParam<Scan> {};

TEST_P(GpuSplatterVersusCpu, DrawsTheCpuSplattersImage) {
    const Scan scan = GetParam();
    auto spec = test::realScan(scan.name);
    if (!spec) return test::missingData("scan " + scan.name);
    test::glContext();
    auto t = test::ingestSpec(*spec, {32, 2, 8});
    const auto tf = TransferFunction::preset(scan.preset, t->stats);
    const Camera camera = Camera::orbit(LevelGeometry::of(*t->store, 0).box, 30, 20, scan.distance);
    const std::string what =
        scan.name + " " + scan.preset + " x" + std::to_string(scan.distance).substr(0, 3) + " 64^2";
    HybridSplatter cpu(noCulling());
    GpuSplatter gpu;
    double cpuMs = 0, gpuMs = 0;
    FrameStats gs;
    const Image a = frame(*t, cpu, tf, camera, options(64), cpuMs);
    const Image b = frame(*t, gpu, tf, camera, options(64), gpuMs, &gs);
    const auto c = compareImages(b, a);
    test::printComparison(what + " GPU vs CPU splat", c);
    std::printf("[gpusplat] %s: max abs %.2e; CPU %.1f ms, GPU %.1f ms (prepare+upload %.1f, "
                "draw %.1f, %u batches), %llu splats, %llu points, %llu slabs\n",
                what.c_str(), c.maxAbs, cpuMs, gpuMs, gs.uploadMs, gs.renderMs, gs.batches,
                (unsigned long long)gpu.lastFrame().splats,
                (unsigned long long)gpu.lastFrame().points,
                (unsigned long long)gpu.lastFrame().slabs);
    EXPECT_TRUE(test::allFinite(b));
    EXPECT_LE(c.maxAbs, kMaxAbsBound) << "at (" << c.maxAbsX << "," << c.maxAbsY << ")";
    EXPECT_EQ(gpu.lastFrame().splats, cpu.lastFrame().splats);
    EXPECT_EQ(gpu.lastFrame().points, cpu.lastFrame().points);
    EXPECT_EQ(gpu.lastFrame().slabs, cpu.lastFrame().slabs);
    EXPECT_EQ(gpu.lastFrame().leavesSkipped, cpu.lastFrame().leavesSkipped);
    EXPECT_EQ(gpu.lastFrame().splats > 0, scan.mix != Mix::PointsOnly);
    EXPECT_EQ(gpu.lastFrame().points > 0, scan.mix != Mix::SplatsOnly);
    double alpha = 0;
    for (std::size_t i = 3; i < b.rgba.size(); i += 4)
        alpha += b.rgba[i];
    EXPECT_GT(alpha, 0.01 * 64 * 64) << "the view shows almost nothing";

    // Early termination on: the CPU (culling on, as it is used) stops at the threshold.
    const RenderOptions ert = options(64, true);
    HybridSplatter culling;
    const Image ae = frame(*t, culling, tf, camera, ert, cpuMs);
    const Image be = frame(*t, gpu, tf, camera, ert, gpuMs);
    const auto ce = compareImages(be, ae);
    test::printComparison(what + " GPU vs CPU splat, ERT on", ce);
    std::printf("[gpusplat] %s ERT on: max abs %.2e; CPU %.1f ms (culling), GPU %.1f ms\n",
                what.c_str(), ce.maxAbs, cpuMs, gpuMs);
    EXPECT_LE(ce.maxAbs, kBrightestColour * (1.0 - ert.ertThreshold) + kMaxAbsBound)
        << "at (" << ce.maxAbsX << "," << ce.maxAbsY << ")";
}

INSTANTIATE_TEST_SUITE_P(RealScans, GpuSplatterVersusCpu,
                         ::testing::Values(Scan{"headsq", "mr", 1.0, Mix::SplatsOnly},
                                           Scan{"headsq", "mr", 1.6, Mix::Both},
                                           Scan{"hydrogen", "smoke", 2.5, Mix::PointsOnly}),
                         [](const auto& info) {
                             return info.param.name + "_" + info.param.preset + "_x" +
                                    std::to_string(int(info.param.distance * 10));
                         });

TransferFunction flatTf(double lo, double hi, float opacity, const VolumeValueStats& stats) {
    const std::string a = std::to_string(opacity);
    const std::string json = R"({"name":"flat","points":[{"value":)" + std::to_string(lo) +
                             R"(,"rgba":[1,0.8,0.6,)" + a + R"(]},{"value":)" + std::to_string(hi) +
                             R"(,"rgba":[1,0.8,0.6,)" + a + R"(]}]})";
    return TransferFunction::parse(json, "<flat>", stats);
}

// Every voxel equally opaque, face-on and orthographic: the splats reconstruct a constant.
TEST(GpuSplatter, UniformBlockRendersWithoutHoles) {
    test::glContext();
    auto source = brickstore::makeSynthetic(brickstore::SynthKind::Checker, {64, 64, 64}, 1);
    auto t = test::ingestStore(*source, {16, 2, 8});
    const auto tf = flatTf(t->store->info().valueMin, t->store->info().valueMax, 0.02f, t->stats);
    const Box box = LevelGeometry::of(*t->store, 0).box;
    Camera camera;
    camera.orthographic = true;
    camera.target = box.centre();
    camera.eye = box.centre() + glm::dvec3(0, 0, 4.0 * box.size().z);
    camera.orthoHeight = 1.5 * box.size().y;
    RenderOptions o = options(64);
    o.shading = false;
    GpuSplatter gpu;
    HybridSplatter cpu(noCulling());
    double gpuMs = 0, cpuMs = 0;
    const Image image = frame(*t, gpu, tf, camera, o, gpuMs);
    const Image ref = frame(*t, cpu, tf, camera, o, cpuMs);
    double lo = 1, hi = 0;
    for (std::uint32_t y = 14; y < 50; ++y) // 3 pixels inside the block's edge
        for (std::uint32_t x = 14; x < 50; ++x) {
            lo = std::min<double>(lo, image.pixel(x, y)[3]);
            hi = std::max<double>(hi, image.pixel(x, y)[3]);
        }
    const auto c = compareImages(image, ref);
    test::printComparison("uniform block GPU vs CPU splat", c);
    std::printf("[gpusplat] uniform block alpha inside %.5f .. %.5f, max abs %.2e; CPU %.1f ms, "
                "GPU %.1f ms\n",
                lo, hi, c.maxAbs, cpuMs, gpuMs);
    EXPECT_GT(gpu.lastFrame().splats, 0u);
    EXPECT_GT(lo, 0.1);
    EXPECT_LE(hi - lo, 0.01 * hi);
    EXPECT_LE(c.maxAbs, kMaxAbsBound);
}

// The shader's footprint (1D texture of the line integral, read at the exact ray distance)
// against the CPU's (index, half angle) table and the closed form, relative to the centre.
TEST(GpuSplatter, FootprintTextureMatchesTheCpuLookup) {
    const SplatFootprint fp;
    const std::vector<float> texels = GpuSplatter::footprintTexels(fp);
    ASSERT_EQ(texels.size(), GpuSplatter::kFootprintTexels);
    const double centre = fp.lineIntegral(0.0);
    double vsLookup = 0, vsExact = 0;
    for (int a = 0; a <= 30; ++a) {
        const double alpha = a * 3.14159265358979323846 / 180.0;
        for (int k = 0; k <= 4000; ++k) {
            const double i = k / 4000.0;
            const double gpu = GpuSplatter::sampleFootprint(texels, correctedDistance(i, alpha));
            vsLookup = std::max(vsLookup, std::abs(gpu - fp.lookup(i, alpha)) / centre);
            vsExact = std::max(vsExact, std::abs(gpu - fp.evaluate(i, alpha)) / centre);
        }
    }
    std::printf("[gpusplat] footprint texture (%u texels): max error %.2e vs lookup, %.2e vs "
                "closed form (of the centre value)\n",
                GpuSplatter::kFootprintTexels, vsLookup, vsExact);
    EXPECT_LE(vsExact, 2e-6);
    EXPECT_LE(vsLookup, SplatFootprint::kTableRelativeError + 2e-6);
    EXPECT_EQ(GpuSplatter::sampleFootprint(texels, 1.0), 0.0);
    EXPECT_EQ(GpuSplatter::sampleFootprint(texels, 1.5), 0.0);
}

TEST(GpuSplatter, RejectsABadConfigNamingTheField) {
    HybridSplatterConfig c;
    c.pointFilterPixels = 0.1;
    try {
        GpuSplatter s(c);
        FAIL() << "no throw";
    } catch (const std::invalid_argument& e) {
        EXPECT_NE(std::string(e.what()).find("pointFilterPixels"), std::string::npos);
    }
}

} // namespace
} // namespace bc::render
