// Ray-guided residency benchmark (render/RESIDENCY.md): the GPU raycaster flies a
// 1 degree a frame orbit around dense volumes under opaque and see-through transfer functions,
// with pools from half the plan to more than all of it, ray-guided residency on and off.
// Prints, per volume and transfer function: the plan P (bricks in view the TF can show) and
// what rays enter E, then per pool budget both ways: GPU hit rate, uploads and MiB a frame,
// passes a frame, frame ms, and the worst difference from the image with every brick
// resident. Markdown on stdout; --csv writes every cell. In process, no daemon: this is the
// renderer's own residency, the bus benchmark (bc_bench_bus) measures the server around it.
#include "brickstore/BrickCache.h"
#include "brickstore/BrickStore.h"
#include "brickstore/Ingest.h"
#include "brickstore/Readers.h"
#include "render/BrickPlan.h"
#include "render/EglContext.h"
#include "render/GpuRaycaster.h"
#include "render/ImageMetrics.h"
#include "render/TransferFunction.h"
#include "tools/TransferFunctionFile.h"

#include <CLI/CLI.hpp>

#include <algorithm>
#include <cmath>
#include <cstdio>
#include <filesystem>
#include <fstream>
#include <sstream>

namespace {

using namespace bc;
constexpr double kMiB = 1024.0 * 1024.0;

/// Skin as an opaque surface: the case ray-guided residency is for.
constexpr const char* kOpaqueSkin = R"({"name": "opaque-skin", "shading": true, "points": [
    {"fraction": 0.22, "rgba": [0.90, 0.70, 0.55, 0.0]},
    {"fraction": 0.29, "rgba": [0.93, 0.74, 0.61, 0.6]},
    {"fraction": 1.0, "rgba": [1.00, 0.95, 0.90, 0.6]}]})";

struct Options {
    int size = 128, frames = 48, warmup = 4;
    std::uint64_t edge = 256, brick = 32;
    std::string budgets = "0.5,0.75,1,1.5", tfs = "opaque-skin,ct-bone,ct-skin",
                scans = "phantom,cthead";
    std::string dataDir = BC_SHARED_DATA_DIR, storeDir, csv;
    bool quick = false;
};

std::string fmt(const char* format, double v) {
    char b[64];
    std::snprintf(b, sizeof b, format, v);
    return b;
}

struct Table {
    std::string id;
    std::vector<std::string> head;
    std::vector<std::vector<std::string>> rows;
};
std::vector<Table> gTables;

void printTable(const Table& t) {
    std::string line = "\n|";
    for (const auto& h : t.head)
        line += " " + h + " |";
    line += "\n|";
    for (std::size_t i = 0; i < t.head.size(); ++i)
        line += "---|";
    for (const auto& r : t.rows) {
        line += "\n|";
        for (const auto& c : r)
            line += " " + c + " |";
    }
    std::printf("%s\n", line.c_str());
    std::fflush(stdout);
    gTables.push_back(t);
}

std::vector<double> numbers(const std::string& text, const char* option) {
    std::vector<double> out;
    std::stringstream ss(text);
    for (std::string item; std::getline(ss, item, ',');) {
        std::size_t used = 0;
        double v = 0;
        try {
            v = std::stod(item, &used);
        } catch (const std::exception&) {
            used = 0;
        }
        if (used != item.size() || !(v > 0) || v > 100)
            throw std::invalid_argument(std::string(option) + ": '" + item +
                                        "' is not a number in (0, 100]");
        out.push_back(v);
    }
    if (out.empty()) throw std::invalid_argument(std::string(option) + ": empty list");
    return out;
}

std::vector<std::string> names(const std::string& text) {
    std::vector<std::string> out;
    std::stringstream ss(text);
    for (std::string item; std::getline(ss, item, ',');)
        if (!item.empty()) out.push_back(item);
    return out;
}

struct Volume {
    std::string name;
    std::unique_ptr<brickstore::BrickStore> store;
    std::unique_ptr<brickstore::BrickCache> cache;
    render::VolumeValueStats stats;
    std::uint64_t slotBytes = 0;
};

/// The store of `scan` (ingested once into --store-dir), or nullptr when its file is missing.
std::unique_ptr<Volume> openVolume(const std::string& scan, const Options& o) {
    brickstore::SourceSpec spec;
    std::string file;
    if (scan == "phantom" || scan == "vessels") {
        spec.input = "synth:" + scan;
        spec.dims = std::array<std::uint64_t, 3>{o.edge, o.edge, o.edge};
        file = scan + "_" + std::to_string(o.edge) + "_b" + std::to_string(o.brick) + ".bcs";
    } else if (scan == "cthead") {
        spec.input =
            (std::filesystem::path(o.dataDir) / "stanford_cthead_256x256x113_uint16.raw").string();
        spec.spacingMm = std::array<double, 3>{1, 1, 2};
        if (!std::filesystem::exists(spec.input)) {
            std::fprintf(stderr, "bc_bench_residency: %s missing, cthead left out\n",
                         spec.input.c_str());
            return nullptr;
        }
        file = "cthead_b" + std::to_string(o.brick) + ".bcs";
    } else {
        throw std::invalid_argument("--scans: unknown scan '" + scan +
                                    "' (phantom, vessels, cthead)");
    }
    auto v = std::make_unique<Volume>();
    v->name = scan == "cthead" ? "cthead 256x256x113 u16"
                               : scan + " " + std::to_string(o.edge) + "^3 " +
                                     (scan == "phantom" ? "u16" : "u8");
    const std::string path = (std::filesystem::path(o.storeDir) / file).string();
    if (!std::filesystem::exists(path)) {
        auto source = brickstore::openSource(spec);
        brickstore::IngestConfig config;
        config.geometry = {std::uint32_t(o.brick), 2, 8};
        brickstore::ingest(*source, path, config);
    }
    v->store = brickstore::BrickStore::open(path);
    v->cache = std::make_unique<brickstore::BrickCache>(*v->store,
                                                        brickstore::BrickCacheConfig{4ull << 30});
    v->stats = render::VolumeValueStats::fromStore(v->store->info());
    const std::uint64_t e = v->store->layout().storedEdge();
    v->slotBytes = e * e * e * brickstore::voxelBytes(v->store->info().volume.type);
    return v;
}

struct Run {
    double planned = 0, entered = 0, uploads = 0, hits = 0, passes = 0, resumes = 0;
    double deferred = 0, requested = 0, frameMs = 0, fallbacks = 0, worst = 0;
    std::uint32_t slots = 0; ///< the pool's capacity
    std::vector<render::Image> images;
};

/// One orbit with a fresh raycaster; the figures are means over the frames after the warm-up.
Run fly(Volume& v, const render::TransferFunction& tf, std::uint64_t budgetBytes, bool guided,
        const Options& o, const std::vector<render::Image>* reference) {
    render::GpuRaycaster r({budgetBytes});
    render::RenderOptions ro;
    ro.width = ro.height = std::uint32_t(o.size);
    ro.rayGuided = guided;
    const render::Box box = render::LevelGeometry::of(*v.store, 0).box;
    Run run;
    std::uint64_t hitsBefore = 0;
    for (int f = 0; f < o.frames; ++f) {
        render::FrameStats s;
        if (f == o.warmup && r.pool()) hitsBefore = r.pool()->stats().hits;
        render::Image image =
            r.render(*v.store, *v.cache, tf, render::Camera::orbit(box, 30.0 + f, 20), ro, s);
        if (reference)
            run.worst = std::max(run.worst,
                                 render::compareImages(image, (*reference)[std::size_t(f)]).maxAbs);
        else
            run.images.push_back(std::move(image));
        if (f < o.warmup) continue;
        run.planned += double(s.bricksVisited - s.bricksConstant);
        run.entered += double(s.bricksEntered);
        run.uploads += double(s.bricksUploaded);
        run.passes += double(s.batches + s.resumePasses);
        run.resumes += double(s.resumePasses);
        run.deferred += double(s.bricksDeferred);
        run.requested += double(s.bricksRequested);
        run.fallbacks += s.guidedFallback;
        run.frameMs += s.totalMs;
    }
    const double n = double(o.frames - o.warmup);
    run.hits = double(r.pool()->stats().hits - hitsBefore);
    run.slots = r.pool()->capacity();
    for (double* x : {&run.planned, &run.entered, &run.uploads, &run.passes, &run.resumes,
                      &run.deferred, &run.requested, &run.frameMs})
        *x /= n;
    run.hits /= n;
    return run;
}

void runAll(const Options& o) {
    const auto budgets = numbers(o.budgets, "--budgets");
    render::EglContext context;
    std::printf(
        "# bc_bench_residency: ray-guided residency (render/RESIDENCY.md)\n\n"
        "GPU raycaster on %s (%s), %d^2 frames, step 1 voxel, early termination 0.99, "
        "bricks + octree skipping and occlusion frustums on; orbit 1 degree a frame at "
        "elevation 20, the whole volume in view; %d frames, the first %d left out of the "
        "means. P = sampled bricks the plan keeps a frame, E = those an unsaturated ray "
        "enters (the frame's true working set). Budgets are multiples of P. Every run is a "
        "fresh raycaster (cold pool); \"worst diff\" is the largest channel difference from "
        "the same frame with every brick resident.\n",
        context.renderer().c_str(), context.version().c_str(), o.size, o.frames, o.warmup);
    for (const std::string& scan : names(o.scans)) {
        auto v = openVolume(scan, o);
        if (!v) continue;
        for (const std::string& tfName : names(o.tfs)) {
            const auto tf =
                tfName == "opaque-skin"
                    ? render::TransferFunction::parse(kOpaqueSkin, "<opaque-skin>", v->stats)
                    : tools::loadTransferFunction(tfName, v->stats);
            const std::uint64_t all = (v->store->layout().brickCount() + 1) * v->slotBytes;
            const Run full = fly(*v, tf, all, true, o, nullptr);
            const std::string what = v->name + ", " + tfName;
            std::printf(
                "\n## %s\n\nP = %.0f bricks (%.1f MiB), E = %.0f (%.0f%% of P); every brick "
                "resident: %.1f ms a frame, %.2f passes.\n",
                what.c_str(), full.planned, full.planned * double(v->slotBytes) / kMiB,
                full.entered, 100.0 * full.entered / std::max(full.planned, 1.0), full.frameMs,
                full.passes);
            Table t{"residency " + what,
                    {"pool (x P)", "slots", "ray-guided", "GPU hit rate", "uploads / frame",
                     "MiB up / frame", "passes / frame", "of them resuming", "deferred / frame",
                     "asked for / frame", "fallback frames", "frame ms", "worst diff"},
                    {}};
            for (double m : budgets) {
                const auto slots = std::max<std::uint64_t>(1, std::uint64_t(m * full.planned));
                for (bool guided : {false, true}) {
                    const Run run = fly(*v, tf, slots * v->slotBytes, guided, o, &full.images);
                    t.rows.push_back(
                        {fmt("%.2f", m), std::to_string(run.slots), guided ? "on" : "off",
                         fmt("%.1f%%", 100.0 * run.hits / std::max(run.hits + run.uploads, 1e-9)),
                         fmt("%.1f", run.uploads),
                         fmt("%.2f", run.uploads * double(v->slotBytes) / kMiB),
                         fmt("%.2f", run.passes), fmt("%.2f", run.resumes),
                         fmt("%.1f", run.deferred), fmt("%.1f", run.requested),
                         fmt("%.0f", run.fallbacks), fmt("%.1f", run.frameMs),
                         fmt("%.2g", run.worst)});
                }
            }
            printTable(t);
        }
    }
}

void writeCsv(const std::string& path) {
    std::ofstream out(path);
    if (!out) throw std::runtime_error("--csv: cannot write " + path);
    auto cell = [](const std::string& s) {
        if (s.find_first_of(",\"\n") == std::string::npos) return s;
        std::string q = "\"";
        for (char c : s)
            q += c == '"' ? std::string("\"\"") : std::string(1, c);
        return q + "\"";
    };
    out << "table,row,column,value\n";
    for (const auto& t : gTables)
        for (std::size_t r = 0; r < t.rows.size(); ++r)
            for (std::size_t c = 0; c < t.rows[r].size() && c < t.head.size(); ++c)
                out << cell(t.id) << ',' << r << ',' << cell(t.head[c]) << ',' << cell(t.rows[r][c])
                    << '\n';
}

} // namespace

int main(int argc, char** argv) {
    Options o;
    CLI::App app{"Ray-guided residency: uploads, passes and frame time against the pool budget, "
                 "on and off (tables on stdout)"};
    app.add_option("--size", o.size, "Image edge (pixels)")
        ->capture_default_str()
        ->check(CLI::Range(16, 1024));
    app.add_option("--frames", o.frames, "Frames of each orbit")
        ->capture_default_str()
        ->check(CLI::Range(2, 3600));
    app.add_option("--warmup", o.warmup, "Frames left out of the means")
        ->capture_default_str()
        ->check(CLI::Range(1, 100));
    app.add_option("--edge", o.edge, "Edge of the generated phantom (voxels)")
        ->capture_default_str()
        ->check(CLI::Range(32, 2048));
    app.add_option("--brick", o.brick, "Brick edge (voxels)")
        ->capture_default_str()
        ->check(CLI::IsMember({8, 16, 32, 64}));
    app.add_option("--budgets", o.budgets, "Pool budgets, multiples of the plan P")
        ->capture_default_str();
    app.add_option("--tfs", o.tfs, "Transfer functions: opaque-skin or presets")
        ->capture_default_str();
    app.add_option("--scans", o.scans, "phantom, vessels (generated), cthead (../shared/data)")
        ->capture_default_str();
    app.add_option("--data-dir", o.dataDir, "Where the real scans are")->capture_default_str();
    app.add_option("--store-dir", o.storeDir,
                   "Where ingested stores are kept (default: a temporary folder)");
    app.add_option("--csv", o.csv, "Write every table cell as CSV");
    app.add_flag("--quick", o.quick, "A short run: 64^2, 16 frames, opaque-skin, budgets 0.75,1.5");
    CLI11_PARSE(app, argc, argv);
    try {
        if (o.quick) {
            o.size = 64;
            o.frames = 16;
            o.tfs = "opaque-skin";
            o.budgets = "0.75,1.5";
        }
        if (o.warmup >= o.frames) throw std::invalid_argument("--warmup must be below --frames");
        if (o.storeDir.empty())
            o.storeDir = (std::filesystem::temp_directory_path() / "bc_bench_residency").string();
        std::filesystem::create_directories(o.storeDir);
        runAll(o);
        if (!o.csv.empty()) writeCsv(o.csv);
    } catch (const std::exception& e) {
        std::fprintf(stderr, "bc_bench_residency: %s\n", e.what());
        return 1;
    }
    return 0;
}
