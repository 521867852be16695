// Ingest benchmark: per real dataset, ingest MB/s, compression ratio, single-core
// decompression GB/s and the bytes of constant (empty) bricks never stored; then what the
// synthetic generators (synth:phantom, synth:vessels) produce per second, slab by slab. Prints
// markdown tables; run it on an idle machine and say which machine in anything you quote.
#include "brickstore/BrickStore.h"
#include "brickstore/Ingest.h"
#include "brickstore/Readers.h"

#include <CLI/CLI.hpp>
#include <algorithm>
#include <array>
#include <chrono>
#include <cstdio>
#include <filesystem>
#include <span>
#include <thread>

namespace {

using namespace bc::brickstore;
using Clock = std::chrono::steady_clock;

struct Dataset {
    std::string name;
    SourceSpec spec;
};

std::vector<Dataset> datasets(const std::string& dir) {
    auto at = [&](const std::string& f) { return (std::filesystem::path(dir) / f).string(); };
    std::vector<Dataset> d;
    auto add = [&](std::string name, std::string input, std::array<double, 3> spacing = {1, 1, 1}) {
        SourceSpec s;
        s.input = std::move(input);
        s.spacingMm = spacing;
        d.push_back({std::move(name), s});
    };
    add("stanford_cthead (raw u16)", at("stanford_cthead_256x256x113_uint16.raw"), {1, 1, 2});
    add("CT_AVM (raw u8)", at("CT_AVM_256x242x154_uint8.raw"), {0.72, 0.721, 1.0});
    add("CT_AVM (NIfTI gz)", at("CT_AVM.nii.gz"));
    add("frog (raw u8)", at("frog_500x470x136_uint8.raw"), {1, 1, 1.5});
    add("pancreas CT (DICOM i16)", at("tcia_pancreas_ct_dicom"));
    add("Iguana (NIfTI gz)", at("Iguana.nii.gz"));
    add("gaffer_smoke (VDB f32)", at("gaffer_smoke.vdb"));
    add("hydrogen (raw f32)", at("hydrogen_64x64x64_float32.raw"));
    add("headsq quarter (raw u16)", at("vtk_headsq_quarter_64x64x93_uint16.raw"), {3.2, 3.2, 1.5});
    for (auto& x : d)
        if (x.spec.input.find(".raw") == std::string::npos) x.spec.spacingMm.reset();
    // The bricking literature's way to a gigabyte test volume: a real scan tiled N x M x K.
    SourceSpec mosaic = d.front().spec;
    mosaic.mosaic = {4, 4, 4};
    d.push_back({"cthead mosaic 4x4x4 (u16)", mosaic});
    return d;
}

/// Single-core decompression speed over every stored brick, best of `repeat` passes.
double decompressGBps(const BrickStore& store, int repeat) {
    std::vector<std::byte> buf(store.brickBytes());
    double best = 0;
    for (int r = 0; r < repeat; ++r) {
        std::uint64_t bytes = 0;
        auto t0 = Clock::now();
        for (std::uint64_t i = 0; i < store.layout().brickCount(); ++i) {
            BrickKey k = store.layout().keyOf(i);
            if (!store.record(k).stored()) continue;
            store.readBrick(k, buf);
            bytes += buf.size();
        }
        double s = std::chrono::duration<double>(Clock::now() - t0).count();
        if (s > 0) best = std::max(best, double(bytes) / 1e9 / s);
    }
    return best;
}

/// The generators' speed: an edge^3 volume of each kind read 16 slices at a time, best of
/// `repeat` passes (a checksum keeps the reads from being optimised away).
void printGeneratorTable(std::uint64_t edge, int repeat) {
    std::printf(
        "\n| generator | dims | type | MB | best s | MB/s |\n|---|---|---|---:|---:|---:|\n");
    const std::array<std::uint64_t, 3> dims{edge, edge, edge};
    std::uint64_t checksum = 0;
    for (const char* name : {"phantom", "vessels"}) {
        const SynthKind kind = *parseSynthKind(name);
        double best = 1e30, mb = 0;
        std::string type;
        for (int r = 0; r < repeat; ++r) {
            auto source = makeSynthetic(kind, dims, 1);
            const auto& info = source->info();
            std::vector<std::byte> slab(16 * info.sliceBytes());
            const auto t0 = Clock::now();
            for (std::uint64_t z = 0; z < edge; z += 16) {
                const std::uint64_t n = std::min<std::uint64_t>(16, edge - z);
                source->readSlices(n, std::span(slab).first(n * info.sliceBytes()));
                for (std::size_t i = 0; i < slab.size(); i += 4099)
                    checksum += std::to_integer<std::uint64_t>(slab[i]);
            }
            best = std::min(best, std::chrono::duration<double>(Clock::now() - t0).count());
            mb = double(info.sliceBytes() * edge) / 1e6;
            type = voxelTypeName(info.type);
        }
        std::printf("| synth:%s | %llu^3 | %s | %.0f | %.2f | %.0f |\n", name,
                    (unsigned long long)edge, type.c_str(), mb, best, mb / best);
    }
    std::printf("(checksum %llu)\n", (unsigned long long)checksum);
}

} // namespace

int main(int argc, char** argv) {
    CLI::App app{"brickcast ingest benchmark"};
    std::string dataDir = BC_SHARED_DATA_DIR,
                scratch = std::filesystem::temp_directory_path().string();
    BrickGeometry g;
    unsigned threads = 0;
    int repeat = 3, level = 3;
    app.add_option("--data", dataDir, "Folder of the real scans")->capture_default_str();
    app.add_option("--scratch", scratch, "Where stores are written")->capture_default_str();
    app.add_option("--brick", g.brickVoxels)->capture_default_str();
    app.add_option("--apron", g.apronVoxels)->capture_default_str();
    app.add_option("--threads", threads, "Ingest workers (0 = all cores)")->capture_default_str();
    app.add_option("--repeat", repeat, "Passes; the best is reported")->capture_default_str();
    app.add_option("--zstd-level", level)->capture_default_str();
    std::uint64_t synthEdge = 512;
    app.add_option("--synth-edge", synthEdge,
                   "Edge of the generated volumes (0: no generator table)")
        ->capture_default_str();
    CLI11_PARSE(app, argc, argv);

    unsigned cores = threads ? threads : std::max(1u, std::thread::hardware_concurrency());
    std::printf("brick %u^3 + apron %u, zstd level %d, %u ingest workers, best of %d\n\n",
                g.brickVoxels, g.apronVoxels, level, cores, repeat);
    std::printf("| dataset | dims | source MB | ingest MB/s | stored MB | ratio (bricks) | ratio "
                "(volume) | "
                "decompress GB/s/core | bricks stored/total | empty bytes not stored |\n");
    std::printf("|---|---|---:|---:|---:|---:|---:|---:|---:|---:|\n");
    const std::string store = (std::filesystem::path(scratch) / "bc-bench-ingest.bcs").string();
    for (const auto& d : datasets(dataDir)) {
        if (!std::filesystem::exists(d.spec.input)) {
            std::printf("| %s | missing: %s |\n", d.name.c_str(), d.spec.input.c_str());
            continue;
        }
        IngestReport best;
        best.seconds = 1e30;
        for (int r = 0; r < repeat; ++r) {
            auto src = openSource(d.spec);
            IngestConfig config;
            config.geometry = g;
            config.threads = threads;
            config.zstdLevel = level;
            auto rep = ingest(*src, store, config);
            if (rep.seconds < best.seconds) best = rep;
        }
        auto s = BrickStore::open(store);
        const auto& v = s->info().volume;
        double gbps = decompressGBps(*s, repeat);
        std::printf("| %s | %llux%llux%llu | %.1f | %.1f | %.2f | %.2f | %.2f | %.2f | %llu/%llu | "
                    "%.1f MB |\n",
                    d.name.c_str(), (unsigned long long)v.dims[0], (unsigned long long)v.dims[1],
                    (unsigned long long)v.dims[2], best.sourceBytes / 1e6,
                    best.sourceBytes / 1e6 / best.seconds, best.fileBytes / 1e6,
                    best.storedBytes ? double(best.uncompressedBrickBytes) / best.storedBytes : 0.0,
                    double(best.sourceBytes) / best.fileBytes, gbps,
                    (unsigned long long)best.storedBricks, (unsigned long long)best.bricks,
                    best.constantBrickBytes / 1e6);
        std::fflush(stdout);
    }
    std::filesystem::remove(store);
    std::printf(
        "\nratio (bricks): stored bricks' raw bytes (aprons included) / their compressed bytes.\n"
        "ratio (volume): level-0 source bytes / whole store file (all pyramid levels, index).\n");
    if (synthEdge > 0) printGeneratorTable(synthEdge, repeat);
    return 0;
}
