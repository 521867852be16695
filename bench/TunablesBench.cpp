// bc_bench_tunables: the skipping tunables swept one at a time from the defaults,
// on the real scans of each kind (dense CT, sparse vessels, smoke), so that the defaults are
// chosen from measurements. Tunables: the store's brick edge and leaf edge (ingest geometry),
// the distance maps' cell edge (RenderOptions::cellVoxels), the octree's ratio threshold and
// level limit (OccupancyConfig). For each value, with every other tunable at its default, over
// one camera path: median ms a frame (after a warm-up frame), the ratio to the same tunable's
// default row (measured beside it), samples taken / oracle samples (samples with opacity before the
// ray saturates, from the float64 reference) over the first timed frames, what a new transfer
// function costs (octrees and the first frame's distance maps, built from nothing) and the host
// bytes of the classification after the path (octrees, maps and tables). Markdown on stdout, CSV
// with --csv.
#include "bench/BenchDatasets.h"
#include "brickstore/BrickCache.h"
#include "brickstore/BrickStore.h"
#include "brickstore/Ingest.h"
#include "render/BrickPlan.h"
#include "render/Camera.h"
#include "render/Classification.h"
#include "render/EglContext.h"
#include "render/ReferenceRenderer.h"
#include "render/RendererRegistry.h"
#include "render/View.h"
#include "tools/Parse.h"
#include "tools/RunCommandLine.h"
#include "tools/TransferFunctionFile.h"

#include <CLI/CLI.hpp>

#include <algorithm>
#include <cstdio>
#include <filesystem>
#include <fstream>
#include <map>
#include <optional>
#include <random>
#include <unistd.h>

namespace bc::bench {
namespace {

struct TunablesOptions {
    std::string data = BC_SHARED_DATA_DIR, datasets = "stanford_cthead,CT_AVM,hydrogen", tf,
                path = "orbit", renderer = "cpu", csv;
    std::uint32_t size = 256;
    int frames = 8, oracleFrames = 3;
};

/// One point of the sweep: the defaults with one tunable changed.
struct Variant {
    std::string tunable, value;
    brickstore::BrickGeometry geometry;
    std::uint32_t cellVoxels = render::RenderOptions{}.cellVoxels;
    render::OccupancyConfig octree;
    bool isDefault = false;
};

std::vector<Variant> variants() {
    const Variant d{"default",
                    "",
                    brickstore::BrickGeometry{},
                    render::RenderOptions{}.cellVoxels,
                    render::OccupancyConfig{},
                    true};
    std::vector<Variant> out;
    auto add = [&](const char* tunable, std::string value, auto change) {
        Variant v = d;
        v.tunable = tunable;
        v.value = std::move(value);
        change(v);
        v.isDefault = v.geometry.brickVoxels == d.geometry.brickVoxels &&
                      v.geometry.leafVoxels == d.geometry.leafVoxels &&
                      v.cellVoxels == d.cellVoxels && v.octree == d.octree;
        out.push_back(v);
    };
    for (std::uint32_t b : {32u, 64u, 128u})
        add("brick edge", std::to_string(b), [b](Variant& v) { v.geometry.brickVoxels = b; });
    for (std::uint32_t l : {4u, 8u, 16u})
        add("leaf edge", std::to_string(l), [l](Variant& v) { v.geometry.leafVoxels = l; });
    for (std::uint32_t c : {0u, 1u, 2u, 4u})
        add("map cell edge", c ? std::to_string(c) : "off", [c](Variant& v) { v.cellVoxels = c; });
    for (const char* r : {"1", "0.75", "0.5"})
        add("octree ratio", r, [r](Variant& v) { v.octree.ratioThreshold = std::stod(r); });
    for (std::uint32_t l : {32u, 2u, 1u})
        add("octree level limit", l == 32 ? "none" : std::to_string(l),
            [l](Variant& v) { v.octree.levelLimit = l; });
    return out;
}

struct Row {
    std::string dataset, tf, tunable, value;
    bool isDefault = false;
    double ms = 0, ratio = 0, overOracle = 0, octreeMs = 0, mapsMs = 0, mapsPathMs = 0;
    double classificationBytes = 0, bricks = 0;
};

double median(std::vector<double> v) {
    if (v.empty()) return 0.0;
    std::sort(v.begin(), v.end());
    return v[v.size() / 2];
}

/// A store of `d` with `geometry`, ingested once per geometry into `dir`.
struct Stores {
    std::string dir;
    std::map<std::string, std::unique_ptr<brickstore::BrickStore>> open;
    brickstore::BrickStore& of(const Dataset& d, const brickstore::BrickGeometry& g) {
        const std::string key = std::to_string(g.brickVoxels) + "-" + std::to_string(g.leafVoxels);
        auto& s = open[key];
        if (s) return *s;
        const std::string path = dir + "/" + key + ".bcs";
        auto source = brickstore::openSource(d.spec);
        brickstore::IngestConfig config;
        config.geometry = g;
        brickstore::ingest(*source, path, config);
        s = brickstore::BrickStore::open(path);
        return *s;
    }
};

Row measure(brickstore::BrickStore& store, const render::TransferFunction& tf, const Variant& v,
            const TunablesOptions& o, const std::vector<render::Camera>& cams,
            const std::vector<std::uint64_t>& oracle) {
    brickstore::BrickCache cache(store, brickstore::BrickCacheConfig{4ull << 30});
    render::ClassificationCache classifications; // a new transfer function: built from nothing
    auto renderer = render::RendererRegistry::builtin().create(o.renderer);
    render::RenderOptions ro;
    ro.width = ro.height = o.size;
    ro.cellVoxels = v.cellVoxels;
    ro.octree = v.octree;
    Row row;
    std::vector<double> ms;
    double samples = 0, oracleSum = 0;
    for (std::size_t f = 0; f < cams.size(); ++f) {
        render::FrameStats st;
        renderer->render(render::Scene{store, cache, tf, classifications},
                         render::View::of(cams[f], o.size, o.size), ro, st);
        row.mapsPathMs += st.cellBuildMs;
        if (f == 0) {
            row.octreeMs = st.octreeRebuildMs;
            row.mapsMs = st.cellBuildMs;
            row.bricks = double(st.bricksVisited);
            continue;
        }
        ms.push_back(st.totalMs);
        if (f - 1 < oracle.size()) {
            samples += double(st.samples);
            oracleSum += double(oracle[f - 1]);
        }
    }
    row.ms = median(ms);
    row.overOracle = samples / std::max(oracleSum, 1.0);
    row.classificationBytes = double(classifications.stats().residentBytes);
    return row;
}

void printTable(const std::vector<Row>& rows) {
    std::string last;
    for (const Row& r : rows) {
        if (r.dataset + r.tf != last) {
            std::printf("\n### %s / %s\n\n| tunable | value | ms/frame | x default | samples / "
                        "oracle | new TF: octrees ms | + maps ms (first frame) | maps ms (path) "
                        "| classification KiB | bricks drawn |\n|---|---|---:|---:|---:|---:|---:|"
                        "---:|---:|---:|\n",
                        r.dataset.c_str(), r.tf.c_str());
            last = r.dataset + r.tf;
        }
        std::printf("| %s | %s%s | %.1f | %.2fx | %.2f | %.1f | %.1f | %.1f | %.0f | %.0f |\n",
                    r.tunable.c_str(), r.value.c_str(), r.isDefault ? " (default)" : "", r.ms,
                    r.ratio, r.overOracle, r.octreeMs, r.mapsMs, r.mapsPathMs,
                    r.classificationBytes / 1024.0, r.bricks);
    }
}

void writeCsv(const std::vector<Row>& rows, const std::string& path) {
    std::ofstream out(path);
    out << "dataset,tf,tunable,value,default,ms,ratio,samples_over_oracle,octree_ms,maps_ms,"
           "maps_path_ms,classification_bytes,bricks\n";
    for (const Row& r : rows)
        out << r.dataset << ',' << r.tf << ',' << r.tunable << ',' << r.value << ','
            << int(r.isDefault) << ',' << r.ms << ',' << r.ratio << ',' << r.overOracle << ','
            << r.octreeMs << ',' << r.mapsMs << ',' << r.mapsPathMs << ',' << r.classificationBytes
            << ',' << r.bricks << '\n';
    if (!out) throw std::runtime_error(path + ": cannot write the CSV");
}

void runSweep(const TunablesOptions& o) {
    if (o.frames < 1 || o.frames > 1000) throw std::invalid_argument("--frames: 1..1000");
    if (o.oracleFrames < 1) throw std::invalid_argument("--oracle-frames: at least 1");
    if (o.size < 8 || o.size > 4096) throw std::invalid_argument("--size: 8..4096");
    if (o.path != "orbit" && o.path != "jumps")
        throw std::invalid_argument("--path: '" + o.path + "' is not orbit or jumps");
    if (o.renderer != "cpu" && o.renderer != "gpu")
        throw std::invalid_argument("--renderer: '" + o.renderer + "' is not cpu or gpu");
    const auto datasets = realDatasets(o.data, o.datasets, o.tf, "bc_bench_tunables");
    if (datasets.empty()) throw std::invalid_argument("--datasets: none of them is here");
    std::optional<render::EglContext> context; // the GPU raycaster's (llvmpipe without a GPU)
    if (o.renderer == "gpu") context.emplace();
    std::printf("bc_bench_tunables: %s raycaster, %u^2, %s path, %d timed frames after one, "
                "step 1, shaded, samples / oracle over the first %d timed frames\n",
                o.renderer.c_str(), o.size, o.path.c_str(), o.frames, o.oracleFrames);
    const std::string tmp =
        (std::filesystem::temp_directory_path() / ("bc-tunables-" + std::to_string(getpid())))
            .string();
    std::vector<Row> rows;
    for (const Dataset& d : datasets) {
        std::filesystem::create_directories(tmp);
        Stores stores{tmp, {}};
        brickstore::BrickStore& base = stores.of(d, brickstore::BrickGeometry{});
        const auto tf =
            tools::loadTransferFunction(d.preset, render::VolumeValueStats::fromStore(base.info()));
        const auto cams = cameraPath(o.path, render::LevelGeometry::of(base, 0).box, o.frames);
        // The oracle: the same for every geometry (sample positions do not depend on it).
        const render::ReferenceVolume volume(base, 0);
        std::vector<std::uint64_t> oracle;
        render::RenderOptions ro;
        ro.width = ro.height = o.size;
        for (int f = 1; f <= std::min(o.frames, o.oracleFrames); ++f) {
            render::FrameStats st;
            render::renderReference(base, volume, tf, cams[std::size_t(f)], ro, st);
            oracle.push_back(st.oracleSamples);
        }
        const std::size_t first = rows.size();
        std::map<std::string, double> defaultMs; // per tunable: its own default row, measured
        for (const Variant& v : variants()) {    // beside its other values
            Row row = measure(stores.of(d, v.geometry), tf, v, o, cams, oracle);
            row.dataset = d.name;
            row.tf = d.preset;
            row.tunable = v.tunable;
            row.value = v.value;
            row.isDefault = v.isDefault;
            if (v.isDefault) defaultMs[v.tunable] = row.ms;
            rows.push_back(row);
            std::fprintf(stderr, "tunables: %s / %s %s %s: %.1f ms\n", d.name.c_str(),
                         d.preset.c_str(), v.tunable.c_str(), v.value.c_str(), row.ms);
        }
        for (std::size_t i = first; i < rows.size(); ++i)
            rows[i].ratio = rows[i].ms / std::max(defaultMs[rows[i].tunable], 1e-9);
        std::filesystem::remove_all(tmp);
    }
    printTable(rows);
    if (!o.csv.empty()) writeCsv(rows, o.csv);
}

} // namespace
} // namespace bc::bench

int main(int argc, char** argv) {
    bc::bench::TunablesOptions o;
    CLI::App app{"The skipping tunables swept one at a time from the defaults, on the real scans",
                 "bc_bench_tunables"};
    app.add_option("--data", o.data, "Folder of the real scans")->capture_default_str();
    app.add_option("--datasets", o.datasets, "Comma-separated scan names")->capture_default_str();
    app.add_option("--tf", o.tf, "One preset or file for every scan (default: each scan's own)");
    app.add_option("--size", o.size, "Image edge")->capture_default_str();
    app.add_option("--path", o.path, "Camera path: orbit or jumps")->capture_default_str();
    app.add_option("--frames", o.frames, "Timed frames")->capture_default_str();
    app.add_option("--oracle-frames", o.oracleFrames,
                   "Timed frames whose samples are set against the reference's oracle")
        ->capture_default_str();
    app.add_option("--renderer", o.renderer, "cpu or gpu (needs EGL)")->capture_default_str();
    app.add_option("--csv", o.csv, "Write every row as CSV");
    app.callback([&o] { bc::bench::runSweep(o); });
    return bc::tools::runCommandLine(app, argc, argv, "bc_bench_tunables");
}
