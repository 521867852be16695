#pragma once
// Shared by the render tests: one EGL context for the whole test binary (GL belongs to the
// thread that made it; GoogleTest runs every test on the main thread), stores ingested from
// the real scans into scratch folders, GPU-vs-reference helpers, and frames drawn in regions.
#include "../TestSupport.h"
#include "brickstore/BrickCache.h"
#include "brickstore/BrickStore.h"
#include "brickstore/Ingest.h"
#include "brickstore/Readers.h"
#include "render/BrickPlan.h"
#include "render/CpuRaycaster.h"
#include "render/EglContext.h"
#include "render/GpuRaycaster.h"
#include "render/ImageMetrics.h"
#include "render/ReferenceRenderer.h"
#include "render/TransferFunction.h"

#include <algorithm>
#include <cstdio>
#include <cstdlib>
#include <memory>
#include <optional>
#include <string>
#include <vector>

namespace bc::test {

/// The process's EGL context, created on first use. Fails the test when ctest runs it without
/// the label "gl" (BC_TEST_NO_GL=1, tests/CMakeLists.txt): it belongs in the gl filter there.
inline render::EglContext& glContext() {
    if (const char* noGl = std::getenv("BC_TEST_NO_GL"); noGl && std::string(noGl) == "1")
        ADD_FAILURE() << "this test needs an EGL context but has no ctest label \"gl\": add it "
                         "to the gl filter of its executable in tests/CMakeLists.txt";
    static render::EglContext context;
    static bool printed = (std::printf("[gl] %s, %s via %s\n", context.renderer().c_str(),
                                       context.version().c_str(), context.platform().c_str()),
                           true);
    (void)printed;
    return context;
}

/// A store ingested into a scratch folder, with a host cache over it.
struct TestStore {
    TempDir dir;
    std::unique_ptr<brickstore::BrickStore> store;
    std::unique_ptr<brickstore::BrickCache> cache;
    render::VolumeValueStats stats;
};

inline std::unique_ptr<TestStore> ingestStore(brickstore::VolumeSource& source,
                                              const brickstore::BrickGeometry& geometry) {
    auto t = std::make_unique<TestStore>();
    const std::string path = t->dir.file("volume.bcs");
    brickstore::IngestConfig config;
    config.geometry = geometry;
    brickstore::ingest(source, path, config);
    t->store = brickstore::BrickStore::open(path);
    t->cache = std::make_unique<brickstore::BrickCache>(*t->store,
                                                        brickstore::BrickCacheConfig{1ull << 30});
    t->stats = render::VolumeValueStats::fromStore(t->store->info());
    return t;
}

inline std::unique_ptr<TestStore> ingestSpec(const brickstore::SourceSpec& spec,
                                             const brickstore::BrickGeometry& geometry) {
    auto source = brickstore::openSource(spec);
    return ingestStore(*source, geometry);
}

/// Voxels of u8 (x fastest) of `dims`, written as a raw file and ingested in `geometry`.
inline std::unique_ptr<TestStore> ingestVoxels(const std::vector<std::uint8_t>& voxels,
                                               const std::array<std::uint64_t, 3>& dims,
                                               const brickstore::BrickGeometry& geometry) {
    const TempDir dir;
    const std::string raw =
        dir.file("volume_" + std::to_string(dims[0]) + "x" + std::to_string(dims[1]) + "x" +
                 std::to_string(dims[2]) + "_uint8.raw");
    writeFile(raw, voxels.data(), voxels.size());
    brickstore::SourceSpec spec;
    spec.input = raw;
    return ingestSpec(spec, geometry);
}

/// Orthographic, looking along +z from (x, y, -40) mm with `height` mm of view (y up): every
/// ray enters a volume whose box holds (x, y) at z = 0.
inline render::Camera orthoAlongZ(double x, double y, double height) {
    render::Camera c;
    c.eye = {x, y, -40.0};
    c.target = {x, y, 0.0};
    c.up = {0.0, 1.0, 0.0};
    c.orthographic = true;
    c.orthoHeight = height;
    return c;
}

/// A frame of `renderer` through a host cache of its own of `budgetBytes` (batches when the
/// frame's bricks do not fit).
inline render::Image underBudget(TestStore& t, render::Renderer& renderer,
                                 std::uint64_t budgetBytes, const render::TransferFunction& tf,
                                 const render::Camera& camera, const render::RenderOptions& o,
                                 render::FrameStats& stats) {
    brickstore::BrickCache cache(*t.store, brickstore::BrickCacheConfig{budgetBytes});
    return renderer.render(*t.store, cache, tf, camera, o, stats);
}

/// Runs `f` and returns the std::invalid_argument's message (empty when none was thrown).
template <class F> std::string refusal(const F& f) {
    try {
        f();
    } catch (const std::invalid_argument& e) {
        return e.what();
    }
    return {};
}

/// Real scans by short name, with the spacing MANIFEST.md gives for the raw files.
inline std::optional<brickstore::SourceSpec> realScan(const std::string& name) {
    brickstore::SourceSpec s;
    if (name == "cthead") {
        s.input = dataPath("stanford_cthead_256x256x113_uint16.raw");
        s.spacingMm = std::array<double, 3>{1, 1, 2};
    } else if (name == "CT_AVM") {
        s.input = dataPath("CT_AVM.nii.gz");
    } else if (name == "frog") {
        s.input = dataPath("frog_500x470x136_uint8.raw");
        s.spacingMm = std::array<double, 3>{1, 1, 1.5};
    } else if (name == "pancreas") {
        s.input = dataPath("tcia_pancreas_ct_dicom");
    } else if (name == "Iguana") {
        s.input = dataPath("Iguana.nii.gz");
    } else if (name == "gaffer_smoke") {
        s.input = dataPath("gaffer_smoke.vdb");
        s.gridName = "density";
    } else if (name == "hydrogen") {
        s.input = dataPath("hydrogen_64x64x64_float32.raw");
    } else if (name == "headsq") {
        s.input = dataPath("vtk_headsq_quarter_64x64x93_uint16.raw");
        s.spacingMm = std::array<double, 3>{3.2, 3.2, 1.5};
    } else {
        return std::nullopt;
    }
    if (!std::filesystem::exists(s.input)) return std::nullopt;
    return s;
}

/// A real scan and one of its presets.
struct ScanPreset {
    std::string scan, preset;
};

inline void PrintTo(const ScanPreset& c, std::ostream* os) {
    *os << c.scan << " " << c.preset;
}

/// Every real scan with the presets the skipping invariants run on (GPU and CPU raycasters).
inline std::vector<ScanPreset> invariantScans() {
    return {{"cthead", "ct-skin"}, {"cthead", "ct-bone"},   {"CT_AVM", "vessels"},
            {"frog", "mr"},        {"pancreas", "ct-bone"}, {"pancreas", "ct-skin"},
            {"Iguana", "ct-bone"}, {"Iguana", "ct-skin"},   {"gaffer_smoke", "smoke"},
            {"hydrogen", "smoke"}, {"headsq", "mr"},        {"headsq", "ct-bone"}};
}

/// A real scan ingested in bricks of 32 (apron 2, octree leaves of 8); nullptr when its data
/// is missing.
inline std::unique_ptr<TestStore> ingestRealScan(const std::string& name) {
    auto spec = realScan(name);
    if (!spec) return nullptr;
    return ingestSpec(*spec, {32, 2, 8});
}

/// GPU frame of a test store.
inline render::Image gpuFrame(TestStore& t, render::GpuRaycaster& raycaster,
                              const render::TransferFunction& tf, const render::Camera& camera,
                              const render::RenderOptions& options,
                              render::FrameStats* statsOut = nullptr) {
    render::FrameStats stats;
    render::Image image = raycaster.render(*t.store, *t.cache, tf, camera, options, stats);
    if (statsOut) *statsOut = stats;
    return image;
}

/// CPU raycaster frame of a test store (a raycaster of its own).
inline render::Image cpuFrame(TestStore& t, const render::TransferFunction& tf,
                              const render::Camera& camera, const render::RenderOptions& options,
                              render::FrameStats* statsOut = nullptr) {
    render::CpuRaycaster raycaster;
    render::FrameStats stats;
    render::Image image = raycaster.render(*t.store, *t.cache, tf, camera, options, stats);
    if (statsOut) *statsOut = stats;
    return image;
}

/// CPU reference frame of a test store (level options.level).
inline render::Image referenceFrame(TestStore& t, const render::TransferFunction& tf,
                                    const render::Camera& camera,
                                    const render::RenderOptions& options) {
    render::ReferenceVolume volume(*t.store, std::uint32_t(options.level));
    render::FrameStats stats;
    return render::renderReference(*t.store, volume, tf, camera, options, stats);
}

/// The frame assembled from regions of `r`: whole rows, then runs of a row, then single pixels,
/// as the daemon slices; each part is checked to be its region's size. `perRegion`: each
/// part's stats.
inline render::Image drawnInRegions(render::Renderer& r, TestStore& t,
                                    const render::TransferFunction& tf,
                                    const render::Camera& camera, render::RenderOptions o,
                                    std::vector<render::FrameStats>* perRegion = nullptr) {
    render::Image frame(o.width, o.height);
    const std::vector<render::PixelRect> regions = {
        {0, 0, o.width, 5}, // rows
        {0, 5, 7, 1},
        {7, 5, o.width - 7, 1},            // a row in two runs
        {0, 6, o.width, o.height - 6 - 1}, // rows
        {0, o.height - 1, 1, 1},
        {1, o.height - 1, o.width - 1, 1}, // one pixel, then the rest
    };
    for (const render::PixelRect& rect : regions) {
        o.region = rect;
        render::FrameStats stats;
        const render::Image part = r.render(*t.store, *t.cache, tf, camera, o, stats);
        if (perRegion) perRegion->push_back(stats);
        EXPECT_EQ(part.width, rect.width);
        EXPECT_EQ(part.height, rect.height);
        if (part.width != rect.width || part.height != rect.height) continue;
        for (std::uint32_t y = 0; y < part.height; ++y)
            std::copy_n(part.pixel(0, y), std::size_t(part.width) * 4,
                        frame.pixel(rect.x, rect.y + y));
    }
    return frame;
}

/// A slice of 4 rows of a 64 x 64 frame costs what it covers: it draws fewer bricks than the
/// whole frame and under half its voxels, each of its pixels the whole frame's to the bit.
inline void expectAThinSliceDrawsLess(render::Renderer& r, TestStore& t,
                                      const render::TransferFunction& tf,
                                      const render::Camera& camera) {
    render::RenderOptions o;
    o.width = o.height = 64;
    render::FrameStats whole, thin;
    const render::Image all = r.render(*t.store, *t.cache, tf, camera, o, whole);
    o.region = {0, 30, 64, 4};
    const render::Image part = r.render(*t.store, *t.cache, tf, camera, o, thin);
    EXPECT_LT(thin.bricksVisited, whole.bricksVisited);
    EXPECT_GT(thin.bricksCulled, whole.bricksCulled);
    EXPECT_LT(thin.samples, whole.samples / 2);
    EXPECT_GT(thin.samples, 0u);
    ASSERT_EQ(part.width, 64u);
    ASSERT_EQ(part.height, 4u);
    for (std::uint32_t y = 0; y < 4; ++y)
        for (std::uint32_t x = 0; x < 64; ++x)
            for (int c = 0; c < 4; ++c)
                ASSERT_EQ(part.pixel(x, y)[c], all.pixel(x, 30 + y)[c]) << x << "," << y;
    std::printf("%s: whole %llu bricks, %llu voxels; 4 rows %llu bricks, %llu voxels\n",
                std::string(r.name()).c_str(), (unsigned long long)whole.bricksVisited,
                (unsigned long long)whole.samples, (unsigned long long)thin.bricksVisited,
                (unsigned long long)thin.samples);
}

/// The values of a volume running 0..1000 with a flat histogram: for transfer functions placed
/// by value without a scan.
inline render::VolumeValueStats unitStats() {
    render::VolumeValueStats s;
    s.valueMin = 0.0;
    s.valueMax = 1000.0;
    s.histogram.assign(16, 1);
    return s;
}

/// A grey ramp over the volume's values, transparent black at the lowest and opaque white at
/// the highest: an average projection's radiograph.
inline render::TransferFunction greyRamp(const render::VolumeValueStats& stats) {
    using render::Placement;
    return render::TransferFunction::fromPoints(
        {{Placement::Value, stats.valueMin, {0.0f, 0.0f, 0.0f, 0.0f}},
         {Placement::Value, stats.valueMax, {1.0f, 1.0f, 1.0f, 1.0f}}},
        "grey ramp", stats);
}

/// The sum of an image's alpha: how much it shows.
inline double alphaSum(const render::Image& image) {
    double alpha = 0;
    for (std::size_t i = 3; i < image.rgba.size(); i += 4)
        alpha += image.rgba[i];
    return alpha;
}

/// True when every channel of every pixel is finite.
inline bool allFinite(const render::Image& image) {
    for (float v : image.rgba)
        if (!std::isfinite(v)) return false;
    return true;
}

/// A 16384 x 40 x 40 checkerboard (voxels 0 and 255, 64-voxel bricks) that fills every brick,
/// a TF that shows its 255 voxels, and a camera at the far end, where float keeps about 1/1000
/// voxel of a position: any hole, seam or NaN from lost precision shows.
struct FarChecker {
    std::unique_ptr<TestStore> store;
    render::TransferFunction tf;
    render::Camera camera;
};
inline FarChecker farChecker() {
    auto source = brickstore::makeSynthetic(brickstore::SynthKind::Checker, {16384, 40, 40}, 5);
    auto store = ingestStore(*source, {64, 2, 8});
    const std::string json = R"({"name":"checker","points":[{"value":100,"rgba":[0.9,0.7,0.4,0]},)"
                             R"({"value":255,"rgba":[0.9,0.7,0.4,0.6]}]})";
    auto tf = render::TransferFunction::parse(json, "<checker>", store->stats);
    render::Camera camera;
    camera.eye = {16300, -60, 80};
    camera.target = {16340, 20, 20};
    camera.up = {0, 0, 1};
    camera.fovYDeg = 40;
    return {std::move(store), std::move(tf), camera};
}

inline void printComparison(const std::string& what, const render::ImageComparison& c) {
    std::printf("[metrics] %-48s max abs %.4f (%.1f/255)  RMSE %.5f  PSNR %.2f dB  SSIM %.5f  "
                "low-pass PSNR %.2f dB\n",
                what.c_str(), c.maxAbs, c.maxAbs * 255.0, c.rmse, c.psnrDb, c.ssim,
                c.lowPassPsnrDb);
}

} // namespace bc::test
