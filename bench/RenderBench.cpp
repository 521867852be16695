// Render benchmark (issue 3): per real dataset, ms/frame and samples per pixel over an orbit
// for plain raycasting, + brick skipping, + early ray termination, with speed-ups taken in
// one run, the error of each against the CPU reference, and the same for a generated volume
// four times larger than the GPU budget. Prints markdown tables; say which machine in
// anything you quote (the GPU is whatever EGL gives: llvmpipe on the development VMs).
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

#include <CLI/CLI.hpp>
#include <algorithm>
#include <cstdio>
#include <filesystem>
#include <unistd.h>

namespace {

using namespace bc;

struct Dataset {
    std::string name, preset;
    brickstore::SourceSpec spec;
};

std::vector<Dataset> datasets(const std::string& dir) {
    auto at = [&](const std::string& f) { return (std::filesystem::path(dir) / f).string(); };
    std::vector<Dataset> d;
    auto add = [&](std::string name, std::string preset, std::string input,
                   std::optional<std::array<double, 3>> spacing = std::nullopt) {
        brickstore::SourceSpec s;
        s.input = std::move(input);
        s.spacingMm = spacing;
        if (s.input.ends_with(".vdb")) s.gridName = "density";
        if (std::filesystem::exists(s.input)) d.push_back({std::move(name), std::move(preset), s});
    };
    add("stanford_cthead", "ct-skin", at("stanford_cthead_256x256x113_uint16.raw"),
        std::array<double, 3>{1, 1, 2});
    add("stanford_cthead", "ct-bone", at("stanford_cthead_256x256x113_uint16.raw"),
        std::array<double, 3>{1, 1, 2});
    add("CT_AVM", "vessels", at("CT_AVM.nii.gz"));
    add("frog", "mr", at("frog_500x470x136_uint8.raw"), std::array<double, 3>{1, 1, 1.5});
    add("pancreas (DICOM)", "ct-bone", at("tcia_pancreas_ct_dicom"));
    add("Iguana", "ct-bone", at("Iguana.nii.gz"));
    add("gaffer_smoke", "smoke", at("gaffer_smoke.vdb"));
    add("hydrogen", "smoke", at("hydrogen_64x64x64_float32.raw"));
    return d;
}

struct Technique {
    const char* name;
    render::SkipMode skip;
    bool ert;
    bool hardwareFilter;
    bool frustums = false;
};
constexpr Technique kTechniques[] = {
    {"plain", render::SkipMode::None, false, false},
    {"+bricks", render::SkipMode::Bricks, false, false},
    {"+bricks +ERT", render::SkipMode::Bricks, true, false},
    {"+bricks +octree +ERT", render::SkipMode::All, true, false},
    {"+bricks +octree +ERT +occlusion frustums", render::SkipMode::All, true, false, true},
    {"+bricks +octree +ERT, hardware filtering", render::SkipMode::All, true, true},
};
constexpr int kTechniqueCount = int(std::size(kTechniques));

struct Row {
    double medianMs = 0, samplesPerPixel = 0, psnr = 0, ssim = 0;
    std::uint64_t uploadedFirst = 0;
    int frustumFrames = 0;
};

constexpr double kDegreesPerFrame = 2.0; // a slowly rotating object, as in the papers

double median(std::vector<double> v) {
    std::sort(v.begin(), v.end());
    return v.empty() ? 0 : v[v.size() / 2];
}

Row measure(brickstore::BrickStore& store, const render::TransferFunction& tf, const Technique& t,
            const render::RenderOptions& base, int frames, std::uint64_t budgetBytes,
            const render::Image* reference) {
    brickstore::BrickCache cache(store, {4ull << 30});
    render::Raycaster raycaster({budgetBytes});
    const render::Box box = render::LevelGeometry::of(store, 0).box;
    render::RenderOptions o = base;
    o.skip = t.skip;
    o.earlyTermination = t.ert;
    o.hardwareFilter = t.hardwareFilter;
    o.occlusionFrustums = t.frustums;
    Row row;
    std::vector<double> ms;
    double samples = 0;
    for (int f = 0; f <= frames; ++f) { // frame 0 warms the pool and is not timed
        render::FrameStats s;
        const auto camera = render::Camera::orbit(box, 30.0 + kDegreesPerFrame * f, 20.0);
        const render::Image image = raycaster.render(store, cache, tf, camera, o, s);
        if (f == 0) {
            row.uploadedFirst = s.bytesUploaded;
            if (reference) {
                const auto c = render::compareImages(image, *reference);
                row.psnr = c.psnrDb;
                row.ssim = c.ssim;
            }
            continue;
        }
        ms.push_back(s.totalMs);
        row.frustumFrames += s.occlusionUsed;
        samples += double(s.samples) / (double(o.width) * o.height);
    }
    row.medianMs = median(ms);
    row.samplesPerPixel = samples / std::max(frames, 1);
    return row;
}

std::unique_ptr<brickstore::BrickStore> ingestTemp(brickstore::VolumeSource& source,
                                                   const std::string& path, std::uint32_t brick) {
    brickstore::IngestConfig config;
    config.geometry = {brick, 2, 8};
    brickstore::ingest(source, path, config);
    return brickstore::BrickStore::open(path);
}

void printTable(const std::string& title,
                const std::vector<std::pair<std::string, std::array<Row, kTechniqueCount>>>& rows) {
    std::printf("\n%s\n\n", title.c_str());
    std::printf(
        "| dataset / TF | technique | ms/frame | samples/pixel | speed-up | PSNR dB | SSIM |\n");
    std::printf("|---|---|---:|---:|---:|---:|---:|\n");
    // (frames drawn with occlusion frustums are counted on stderr)
    for (const auto& [name, r] : rows)
        for (int i = 0; i < kTechniqueCount; ++i) {
            char error[64] = "n/a | n/a"; // no CPU reference for the generated volume
            if (r[i].ssim > 0.0) std::snprintf(error, sizeof error, "%.1f | %.4f", r[i].psnr, r[i].ssim);
            if (kTechniques[i].frustums)
                std::fprintf(stderr, "%s: occlusion frustums used in %d frames\n", name.c_str(),
                             r[i].frustumFrames);
            std::printf("| %s | %s | %.1f | %.1f | %.2fx | %s |\n", i == 0 ? name.c_str() : "",
                        kTechniques[i].name, r[i].medianMs, r[i].samplesPerPixel,
                        r[0].medianMs / r[i].medianMs, error);
        }
}

} // namespace

int main(int argc, char** argv) {
    CLI::App app{"brickcast render benchmark"};
    std::string data = BC_SHARED_DATA_DIR;
    int size = 256, frames = 8, brick = 32;
    std::uint64_t budgetMb = 512, bigBudgetMb = 64;
    bool skipBig = false;
    app.add_option("--data", data, "Folder of the real scans")->capture_default_str();
    app.add_option("--size", size, "Image edge")->capture_default_str();
    app.add_option("--frames", frames, "Timed orbit frames per technique")->capture_default_str();
    app.add_option("--brick", brick, "Brick edge of the stores")->capture_default_str();
    app.add_option("--gpu-budget-mb", budgetMb, "GPU budget for the real scans")
        ->capture_default_str();
    app.add_option("--big-budget-mb", bigBudgetMb, "GPU budget of the 4x-budget generated volume")
        ->capture_default_str();
    app.add_flag("--no-big", skipBig, "Skip the generated volume");
    CLI11_PARSE(app, argc, argv);

    render::EglContext context;
    std::printf("renderer: %s (%s, EGL %s); %dx%d, step 1 voxel, shaded, %d orbit frames at %.0f deg "
                "per frame (median), bricks %d^3 + 2\n",
                context.renderer().c_str(), context.version().c_str(), context.platform().c_str(),
                size, size, frames, kDegreesPerFrame, brick);
    const std::string tmp =
        (std::filesystem::temp_directory_path() / ("bc-render-bench-" + std::to_string(getpid())))
            .string();
    std::filesystem::create_directories(tmp);
    render::RenderOptions base;
    base.width = base.height = std::uint32_t(size);
    std::vector<std::pair<std::string, std::array<Row, kTechniqueCount>>> rows;
    for (const auto& d : datasets(data)) {
        auto source = brickstore::openSource(d.spec);
        auto store = ingestTemp(*source, tmp + "/scan.bcs", std::uint32_t(brick));
        const auto tf = render::TransferFunction::load(
            d.preset, render::VolumeValueStats::fromStore(store->info()));
        const render::ReferenceVolume volume(*store, 0);
        render::FrameStats rs;
        render::RenderOptions ro = base;
        const auto camera0 =
            render::Camera::orbit(render::LevelGeometry::of(*store, 0).box, 30.0, 20.0);
        const render::Image reference =
            render::renderReference(*store, volume, tf, camera0, ro, rs);
        std::array<Row, kTechniqueCount> r;
        for (int i = 0; i < kTechniqueCount; ++i)
            r[i] = measure(*store, tf, kTechniques[i], base, frames, budgetMb << 20, &reference);
        rows.push_back({d.name + " / " + d.preset, r});
        std::fprintf(stderr, "done %s / %s (reference %.0f ms)\n", d.name.c_str(), d.preset.c_str(),
                     rs.totalMs);
    }
    printTable("Real scans (GPU budget " + std::to_string(budgetMb) +
                   " MiB; PSNR/SSIM of the first frame against "
                   "the CPU reference)",
               rows);

    if (!skipBig) {
        // Four times the GPU budget: u16 vessels of 4 * budget bytes.
        const std::uint64_t voxels = (bigBudgetMb << 20) * 4 / 2;
        const auto edge = std::uint64_t(std::cbrt(double(voxels)));
        auto source = brickstore::makeSynthetic(brickstore::SynthKind::Vessels,
                                                {edge, edge, voxels / (edge * edge)}, 1);
        auto store = ingestTemp(*source, tmp + "/big.bcs", 64);
        const auto tf = render::TransferFunction::load(
            "vessels", render::VolumeValueStats::fromStore(store->info()));
        std::array<Row, kTechniqueCount> r;
        for (int i = 0; i < kTechniqueCount; ++i)
            r[i] = measure(*store, tf, kTechniques[i], base, frames, bigBudgetMb << 20, nullptr);
        const auto& dims = store->info().volume.dims;
        printTable("Generated vessels " + std::to_string(dims[0]) + "x" + std::to_string(dims[1]) +
                       "x" + std::to_string(dims[2]) + " " +
                       std::string(brickstore::voxelTypeName(store->info().volume.type)) + " (" +
                       std::to_string((voxels * 2) >> 20) + " MiB) under a " +
                       std::to_string(bigBudgetMb) + " MiB GPU budget",
                   {{"vessels / vessels", r}});
    }
    std::filesystem::remove_all(tmp);
    return 0;
}
