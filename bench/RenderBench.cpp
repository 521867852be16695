// bc_bench_render (formerly `brickcast bench`): run time against error. For each
// real dataset and transfer function, each technique set, each camera path and image size: median
// ms/frame, samples per pixel, samples taken / oracle samples, speed-up over plain in the same run,
// PSNR and SSIM against the CPU reference, octree rebuild ms, occlusion-frustum build ms and
// triangles; then a step sweep (run time against error), and the octree rebuild of a 512^3
// volume. A markdown table on stdout, CSV with --csv, a PNG plot (gnuplot) with --plot.
// Timings are whole frames on whatever EGL gives (llvmpipe without a GPU): say which.
#include "bench/BenchDatasets.h"
#include "bench/BenchReport.h"
#include "brickstore/BrickCache.h"
#include "brickstore/BrickStore.h"
#include "brickstore/Ingest.h"
#include "brickstore/Readers.h"
#include "render/BrickPlan.h"
#include "render/CpuRaycaster.h"
#include "render/EglContext.h"
#include "render/GpuRaycaster.h"
#include "render/ImageMetrics.h"
#include "render/Occupancy.h"
#include "render/ReferenceRenderer.h"
#include "render/TransferFunction.h"
#include "tools/Parse.h"
#include "tools/RunCommandLine.h"
#include "tools/TransferFunctionFile.h"

#include <CLI/CLI.hpp>

#include <algorithm>
#include <chrono>
#include <cmath>
#include <cstdio>
#include <filesystem>
#include <random>
#include <sstream>
#include <thread>
#include <unistd.h>

namespace bc::bench {
namespace {

struct BenchOptions {
    std::string data = BC_SHARED_DATA_DIR, datasets, tf, sizes = "256", paths = "orbit,jumps",
                steps = "0.25,0.5,1,2,4", csv, plot, renderer = "gpu";
    int frames = 8;
    std::uint32_t brick = 32;
    std::uint64_t gpuBudgetMb = 512, generatedBudgetMb = 64;
    bool noRebuild512 = false, noGenerated = false;
};

std::vector<Dataset> datasetsOf(const BenchOptions& o) {
    std::vector<Dataset> out = realDatasets(o.data, o.datasets, o.tf, "bench");
    if (!o.noGenerated) { // u8 vessels of four times the GPU budget: out of core
        const auto edge = std::uint64_t(std::cbrt(double((o.generatedBudgetMb << 20) * 4)));
        brickstore::SourceSpec s;
        s.input = "synth:vessels";
        s.dims = std::array<std::uint64_t, 3>{edge, edge, edge};
        out.push_back({"generated vessels " + std::to_string(edge) + "^3 (4x the budget)",
                       o.tf.empty() ? "vessels" : o.tf, s, o.generatedBudgetMb, ""});
    }
    if (out.empty()) throw std::invalid_argument("--datasets: none of the named scans is here");
    return out;
}

/// Each technique on its own over plain (+octree includes the bricks it lives in; frustums
/// need the bricks to find first hits), octrees with early termination (the paper's
/// pairing), then all together.
struct TechniqueSet {
    const char* name;
    render::SkipMode skip;
    bool ert, frustums;
    std::uint32_t cells = 0; ///< RenderOptions::cellVoxels (CPU raycaster: distance maps)
};
constexpr std::uint32_t kCells = render::RenderOptions{}.cellVoxels; // the default
constexpr TechniqueSet kSets[] = {
    {"plain", render::SkipMode::None, false, false},
    {"+ERT", render::SkipMode::None, true, false},
    {"+bricks", render::SkipMode::Bricks, false, false},
    {"+octree", render::SkipMode::All, false, false},
    {"+octree +ERT", render::SkipMode::All, true, false},
    {"+octree +cells 2 +ERT", render::SkipMode::All, true, false, 2},
    {"+octree +cells 1 +ERT", render::SkipMode::All, true, false, 1},
    {"+occlusion frustums", render::SkipMode::Bricks, false, true},
    {"all", render::SkipMode::All, true, true, kCells},
};

double median(std::vector<double> v) {
    if (v.empty()) return 0.0;
    std::sort(v.begin(), v.end());
    return v[v.size() / 2];
}

struct Scene {
    std::unique_ptr<brickstore::BrickStore> store;
    std::unique_ptr<brickstore::BrickCache> cache;
    std::unique_ptr<render::ReferenceVolume> volume;
    std::optional<render::TransferFunction> tf;
};

/// One technique set over one path: frame 1 is compared with `reference`.
BenchRow measure(Scene& s, const TechniqueSet& t, const std::string& renderer,
                 const std::vector<render::Camera>& cams, render::RenderOptions o,
                 std::uint64_t budgetBytes, const render::Image* reference,
                 const render::FrameStats& referenceStats) {
    const bool cpu = renderer == "cpu";
    render::GpuRaycaster* gpu = nullptr;
    std::optional<render::GpuRaycaster> gpuRaycaster;
    std::optional<render::CpuRaycaster> cpuRaycaster;
    if (cpu)
        cpuRaycaster.emplace();
    else
        gpu = &gpuRaycaster.emplace(render::GpuRaycasterConfig{budgetBytes});
    o.skip = t.skip;
    o.earlyTermination = t.ert;
    o.occlusionFrustums = t.frustums;
    o.cellVoxels = t.cells;
    BenchRow row;
    row.technique = cpu ? std::string(t.name) + " (CPU)" : std::string(t.name);
    std::vector<double> ms, ofMs;
    double spp = 0, triangles = 0;
    for (std::size_t f = 0; f < cams.size(); ++f) {
        render::FrameStats st;
        const render::Image image =
            cpu ? cpuRaycaster->render(*s.store, *s.cache, *s.tf, cams[f], o, st)
                : gpu->render(*s.store, *s.cache, *s.tf, cams[f], o, st);
        if (f == 0) {
            row.octreeRebuildMs = st.octreeRebuildMs;
            row.cellBuildMs = st.cellBuildMs;
            continue;
        }
        if (f == 1 && reference) {
            const auto c = render::compareImages(image, *reference);
            row.psnr = c.psnrDb;
            row.ssim = c.ssim;
            row.overOracle = double(st.samples) /
                             double(std::max<std::uint64_t>(referenceStats.oracleSamples, 1));
        }
        ms.push_back(st.totalMs);
        spp += double(st.samples) / (double(o.width) * o.height);
        if (st.occlusionUsed) {
            ++row.frustumFrames;
            ofMs.push_back(st.occlusionBuildMs);
            triangles += double(st.occlusionTriangles);
        }
    }
    row.ms = median(ms);
    row.spp = spp / double(ms.size());
    row.frustumBuildMs = median(ofMs);
    row.frustumTriangles = row.frustumFrames ? triangles / row.frustumFrames : 0.0;
    return row;
}

std::vector<double> numbersOf(const std::string& text, const char* what) {
    auto out = tools::parseNumbers(text, what, 1, 64);
    for (double v : out)
        if (!(v > 0)) throw std::invalid_argument(std::string(what) + ": values must be positive");
    return out;
}

void benchScene(Scene& s, const Dataset& d, const BenchOptions& o, BenchReport& report) {
    const render::Box box = render::LevelGeometry::of(*s.store, 0).box;
    for (double size : numbersOf(o.sizes, "--sizes")) {
        render::RenderOptions base;
        base.width = base.height = std::uint32_t(size);
        for (const auto& path : tools::splitList(o.paths)) {
            const auto cams = cameraPath(path, box, o.frames);
            render::FrameStats rs;
            std::optional<render::Image> reference;
            if (s.volume)
                reference = render::renderReference(*s.store, *s.volume, *s.tf, cams[1], base, rs);
            for (const auto& t : kSets)
                for (const std::string renderer : {"gpu", "cpu"}) {
                    if (o.renderer != "both" && o.renderer != renderer) continue;
                    if (renderer == "cpu" && t.frustums) continue; // a GPU technique
                    BenchRow row = measure(s, t, renderer, cams, base,
                                           (d.budgetMb ? d.budgetMb : o.gpuBudgetMb) << 20,
                                           reference ? &*reference : nullptr, rs);
                    row.dataset = d.name;
                    row.tf = d.preset;
                    row.path = path;
                    row.size = base.width;
                    row.step = base.stepVoxels;
                    report.add(row);
                }
            std::fprintf(stderr, "bench: %s / %s %s %u^2 done\n", d.name.c_str(), d.preset.c_str(),
                         path.c_str(), base.width);
        }
    }
}

/// Run time against error: every step with all techniques, against a reference at the
/// finest step (first size, orbit).
void stepSweep(Scene& s, const Dataset& d, const BenchOptions& o, BenchReport& report) {
    if (!s.volume) return; // no reference to measure the error with
    auto steps = numbersOf(o.steps, "--steps");
    std::sort(steps.begin(), steps.end());
    render::RenderOptions base;
    base.width = base.height = std::uint32_t(numbersOf(o.sizes, "--sizes").front());
    base.stepVoxels = steps.front();
    const auto cams = cameraPath("orbit", render::LevelGeometry::of(*s.store, 0).box, o.frames);
    render::FrameStats rs;
    const render::Image reference =
        render::renderReference(*s.store, *s.volume, *s.tf, cams[1], base, rs);
    for (double step : steps) {
        render::RenderOptions so = base;
        so.stepVoxels = step;
        BenchRow row = measure(s, kSets[std::size(kSets) - 1], o.renderer == "cpu" ? "cpu" : "gpu",
                               cams, so, o.gpuBudgetMb << 20, &reference, rs);
        row.kind = "sweep";
        row.dataset = d.name;
        row.tf = d.preset;
        row.path = "orbit";
        row.size = base.width;
        row.step = step;
        report.add(row);
    }
}

/// The paper's rebuild figure: every octree of a dense 512^3 volume rebuilt (forced by a
/// config change), and what the incremental path does on a TF switch.
void rebuild512(const std::string& tmp) {
    auto source = brickstore::makeSynthetic(brickstore::SynthKind::Phantom, {512, 512, 512}, 1);
    const std::string path = tmp + "/phantom512.bcs";
    brickstore::ingest(*source, path, {});
    auto store = brickstore::BrickStore::open(path);
    const auto stats = render::VolumeValueStats::fromStore(store->info());
    const auto a = tools::loadTransferFunction("ct-skin", stats).table(1.0);
    const auto b = tools::loadTransferFunction("ct-bone", stats).table(1.0);
    render::OccupancyTrees trees(*store, 0);
    std::vector<double> full, incremental;
    std::uint64_t stored = 0, rebuilt = 0;
    for (int i = 0; i < 8; ++i) { // full: a new ratio threshold every time
        const auto r = trees.update(i % 2 ? a : b, {1.0 - 1e-6 * (i + 1), 32});
        full.push_back(r.ms);
        stored = r.bricksStored;
    }
    for (int i = 0; i < 8; ++i) {
        const auto r = trees.update(i % 2 ? a : b, {1.0 - 1e-6 * 9, 32});
        if (i > 0) incremental.push_back(r.ms), rebuilt += r.bricksRebuilt;
    }
    std::printf("\nOctree rebuild from leaf ranges, 512^3 u8 phantom (64^3 bricks, 8^3 leaves, "
                "%llu stored bricks, %u threads): all octrees %.2f ms (median of 8); TF switch "
                "ct-skin <-> ct-bone, incremental, %.2f ms (%.0f bricks rebuilt). Ruijters & "
                "Vilanova 2006: 3.5 ms for 512^3.\n",
                (unsigned long long)stored, std::thread::hardware_concurrency(), median(full),
                median(incremental),
                double(rebuilt) / double(std::max<std::size_t>(incremental.size(), 1)));
}

void runBench(const BenchOptions& o) {
    if (o.frames < 1 || o.frames > 1000) throw std::invalid_argument("--frames: 1..1000");
    if (o.renderer != "gpu" && o.renderer != "cpu" && o.renderer != "both")
        throw std::invalid_argument("--renderer: '" + o.renderer + "' is not gpu, cpu or both");
    for (const auto& path : tools::splitList(o.paths))
        if (path != "orbit" && path != "jumps")
            throw std::invalid_argument("--paths: '" + path + "' is not orbit or jumps");
    for (double size : numbersOf(o.sizes, "--sizes"))
        if (size != std::floor(size) || size > 4096)
            throw std::invalid_argument("--sizes: image edges are whole numbers up to 4096");
    numbersOf(o.steps, "--steps");
    datasetsOf(o); // names the missing or unknown scans before any work
    render::EglContext context;
    std::printf("brickcast bench on %s (%s, EGL %s); step 1 voxel unless swept, shaded, "
                "%d timed frames per path (orbit 2 deg/frame; jumps seeded), bricks %u^3 + 2\n",
                context.renderer().c_str(), context.version().c_str(), context.platform().c_str(),
                o.frames, o.brick);
    const std::string tmp =
        (std::filesystem::temp_directory_path() / ("bc-bench-" + std::to_string(getpid())))
            .string();
    std::filesystem::create_directories(tmp);
    BenchReport report;
    for (const auto& d : datasetsOf(o)) {
        Scene s;
        auto source = brickstore::openSource(d.spec);
        brickstore::IngestConfig config;
        config.geometry = {o.brick, 2, 8};
        if (d.budgetMb) config.geometry = {64, 2, 8};
        brickstore::ingest(*source, tmp + "/scan.bcs", config);
        s.store = brickstore::BrickStore::open(tmp + "/scan.bcs");
        s.cache = std::make_unique<brickstore::BrickCache>(
            *s.store, brickstore::BrickCacheConfig{4ull << 30});
        if (!d.budgetMb) s.volume = std::make_unique<render::ReferenceVolume>(*s.store, 0);
        s.tf = tools::loadTransferFunction(d.preset,
                                           render::VolumeValueStats::fromStore(s.store->info()));
        benchScene(s, d, o, report);
        stepSweep(s, d, o, report);
    }
    report.printMarkdown();
    if (!o.csv.empty()) report.writeCsv(o.csv);
    if (!o.plot.empty()) report.writePlot(o.plot, tmp);
    if (!o.noRebuild512) rebuild512(tmp);
    std::filesystem::remove_all(tmp);
}

} // namespace
} // namespace bc::bench

int main(int argc, char** argv) {
    bc::bench::BenchOptions o;
    CLI::App app{"Run time against error of every technique set on the real scans",
                 "bc_bench_render"};
    app.add_option("--data", o.data, "Folder of the real scans")->capture_default_str();
    app.add_option("--datasets", o.datasets, "Comma-separated scan names (default: all present)");
    app.add_option("--tf", o.tf, "One preset or file for every scan (default: each scan's own)");
    app.add_option("--sizes", o.sizes, "Image edges, comma-separated")->capture_default_str();
    app.add_option("--paths", o.paths, "Camera paths: orbit, jumps")->capture_default_str();
    app.add_option("--frames", o.frames, "Timed frames per path")->capture_default_str();
    app.add_option("--steps", o.steps, "Step sweep, voxels")->capture_default_str();
    app.add_option("--brick", o.brick, "Brick edge of the stores")->capture_default_str();
    app.add_option("--gpu-budget-mb", o.gpuBudgetMb, "GPU brick pool budget")
        ->capture_default_str();
    app.add_option("--renderer", o.renderer,
                   "gpu (the EGL raycaster), cpu (the CPU raycaster) or both, alternating per set")
        ->capture_default_str();
    app.add_option("--csv", o.csv, "Write every row as CSV");
    app.add_option("--plot", o.plot, "Draw run time against error as PNG (needs gnuplot)");
    app.add_flag("--no-rebuild-512", o.noRebuild512, "Skip the 512^3 octree rebuild timing");
    app.add_flag("--no-generated", o.noGenerated, "Skip the generated out-of-core volume");
    app.add_option("--generated-budget-mb", o.generatedBudgetMb,
                   "GPU budget of the generated volume (which is four times larger)")
        ->capture_default_str();
    app.callback([&o] { bc::bench::runBench(o); });
    return bc::tools::runCommandLine(app, argc, argv, "bc_bench_render");
}
