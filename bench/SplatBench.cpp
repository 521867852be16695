// bc_bench_splat (formerly `brickcast bench-splat`): the hybrid splatter's timings in the layout of
// Yuan et al. 2003, Figure 9, beside the raycaster at equal error. For each dataset three
// views on one orbit: "all splats" (every visible voxel projects to at least the point threshold;
// the framing view when that holds, else as close as it must be), "mixed" (the volume centre at the
// threshold) and "all points" (the nearest voxel below it). Per view: the splatter's median ms, the
// share of drawn voxels that were splats, its error against the float64 reference (k x k
// supersampled: the pixel's area average, which is what an antialiased image should converge to),
// the same with occlusion culling off (and the largest pixel difference, which must be 0: culling
// changes no pixel), the GPU splatter when EGL gives a context (its ms and largest difference from
// the CPU splatter), and the CPU raycaster in every (step, supersampling) configuration of the
// sweep: its default (1 voxel, no supersampling), and the fastest configuration whose PSNR is at
// least the splatter's, the raycaster "at equal error". Ratios come from one run: the machines are
// shared and noisy.
#include "bench/BenchDatasets.h"
#include "brickstore/BrickCache.h"
#include "brickstore/BrickStore.h"
#include "brickstore/Ingest.h"
#include "brickstore/Readers.h"
#include "render/BrickPlan.h"
#include "render/CpuRaycaster.h"
#include "render/EglContext.h"
#include "render/GpuSplatter.h"
#include "render/HybridSplatter.h"
#include "render/ImageMetrics.h"
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
#include <fstream>
#include <functional>
#include <optional>
#include <thread>
#include <unistd.h>

namespace bc::bench {
namespace {

using Clock = std::chrono::steady_clock;
double msSince(Clock::time_point t) {
    return std::chrono::duration<double, std::milli>(Clock::now() - t).count();
}
constexpr double kPi = 3.14159265358979323846;

struct SplatBenchOptions {
    std::string data = BC_SHARED_DATA_DIR, datasets, tf, csv, steps = "0.5,1,2,4",
                supersampling = "1,2";
    std::uint32_t size = 400; ///< the paper's images are 400 x 400
    std::uint32_t brick = 32;
    std::uint32_t referenceSupersampling = 2;
    double referenceStep = 0.5;
    int frames = 3;
    bool noChecker = false, noGpu = false;
};

/// The paper's fifth volume: a 100^3 checker box, every voxel non-transparent.
Dataset checkerBox() {
    brickstore::SourceSpec s;
    s.input = "synth:checker";
    s.dims = std::array<std::uint64_t, 3>{100, 100, 100};
    Dataset d{"checker box 100^3", "checker", s, 0, ""};
    d.tfJson = R"({"name":"checker","points":[{"value":0,"rgba":[1,0.2,0.2,0.05]},)"
               R"({"value":255,"rgba":[0.9,0.9,1,0.5]}]})";
    return d;
}

/// Box filter by `factor` along both axes.
render::Image downsample(const render::Image& image, std::uint32_t factor) {
    if (factor == 1) return image;
    render::Image out(image.width / factor, image.height / factor);
    const float w = 1.0f / float(factor * factor);
    for (std::uint32_t y = 0; y < out.height; ++y)
        for (std::uint32_t x = 0; x < out.width; ++x) {
            float* o = out.pixel(x, y);
            for (std::uint32_t j = 0; j < factor; ++j)
                for (std::uint32_t i = 0; i < factor; ++i) {
                    const float* p = image.pixel(x * factor + i, y * factor + j);
                    for (int c = 0; c < 4; ++c)
                        o[c] += p[c] * w;
                }
        }
    return out;
}

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
    std::uint64_t visibleVoxels = 0; ///< voxels the TF gives non-zero opacity
};

struct View {
    const char* name;
    double distanceFactor; ///< Camera::orbit's
};

/// Distances from the splatter's own rule: a voxel at eye depth z is a point when its
/// sphere (radiusVoxels * max spacing) projects below pointThresholdPixels, i.e. when
/// z > zSplit = radius * focal / threshold. The box's bounding sphere (radius R) spans
/// depths D +- R about its centre at distance D.
std::array<View, 3> viewsOf(const render::LevelGeometry& g, std::uint32_t size,
                            const render::HybridSplatterConfig& config) {
    const double fov = 30.0 * kPi / 180.0;
    const double focal = 0.5 * size / std::tan(0.5 * fov);
    const double maxSpacing = std::max({g.spacing.x, g.spacing.y, g.spacing.z});
    const double zSplit = config.radiusVoxels * maxSpacing * focal / config.pointThresholdPixels;
    const double R = g.box.radius(), framing = R / std::sin(0.5 * fov);
    const double close = std::max(std::min(framing, 0.97 * (zSplit - R)), 1.05 * R);
    return {View{"all splats", close / framing}, View{"mixed", zSplit / framing},
            View{"all points", 1.03 * (zSplit + R) / framing}};
}

std::vector<render::Camera> camerasOf(const render::Box& box, double distanceFactor, int frames) {
    std::vector<render::Camera> cams; // frame 0 warms caches and octrees: not timed
    for (int f = 0; f <= frames; ++f)
        cams.push_back(render::Camera::orbit(box, 30.0 + 2.0 * f, 20.0, distanceFactor));
    return cams;
}

/// One renderer over a view: median ms of frames 1.., frame 1 kept for the comparison.
struct Timed {
    double ms = 0;
    render::Image first;
    render::HybridSplatStats splat; ///< of frame 1 (splatter only)
};

using RenderFn = std::function<render::Image(const render::Camera&, render::HybridSplatStats&)>;

Timed timeFrames(const std::vector<render::Camera>& cams, const RenderFn& draw) {
    Timed t;
    std::vector<double> ms;
    for (std::size_t f = 0; f < cams.size(); ++f) {
        render::HybridSplatStats n;
        const auto start = Clock::now();
        render::Image image = draw(cams[f], n);
        if (f == 0) continue;
        ms.push_back(msSince(start));
        if (f == 1) t.first = std::move(image), t.splat = n;
    }
    t.ms = median(ms);
    return t;
}

struct RaycastConfig {
    double step;
    std::uint32_t supersampling;
    double ms = 0, psnr = 0, ssim = 0;
};

struct ViewResult {
    std::string dataset, preset;
    std::string view;
    double distanceFactor = 0;
    double splatMs = 0, noCullMs = 0, psnr = 0, ssim = 0, cullMaxAbs = 0;
    double gpuMs = std::nan(""), gpuMaxAbs = std::nan(""); ///< NaN: no GPU splatter run
    render::HybridSplatStats n;
    std::vector<RaycastConfig> raycasts;
    double splatFraction() const {
        const double drawn = double(n.points + n.splats);
        return drawn > 0 ? double(n.splats) / drawn : 0.0;
    }
    /// The default raycast (step 1, no supersampling) when swept.
    const RaycastConfig* defaultRaycast() const {
        for (const auto& r : raycasts)
            if (r.step == 1.0 && r.supersampling == 1) return &r;
        return nullptr;
    }
    /// The fastest raycast at least as accurate as the splatter; null when none is.
    const RaycastConfig* equalError() const {
        const RaycastConfig* best = nullptr;
        for (const auto& r : raycasts)
            if (r.psnr >= psnr && (!best || r.ms < best->ms)) best = &r;
        return best;
    }
};

std::uint64_t countVisible(const render::ReferenceVolume& volume,
                           const render::TransferFunctionTable& table) {
    std::uint64_t n = 0;
    const auto& d = volume.dims();
    for (std::uint64_t z = 0; z < d[2]; ++z)
        for (std::uint64_t y = 0; y < d[1]; ++y)
            for (std::uint64_t x = 0; x < d[0]; ++x)
                n += table.lookup(volume.sample(x + 0.5, y + 0.5, z + 0.5))[3] > 0.0f;
    return n;
}

std::vector<ViewResult> benchDataset(Scene& s, const Dataset& d, const SplatBenchOptions& o,
                                     const std::vector<RaycastConfig>& sweep, bool gpu) {
    const render::LevelGeometry g = render::LevelGeometry::of(*s.store, 0);
    render::HybridSplatterConfig culling, noCulling;
    noCulling.occlusionCulling = false;
    std::vector<ViewResult> out;
    for (const View& v : viewsOf(g, o.size, culling)) {
        ViewResult r;
        r.dataset = d.name;
        r.preset = d.preset;
        r.view = v.name;
        r.distanceFactor = v.distanceFactor;
        const auto cams = camerasOf(g.box, v.distanceFactor, o.frames);
        render::RenderOptions ro;
        ro.width = ro.height = o.size;
        render::RenderOptions refOptions = ro;
        refOptions.width = refOptions.height = o.size * o.referenceSupersampling;
        refOptions.stepVoxels = o.referenceStep;
        render::FrameStats rs;
        const render::Image reference =
            downsample(render::renderReference(*s.store, *s.volume, *s.tf, cams[1], refOptions, rs),
                       o.referenceSupersampling);

        auto splatWith = [&](const render::HybridSplatterConfig& config) {
            render::HybridSplatter splatter(config);
            return timeFrames(cams, [&](const render::Camera& c, render::HybridSplatStats& n) {
                render::FrameStats st;
                render::Image image = splatter.render(*s.store, *s.cache, *s.tf, c, ro, st);
                n = splatter.lastFrame();
                return image;
            });
        };
        const Timed splat = splatWith(culling), plain = splatWith(noCulling);
        const auto cmp = render::compareImages(splat.first, reference);
        r.splatMs = splat.ms;
        r.noCullMs = plain.ms;
        r.n = splat.splat;
        r.psnr = cmp.psnrDb;
        r.ssim = cmp.ssim;
        r.cullMaxAbs = render::compareImages(splat.first, plain.first).maxAbs;
        if (gpu) {
            render::GpuSplatter splatter(culling);
            const Timed g =
                timeFrames(cams, [&](const render::Camera& c, render::HybridSplatStats&) {
                    render::FrameStats st;
                    return splatter.render(*s.store, *s.cache, *s.tf, c, ro, st);
                });
            r.gpuMs = g.ms;
            r.gpuMaxAbs = render::compareImages(g.first, plain.first).maxAbs;
        }

        render::CpuRaycaster raycaster;
        for (RaycastConfig rc : sweep) {
            render::RenderOptions co = ro;
            co.width = co.height = o.size * rc.supersampling;
            co.stepVoxels = rc.step;
            const Timed t =
                timeFrames(cams, [&](const render::Camera& c, render::HybridSplatStats&) {
                    render::FrameStats st;
                    return downsample(raycaster.render(*s.store, *s.cache, *s.tf, c, co, st),
                                      rc.supersampling);
                });
            const auto c = render::compareImages(t.first, reference);
            rc.ms = t.ms;
            rc.psnr = c.psnrDb;
            rc.ssim = c.ssim;
            r.raycasts.push_back(rc);
        }
        std::fprintf(stderr, "bench-splat: %s / %s %s done (%.0f%% splats)\n", d.name.c_str(),
                     d.preset.c_str(), v.name, 100.0 * r.splatFraction());
        out.push_back(std::move(r));
    }
    return out;
}

std::string dims(const render::LevelGeometry& g) {
    return std::to_string(g.dims[0]) + "x" + std::to_string(g.dims[1]) + "x" +
           std::to_string(g.dims[2]);
}

std::string raycastText(const RaycastConfig* r) {
    if (!r) return "none as accurate";
    char b[96];
    std::snprintf(b, sizeof b, "step %g, %ux%u: %.0f ms, %.1f dB", r->step, r->supersampling,
                  r->supersampling, r->ms, r->psnr);
    return b;
}

void printTables(const std::vector<std::pair<Dataset, std::string>>& sets,
                 const std::vector<std::uint64_t>& visible,
                 const std::vector<std::vector<ViewResult>>& results, const SplatBenchOptions& o) {
    std::printf(
        "\n## Figure 9 layout: hybrid splatter ms per %u^2 frame (share drawn as splats)\n\n",
        o.size);
    std::printf("| Dataset | TF | Resolution | Non-transparent voxels | All splats | Mixed | "
                "All points |\n|---|---|---|---|---|---|---|\n");
    for (std::size_t i = 0; i < results.size(); ++i) {
        std::printf("| %s | %s | %s | %llu |", sets[i].first.name.c_str(),
                    sets[i].first.preset.c_str(), sets[i].second.c_str(),
                    (unsigned long long)visible[i]);
        for (const auto& r : results[i])
            std::printf(" %.0f (%.1f%%) |", r.splatMs, 100.0 * r.splatFraction());
        std::printf("\n");
    }
    std::printf("\n## Beside the raycaster at equal error (against the float64 reference, "
                "step %g, %ux%u supersampled)\n\n",
                o.referenceStep, o.referenceSupersampling, o.referenceSupersampling);
    std::printf("| Dataset | View | Distance | Drawn (culled) | Splatter ms | PSNR dB | SSIM | "
                "No culling ms (max diff) | GPU splatter ms (max diff) | Raycaster default | "
                "Raycaster at equal error | Splatter / equal-error raycaster time |\n"
                "|---|---|---|---|---|---|---|---|---|---|---|---|\n");
    for (const auto& rows : results)
        for (const auto& r : rows) {
            const auto* eq = r.equalError();
            char ratio[32] = "n/a";
            if (eq) std::snprintf(ratio, sizeof ratio, "%.2f", r.splatMs / eq->ms);
            char gpu[48] = "not run";
            if (!std::isnan(r.gpuMs))
                std::snprintf(gpu, sizeof gpu, "%.0f (%.5f)", r.gpuMs, r.gpuMaxAbs);
            std::printf(
                "| %s %s | %s | %.2f | %llu (%llu) | %.0f | %.1f | %.4f | %.0f (%.4f) | %s | "
                "%s | %s | %s |\n",
                r.dataset.c_str(), r.preset.c_str(), r.view.c_str(), r.distanceFactor,
                (unsigned long long)(r.n.points + r.n.splats), (unsigned long long)r.n.culled,
                r.splatMs, r.psnr, r.ssim, r.noCullMs, r.cullMaxAbs, gpu,
                raycastText(r.defaultRaycast()).c_str(), raycastText(eq).c_str(), ratio);
        }
}

void writeCsv(const std::string& path, const std::vector<std::vector<ViewResult>>& results) {
    std::ofstream out(path);
    if (!out) throw std::runtime_error(path + ": cannot write the CSV");
    out << "dataset,tf,view,distance_factor,renderer,step,supersampling,ms,psnr_db,ssim,splats,"
           "points,culled\n";
    for (const auto& rows : results)
        for (const auto& r : rows) {
            out << r.dataset << ',' << r.preset << ',' << r.view << ',' << r.distanceFactor
                << ",splatter,,1," << r.splatMs << ',' << r.psnr << ',' << r.ssim << ','
                << r.n.splats << ',' << r.n.points << ',' << r.n.culled << '\n';
            out << r.dataset << ',' << r.preset << ',' << r.view << ',' << r.distanceFactor
                << ",splatter no culling,,1," << r.noCullMs << ",,,,,\n";
            if (!std::isnan(r.gpuMs))
                out << r.dataset << ',' << r.preset << ',' << r.view << ',' << r.distanceFactor
                    << ",gpu splatter,,1," << r.gpuMs << ",,,,,\n";
            for (const auto& c : r.raycasts)
                out << r.dataset << ',' << r.preset << ',' << r.view << ',' << r.distanceFactor
                    << ",cpu raycaster," << c.step << ',' << c.supersampling << ',' << c.ms << ','
                    << c.psnr << ',' << c.ssim << ",,,\n";
        }
    if (!out) throw std::runtime_error(path + ": write failed");
}

void runSplatBench(const SplatBenchOptions& o) {
    if (o.frames < 1 || o.frames > 100) throw std::invalid_argument("--frames: 1..100");
    if (o.size < 16 || o.size > 2048) throw std::invalid_argument("--size: 16..2048");
    if (o.referenceSupersampling < 1 || o.referenceSupersampling > 8)
        throw std::invalid_argument("--reference-supersampling: 1..8");
    if (!(o.referenceStep > 0.0 && o.referenceStep <= 4.0))
        throw std::invalid_argument("--reference-step: (0, 4]");
    std::vector<RaycastConfig> sweep;
    for (double step : tools::parseNumbers(o.steps, "--steps", 1, 16)) {
        if (!(step > 0.0 && step <= 16.0))
            throw std::invalid_argument("--steps: each step in (0, 16] voxels");
        for (double k : tools::parseNumbers(o.supersampling, "--supersampling", 1, 8)) {
            if (k != std::floor(k) || k < 1 || k > 8)
                throw std::invalid_argument("--supersampling: whole factors 1..8");
            sweep.push_back({step, std::uint32_t(k)});
        }
    }
    std::vector<Dataset> datasets = realDatasets(o.data, o.datasets, o.tf, "bench-splat");
    if (!o.noChecker && (o.datasets.empty() || o.datasets.find("checker") != std::string::npos))
        datasets.push_back(checkerBox());
    if (datasets.empty())
        throw std::invalid_argument("--datasets: none of the named scans is here");

    std::optional<render::EglContext> context;
    if (!o.noGpu) {
        try {
            context.emplace();
        } catch (const std::exception& e) {
            std::fprintf(stderr, "bench-splat: no GPU splatter: %s\n", e.what());
        }
    }
    std::printf("brickcast bench-splat: %u^2 frames, %d timed frames per view (orbit 2 deg/frame "
                "at the view's distance), shaded, early termination 0.99, bricks %u^3 + 2, "
                "%u threads; CPU hybrid splatter (radius 1.25 voxels, points below 0.5 px) "
                "and CPU raycaster; GPU splatter on %s\n",
                o.size, o.frames, o.brick, std::thread::hardware_concurrency(),
                context ? context->renderer().c_str() : "nothing (not run)");
    const std::string tmp =
        (std::filesystem::temp_directory_path() / ("bc-bench-splat-" + std::to_string(getpid())))
            .string();
    std::filesystem::create_directories(tmp);
    std::vector<std::pair<Dataset, std::string>> sets;
    std::vector<std::uint64_t> visible;
    std::vector<std::vector<ViewResult>> results;
    for (const auto& d : datasets) {
        Scene s;
        auto source = brickstore::openSource(d.spec);
        brickstore::IngestConfig config;
        config.geometry = {o.brick, 2, 8};
        brickstore::ingest(*source, tmp + "/scan.bcs", config);
        s.store = brickstore::BrickStore::open(tmp + "/scan.bcs");
        s.cache = std::make_unique<brickstore::BrickCache>(
            *s.store, brickstore::BrickCacheConfig{4ull << 30});
        s.volume = std::make_unique<render::ReferenceVolume>(*s.store, 0);
        const auto stats = render::VolumeValueStats::fromStore(s.store->info());
        s.tf = d.tfJson.empty() ? tools::loadTransferFunction(d.preset, stats)
                                : render::TransferFunction::parse(d.tfJson, d.name, stats);
        visible.push_back(countVisible(*s.volume, s.tf->table(1.0)));
        sets.emplace_back(d, dims(render::LevelGeometry::of(*s.store, 0)));
        results.push_back(benchDataset(s, d, o, sweep, context.has_value()));
    }
    std::filesystem::remove_all(tmp);
    printTables(sets, visible, results, o);
    if (!o.csv.empty()) writeCsv(o.csv, results);
}

} // namespace
} // namespace bc::bench

int main(int argc, char** argv) {
    bc::bench::SplatBenchOptions o;
    CLI::App app{"Hybrid splatter timings in the layout of Yuan et al. 2003 Fig. 9, beside the "
                 "raycaster at equal error",
                 "bc_bench_splat"};
    app.add_option("--data", o.data, "Folder of the real scans")->capture_default_str();
    app.add_option(
        "--datasets", o.datasets,
        "Comma-separated scan names, 'checker' for the 100^3 checker box (default: all)");
    app.add_option("--tf", o.tf, "One preset or file for every scan (default: each scan's own)");
    app.add_option("--size", o.size, "Image edge")->capture_default_str();
    app.add_option("--frames", o.frames, "Timed frames per view")->capture_default_str();
    app.add_option("--steps", o.steps, "Raycaster steps swept, voxels")->capture_default_str();
    app.add_option("--supersampling", o.supersampling, "Raycaster supersampling factors swept")
        ->capture_default_str();
    app.add_option("--reference-step", o.referenceStep, "Step of the float64 reference")
        ->capture_default_str();
    app.add_option("--reference-supersampling", o.referenceSupersampling,
                   "Supersampling factor of the reference")
        ->capture_default_str();
    app.add_option("--brick", o.brick, "Brick edge of the stores")->capture_default_str();
    app.add_option("--csv", o.csv, "Write every measurement as CSV");
    app.add_flag("--no-checker", o.noChecker, "Leave out the generated 100^3 checker box");
    app.add_flag("--no-gpu", o.noGpu, "Leave out the GPU splatter (slow on llvmpipe)");
    app.callback([&o] { bc::bench::runSplatBench(o); });
    return bc::tools::runCommandLine(app, argc, argv, "bc_bench_splat");
}
