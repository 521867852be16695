#pragma once
// Shared by the render tests: one EGL context for the whole test binary (GL belongs to the
// thread that made it; GoogleTest runs every test on the main thread), stores ingested from
// the real scans into scratch folders, and GPU-vs-reference helpers.
#include "../TestSupport.h"
#include "brickstore/BrickCache.h"
#include "brickstore/BrickStore.h"
#include "brickstore/Ingest.h"
#include "brickstore/Readers.h"
#include "render/BrickPlan.h"
#include "render/EglContext.h"
#include "render/ImageMetrics.h"
#include "render/Raycaster.h"
#include "render/ReferenceRenderer.h"
#include "render/TransferFunction.h"

#include <cstdio>
#include <cstdlib>
#include <memory>
#include <optional>

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

/// GPU frame of a test store.
inline render::Image gpuFrame(TestStore& t, render::Raycaster& raycaster,
                              const render::TransferFunction& tf, const render::Camera& camera,
                              const render::RenderOptions& options,
                              render::FrameStats* statsOut = nullptr) {
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

/// True when every channel of every pixel is finite.
inline bool allFinite(const render::Image& image) {
    for (float v : image.rgba)
        if (!std::isfinite(v)) return false;
    return true;
}

inline void printComparison(const std::string& what, const render::ImageComparison& c) {
    std::printf("[metrics] %-48s max abs %.4f (%.1f/255)  RMSE %.5f  PSNR %.2f dB  SSIM %.5f\n",
                what.c_str(), c.maxAbs, c.maxAbs * 255.0, c.rmse, c.psnrDb, c.ssim);
}

} // namespace bc::test
