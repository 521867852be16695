// Bus/residency benchmark: a brickcastd in this process on loopback, serving a
// generated "vessels" volume several times the GPU budget, driven by clients flying 1 degree
// a frame orbits with the GPU raycaster. Each run is a fresh daemon (a cold pool) on the same
// ingested store. Tables (markdown on stdout):
//   1. the volume and this machine's host -> GPU and disk -> host rates
//   2. the working set W (bytes of the distinct bricks one frame samples) with room for all
//   3. GPU/host hit rates, bytes moved and latency against the pool budget (multiples of W)
//   4. latency, frames/s and hit rate against clients at 2 W
//   5. prefetch on against off at 1.5 W and 1 W
//   6. the bus model (render ms at full residency + bytes / bandwidth) against table 3, then
//      its predictions for budgets larger than this machine's
// --csv writes every cell of every table (long form) and every frame; --plot draws PNGs
// with gnuplot. Figures are whatever renders here (llvmpipe without a GPU): the output says.
#include "brickstore/BrickStore.h"
#include "brickstore/Ingest.h"
#include "brickstore/Readers.h"
#include "client/Client.h"
#include "client/Orbit.h"
#include "server/Daemon.h"
#include "server/Log.h"

#include <CLI/CLI.hpp>

#include <algorithm>
#include <chrono>
#include <cmath>
#include <cstdio>
#include <filesystem>
#include <fstream>
#include <latch>
#include <map>
#include <mutex>
#include <numeric>
#include <sstream>
#include <thread>
#include <unistd.h>

namespace {

using namespace bc;
using Clock = std::chrono::steady_clock;
constexpr const char* kVolume = "vessels";
constexpr double kMiB = 1024.0 * 1024.0;

struct Options {
    double gpuBudgetMb = 16, hostBudgetMb = 1024, distance = 0.5, elevationDeg = 20, fovDeg = 7;
    double pcieGBs = 25, nvmeGBs = 3;
    std::uint64_t edge = 416;
    int frames = 90, warmup = 5, size = 64, clientFrames = 24, manyClientFrames = 8;
    std::string level = "0", clients = "1,4,16,64", budgets = "0.5,0.75,1,1.25,1.5,2,3",
                planGib = "1,4,16,64", csv, plot, storeDir;
    bool noPrefetchTable = false, quick = false;
};

// ---- small helpers -------------------------------------------------------------------------

std::vector<double> numberList(const std::string& text, const std::string& option) {
    std::vector<double> out;
    std::stringstream in(text);
    for (std::string item; std::getline(in, item, ',');) {
        std::size_t used = 0;
        double v = 0;
        try {
            v = std::stod(item, &used);
        } catch (const std::exception&) {
            used = 0;
        }
        if (used == 0 || used != item.size() || !std::isfinite(v) || v <= 0)
            throw std::invalid_argument(option + ": '" + item + "' is not a positive number");
        out.push_back(v);
    }
    if (out.empty()) throw std::invalid_argument(option + ": an empty list");
    return out;
}

double percentile(std::vector<double> v, double p) {
    if (v.empty()) return std::nan("");
    std::sort(v.begin(), v.end());
    return v[std::min(v.size() - 1, std::size_t(p / 100.0 * double(v.size())))];
}

double mean(const std::vector<double>& v) {
    return v.empty() ? std::nan("") : std::accumulate(v.begin(), v.end(), 0.0) / double(v.size());
}

std::string fmt(const char* format, double v) {
    if (std::isnan(v)) return "n/a";
    char b[64];
    std::snprintf(b, sizeof b, format, v);
    return b;
}

std::string mib(double bytes) {
    return fmt("%.2f", bytes / kMiB);
}
std::string pct(double fraction) {
    return fmt("%.1f%%", 100.0 * fraction);
}

double ratioOf(double a, double b) {
    return b > 0 ? a / b : std::nan("");
}

/// The server's counters: name{labels} -> value; of(name) sums every label set of name.
struct Counters {
    std::vector<std::pair<std::string, double>> values;
    double of(const std::string& name) const {
        double sum = 0;
        for (const auto& [k, v] : values)
            if (k == name || k.starts_with(name + "{")) sum += v;
        return sum;
    }
    bool has(const std::string& name) const {
        return std::any_of(values.begin(), values.end(), [&](const auto& kv) {
            return kv.first == name || kv.first.starts_with(name + "{");
        });
    }
};

// ---- tables --------------------------------------------------------------------------------

struct Table {
    std::string id;
    std::vector<std::string> head;
    std::vector<std::vector<std::string>> rows;
};

std::vector<Table> gTables; // every table printed, for --csv

void printTable(const Table& t) {
    std::string line = "\n|";
    for (const auto& h : t.head)
        line += " " + h + " |";
    line += "\n|";
    for (std::size_t i = 0; i < t.head.size(); ++i)
        line += "---|";
    std::printf("%s\n", line.c_str());
    for (const auto& r : t.rows) {
        line = "|";
        for (const auto& c : r)
            line += " " + c + " |";
        std::printf("%s\n", line.c_str());
    }
    std::fflush(stdout);
    gTables.push_back(t);
}

std::string csvCell(const std::string& s) {
    if (s.find_first_of(",\"\n") == std::string::npos) return s;
    std::string out = "\"";
    for (char c : s)
        out += c == '"' ? std::string("\"\"") : std::string(1, c);
    return out + "\"";
}

// ---- the store -----------------------------------------------------------------------------

struct StoreFacts {
    std::string path;
    std::uint64_t voxelBytes = 0, storedBytes = 0, storedBricks = 0, bricks = 0, slotBytes = 0;
    std::uint32_t storedEdge = 0, brickVoxels = 0, levels = 0;
    double ingestS = 0;        ///< 0 when the store was already there
    double diskBytesPerMs = 0; ///< read + decompress every stored brick, one thread
};

/// The path Catalog gives a generated entry (server/Catalog.cpp generatedStore), so the
/// daemons find the store this ingests and never ingest again.
std::string generatedPath(const std::string& dir, std::uint64_t edge) {
    const std::string e = std::to_string(edge);
    return (std::filesystem::path(dir) /
            (std::string(kVolume) + "_" + e + "x" + e + "x" + e + ".bcs"))
        .string();
}

StoreFacts prepareStore(const std::string& dir, std::uint64_t edge) {
    StoreFacts f;
    f.path = generatedPath(dir, edge);
    std::filesystem::create_directories(dir);
    if (!std::filesystem::exists(f.path)) {
        const auto start = Clock::now();
        auto source =
            brickstore::makeSynthetic(brickstore::SynthKind::Vessels, {edge, edge, edge}, 1);
        brickstore::ingest(*source, f.path, {});
        f.ingestS = std::chrono::duration<double>(Clock::now() - start).count();
    }
    const auto store = brickstore::BrickStore::open(f.path);
    const auto& info = store->info();
    const auto& layout = store->layout();
    f.voxelBytes = info.volume.dims[0] * info.volume.dims[1] * info.volume.dims[2] *
                   brickstore::voxelBytes(info.volume.type);
    f.storedBytes = info.storedBytes;
    f.storedBricks = info.storedBricks;
    f.bricks = layout.brickCount();
    f.slotBytes = store->brickBytes();
    f.storedEdge = layout.storedEdge();
    f.brickVoxels = layout.geometry().brickVoxels;
    f.levels = std::uint32_t(layout.levels().size());
    std::vector<std::byte> buffer(f.slotBytes);
    std::uint64_t read = 0;
    const auto start = Clock::now();
    for (std::uint64_t i = 0; i < f.bricks; ++i) {
        const auto key = layout.keyOf(i);
        if (!store->record(key).stored()) continue;
        store->readBrick(key, buffer);
        read += f.slotBytes;
    }
    f.diskBytesPerMs =
        double(read) / std::chrono::duration<double, std::milli>(Clock::now() - start).count();
    return f;
}

// ---- one run: a fresh daemon, N clients on orbits ------------------------------------------

struct RunSpec {
    std::string table, label;
    std::uint64_t gpuBudgetBytes = 0;
    bool prefetch = true;
    int clients = 1, frames = 90, warmup = 5;
    double distance = std::nan(""), fovDeg = std::nan(""); ///< NaN: the options' orbit
};

struct FrameRow {
    int client = 0, frame = 0;
    bool warmup = false;
    double latencyMs = 0, renderMs = 0, queueMs = 0;
    std::uint64_t bytesUploaded = 0, bricksDrawn = 0;
    int level = 0;
};

struct RunResult {
    RunSpec spec;
    std::vector<FrameRow> rows;
    Counters warmed, after; ///< after the warm-up frames (every client's), at the end
    double wallS = 0;       ///< the measured frames, all clients
    double delta(const std::string& name) const { return after.of(name) - warmed.of(name); }
};

struct Bench {
    Options o;
    StoreFacts store;
    std::vector<std::vector<std::string>> frameCsv;

    server::DaemonConfig configOf(const RunSpec& s) const {
        server::DaemonConfig c;
        c.source = "<bus bench>";
        c.listenPort = 0;
        c.maxClients = std::uint32_t(s.clients + 1); // and the control client
        c.gpuBudgetBytes = s.gpuBudgetBytes;
        c.hostBudgetBytes = std::uint64_t(o.hostBudgetMb * kMiB);
        c.prefetch = s.prefetch;
        c.storeDir = o.storeDir;
        c.readTimeoutMs = c.idleTimeoutMs = 600000;
        server::CatalogEntry e;
        e.name = kVolume;
        e.generate = kVolume;
        e.dims = {o.edge, o.edge, o.edge};
        c.volumes.push_back(e);
        return c;
    }

    protocol::RenderOptions renderOptions() const {
        protocol::RenderOptions r;
        r.width = r.height = std::uint16_t(o.size);
        r.codec = protocol::Codec::Zstd;
        r.quality = protocol::Quality::Refined; // full resolution, level 0: the plan never coarsens
        r.renderer = protocol::Renderer::GpuRaycaster;
        // Level 0 always: with "auto" the raycaster drops to a coarser level whenever level 0
        // does not fit the pool, so the pool never thrashes and the budget changes the image.
        r.level = o.level == "auto" ? protocol::kLevelAutomatic : std::uint8_t(std::stoi(o.level));
        return r;
    }

    /// The orbit's camera at `azimuthDeg`: the eye where orbitCamera puts it, the field of view
    /// narrowed to --fov (a zoom: the frame shows the volume's centre, fewer bricks).
    protocol::SetCamera cameraAt(const RunSpec& s, const protocol::VolumeInfo& info,
                                 double azimuthDeg, std::uint32_t id) const {
        const double distance = std::isnan(s.distance) ? o.distance : s.distance;
        const double fov = std::isnan(s.fovDeg) ? o.fovDeg : s.fovDeg;
        auto c = client::orbitCamera(info, azimuthDeg, o.elevationDeg, distance, id);
        c.orthoHeight *= std::tan(fov * M_PI / 360) / std::tan(c.fovYDeg * M_PI / 360);
        c.fovYDeg = fov;
        return c;
    }

    /// One client: `warmup` frames, then (once every client is warm) the rest.
    std::vector<FrameRow> fly(std::uint16_t port, const RunSpec& s, int index, std::latch& warmed,
                              std::latch& go) {
        client::ClientConfig cc;
        cc.port = port;
        cc.timeoutMs = 600000;
        bool arrived = false;
        std::vector<FrameRow> out;
        try {
            client::Client c(cc);
            const auto info = c.openVolume(kVolume);
            c.setRenderOptions(renderOptions());
            const double phase = 30.0 + 360.0 * index / s.clients;
            for (int f = 0; f < s.frames; ++f) {
                if (f == s.warmup) {
                    arrived = true;
                    warmed.count_down();
                    go.wait();
                }
                const auto start = Clock::now();
                c.setCamera(cameraAt(s, info, phase + f, std::uint32_t(f + 1)));
                c.requestFrame();
                const auto frame = c.nextFrame();
                FrameRow r;
                r.client = index;
                r.frame = f;
                r.warmup = f < s.warmup;
                r.latencyMs =
                    std::chrono::duration<double, std::milli>(Clock::now() - start).count();
                r.renderMs = frame.header.renderMs;
                r.queueMs = frame.header.queueMs;
                r.bytesUploaded = frame.header.bytesUploaded;
                r.bricksDrawn = frame.header.bricksDrawn;
                r.level = frame.header.level;
                out.push_back(r);
            }
            c.bye();
        } catch (...) {
            if (!arrived) warmed.count_down();
            throw;
        }
        return out;
    }

    RunResult run(const RunSpec& s) {
        RunResult result;
        result.spec = s;
        server::Log log(true);
        server::Daemon daemon(configOf(s), log);
        std::thread serving([&] { daemon.run(); });
        std::latch warmed(s.clients), go(1);
        std::mutex mutex;
        std::vector<std::string> errors;
        std::vector<std::thread> threads;
        bool released = false;
        try {
            client::ClientConfig cc;
            cc.port = daemon.port();
            cc.timeoutMs = 600000;
            client::Client control(cc); // opens no volume: the budget shares stay the clients'
            for (int i = 0; i < s.clients; ++i)
                threads.emplace_back([&, i] {
                    try {
                        auto rows = fly(daemon.port(), s, i, warmed, go);
                        std::lock_guard lock(mutex);
                        result.rows.insert(result.rows.end(), rows.begin(), rows.end());
                    } catch (const std::exception& e) {
                        std::lock_guard lock(mutex);
                        errors.push_back("client " + std::to_string(i) + ": " + e.what());
                    }
                });
            warmed.wait();
            result.warmed.values = control.stats();
            const auto start = Clock::now();
            released = true;
            go.count_down();
            for (auto& t : threads)
                t.join();
            result.wallS = std::chrono::duration<double>(Clock::now() - start).count();
            result.after.values = control.stats();
            control.bye();
        } catch (...) {
            if (!released) go.count_down();
            for (auto& t : threads)
                if (t.joinable()) t.join();
            daemon.stop();
            serving.join();
            throw;
        }
        daemon.stop();
        serving.join();
        if (!errors.empty())
            throw std::runtime_error(s.table + " " + s.label + ": " + errors.front());
        std::sort(result.rows.begin(), result.rows.end(), [](const FrameRow& a, const FrameRow& b) {
            return a.client != b.client ? a.client < b.client : a.frame < b.frame;
        });
        for (const auto& r : result.rows)
            frameCsv.push_back(
                {s.table, s.label, std::to_string(s.gpuBudgetBytes), s.prefetch ? "1" : "0",
                 std::to_string(s.clients), std::to_string(r.client), std::to_string(r.frame),
                 r.warmup ? "1" : "0", fmt("%.3f", r.latencyMs), fmt("%.3f", r.renderMs),
                 fmt("%.3f", r.queueMs), std::to_string(r.bytesUploaded),
                 std::to_string(r.bricksDrawn), std::to_string(r.level)});
        return result;
    }
};

// ---- what a run shows ----------------------------------------------------------------------

struct Summary {
    double frames = 0, poolBytes = 0, slots = 0;
    double gpuHitRate = 0, gpuHitRateAll = 0, hostHitRate = 0;
    double uploadsPerFrame = 0, bytesUpPerFrame = 0, bytesUpDuringFrames = 0, diskBytesPerFrame = 0;
    double movedOverDistinct = 0, uploadMsPerFrame = 0, renderMs = 0, p50 = 0, p99 = 0, fps = 0;
    double bytesUploadedAll = 0, uploadMsAll = 0, workingSet = 0;
    /// The prefetch counters, NaN where this server has none.
    double frameUploadsPerFrame = 0, prefetchUploadsPerFrame = 0, prefetchMsPerFrame = 0;
    double frameHitRate = 0; ///< hits / (hits + uploads a frame waited for): prefetch not a miss
};

Summary summarize(const RunResult& r, std::uint64_t slotBytes) {
    Summary s;
    std::vector<double> latency, render;
    double during = 0;
    for (const auto& f : r.rows)
        if (!f.warmup) {
            latency.push_back(f.latencyMs);
            render.push_back(f.renderMs);
            during += double(f.bytesUploaded);
        }
    s.frames = double(latency.size());
    const double n = std::max(s.frames, 1.0);
    const double hits = r.delta("gpu_pool_hits_total"), ups = r.delta("gpu_pool_uploads_total");
    s.gpuHitRate = ratioOf(hits, hits + ups);
    const double hitsAll = r.after.of("gpu_pool_hits_total"),
                 upsAll = r.after.of("gpu_pool_uploads_total");
    s.gpuHitRateAll = ratioOf(hitsAll, hitsAll + upsAll);
    const double hh = r.delta("host_cache_hits_total"), hm = r.delta("host_cache_misses_total");
    s.hostHitRate = ratioOf(hh, hh + hm);
    s.uploadsPerFrame = ups / n;
    s.bytesUpPerFrame = r.delta("gpu_pool_bytes_uploaded_total") / n;
    s.bytesUpDuringFrames = during / n;
    s.diskBytesPerFrame = r.delta("host_cache_bytes_loaded_total") / n;
    s.bytesUploadedAll = r.after.of("gpu_pool_bytes_uploaded_total");
    s.uploadMsAll = r.after.of("gpu_pool_upload_ms_total");
    s.movedOverDistinct = ratioOf(
        s.bytesUploadedAll, s.bytesUploadedAll - r.after.of("gpu_pool_bytes_refetched_total"));
    s.uploadMsPerFrame = r.delta("gpu_pool_upload_ms_total") / n;
    s.renderMs = mean(render);
    s.p50 = percentile(latency, 50);
    s.p99 = percentile(latency, 99);
    s.fps = s.frames / std::max(r.wallS, 1e-9);
    s.poolBytes = r.after.of("gpu_pool_budget_bytes");
    s.slots = s.poolBytes / double(slotBytes);
    auto perFrame = [&](const char* name) {
        return r.after.has(name) ? r.delta(name) / n : std::nan("");
    };
    s.frameUploadsPerFrame = perFrame("gpu_frame_uploads_total");
    s.prefetchUploadsPerFrame = perFrame("gpu_prefetch_uploads_total");
    s.prefetchMsPerFrame = perFrame("prefetch_ms_total");
    s.frameHitRate = ratioOf(hits, hits + s.frameUploadsPerFrame * n);
    s.workingSet =
        ratioOf(r.delta("frame_working_set_bytes_sum"), r.delta("frame_working_set_bytes_count"));
    return s;
}

// ---- the bus model -------------------------------------------------------------------------

/// Per-frame time = full-residency render ms + uploaded bytes / host->GPU rate + disk bytes /
/// disk rate. Upload bytes a frame, when not measured: the churn (bricks new to the view) if
/// the pool holds the working set, else the whole working set (an orbit revisits its bricks
/// in the order it last used them, which is the order LRU evicts them in).
struct BusModel {
    double renderMs = 0, upBytesPerMs = 0, diskBytesPerMs = 0, workingSet = 0, churn = 0;
    double predictMs(double upBytes, double diskBytes) const {
        return renderMs + upBytes / upBytesPerMs + diskBytes / diskBytesPerMs;
    }
    double uploadsFor(double poolBytes, double w, double churnBytes) const {
        return poolBytes >= w ? churnBytes : w;
    }
};

// ---- the tables ----------------------------------------------------------------------------

struct BudgetRun {
    double multiple; ///< of W; NaN for the nominal budget
    Summary s;
    bool prefetch;
};

void gnuplot(const std::string& script) {
    FILE* p = ::popen("gnuplot", "w");
    if (!p) throw std::runtime_error("--plot: cannot start gnuplot");
    std::fputs(script.c_str(), p);
    if (::pclose(p) != 0) std::fprintf(stderr, "bc_bench_bus: gnuplot reported an error\n");
}

/// A number as gnuplot reads it (NaN for a missing value).
std::string num(double v) {
    return std::isnan(v) ? "NaN" : fmt("%g", v);
}

void plots(const std::string& prefix, const std::vector<BudgetRun>& budgets,
           const std::vector<std::pair<int, Summary>>& clients, const BusModel& model) {
    std::string data = "$b << EOD\n";
    for (const auto& b : budgets) {
        if (std::isnan(b.multiple) || !b.prefetch) continue;
        const double predicted = model.predictMs(
            model.uploadsFor(b.s.poolBytes, model.workingSet, model.churn), b.s.diskBytesPerFrame);
        data += num(b.multiple) + " " + num(100 * b.s.gpuHitRate) + " " +
                num(100 * b.s.hostHitRate) + " " + num(b.s.bytesUpPerFrame / kMiB) + " " +
                num(model.uploadsFor(b.s.poolBytes, model.workingSet, model.churn) / kMiB) + " " +
                num(b.s.p50) + " " + num(b.s.p99) + " " + num(b.s.renderMs) + " " + num(predicted) +
                "\n";
    }
    data += "EOD\n$c << EOD\n";
    for (const auto& [n, s] : clients)
        data += std::to_string(n) + " " + num(s.p50) + " " + num(s.p99) + " " + num(s.fps) + " " +
                num(100 * s.gpuHitRate) + "\n";
    data += "EOD\nset terminal pngcairo size 900,560\nset grid\nset key left top\n";
    const std::string x = "set xlabel 'GPU pool budget / working set W'\n";
    gnuplot(data + x + "set output '" + prefix +
            "_hit_rate.png'\nset key right bottom\nset ylabel 'hit rate %'\n"
            "set yrange [0:105]\nset arrow from 1.5,0 to 1.5,105 nohead dt 2\n"
            "plot $b u 1:2 w lp lw 2 t 'GPU pool', $b u 1:3 w lp t 'host cache', "
            "95 dt 3 t '95% target'\n"
            "unset arrow\nset yrange [*:*]\nset key right top\n"
            "set output '" +
            prefix +
            "_bytes.png'\nset ylabel 'MiB uploaded per frame'\n"
            "plot $b u 1:4 w lp lw 2 t 'measured', $b u 1:5 w l dt 2 t 'model'\n"
            "set output '" +
            prefix +
            "_latency.png'\nset ylabel 'ms'\n"
            "plot $b u 1:6 w lp lw 2 t 'latency p50', $b u 1:7 w lp t 'latency p99', "
            "$b u 1:8 w lp t 'render ms (mean)', $b u 1:9 w l dt 2 t 'model: render ms'\n"
            "set output '" +
            prefix +
            "_clients.png'\nset logscale x 2\nset key left top\n"
            "set xlabel 'clients (budget 2 W)'\nset ylabel 'latency ms'\n"
            "set y2label 'frames/s, GPU hit rate %'\nset y2tics\nset ytics nomirror\n"
            "plot $c u 1:2 w lp lw 2 t 'latency p50', $c u 1:3 w lp t 'latency p99', "
            "$c u 1:4 w lp axes x1y2 t 'frames/s (all)', "
            "$c u 1:5 w lp dt 2 axes x1y2 t 'GPU hit rate %'\n");
}

void runAll(Bench& bench) {
    const Options& o = bench.o;
    const auto budgets = numberList(o.budgets, "--budgets");
    const auto planGib = numberList(o.planGib, "--plan-budgets-gib");
    std::vector<int> clientCounts;
    for (double c : numberList(o.clients, "--clients")) {
        if (c != std::floor(c) || c > 1023)
            throw std::invalid_argument("--clients: whole numbers 1..1023");
        clientCounts.push_back(int(c));
    }
    const auto runStart = Clock::now();
    const StoreFacts& f = bench.store = prepareStore(o.storeDir, o.edge);
    const double nominal = o.gpuBudgetMb * kMiB;
    std::printf(
        "# bc_bench_bus: the bus/residency model\n\n"
        "brickcastd in process on loopback; GPU raycaster (EGL: whatever this machine has, "
        "llvmpipe without a GPU), %d^2 refined frames at brick level %s, zstd; %u hardware "
        "threads. Orbit: 1 degree a frame about the volume centre, elevation %.0f deg, eye at "
        "%.2f x the distance that frames the whole volume in 30 deg, field of view %.1f deg "
        "(a zoom onto the centre: the full view samples most bricks of the volume, see the "
        "reference row below, and then no budget can be both >= 1.5 W and <= 1/4 of the "
        "volume). Each run is a fresh daemon (cold GPU pool and host cache) on one ingested "
        "store.\n",
        o.size, o.level.c_str(), std::thread::hardware_concurrency(), o.elevationDeg, o.distance,
        o.fovDeg);
    printTable(
        {"volume",
         {"volume", "voxel bytes MiB", "stored (compressed) MiB", "bricks (all levels)",
          "stored bricks", "slot = one stored brick", "nominal GPU budget MiB", "volume / budget",
          "ingest s", "disk->host MiB/s (read + unzstd, 1 thread)"},
         {{std::string(kVolume) + " " + std::to_string(o.edge) + "^3 u8", mib(double(f.voxelBytes)),
           mib(double(f.storedBytes)), std::to_string(f.bricks), std::to_string(f.storedBricks),
           std::to_string(f.storedEdge) + "^3 = " + std::to_string(f.slotBytes) + " B",
           fmt("%.1f", o.gpuBudgetMb),
           fmt("%.2fx", double(f.voxelBytes) / nominal) +
               (double(f.voxelBytes) >= 4 * nominal ? " (>= 4x)" : " (UNDER 4x)"),
           f.ingestS > 0 ? fmt("%.1f", f.ingestS) : "reused",
           fmt("%.0f", f.diskBytesPerMs * 1000 / kMiB)}}});

    // 2. The working set, with room for every brick.
    const std::uint64_t everything = (f.bricks + 1) * f.slotBytes;
    const int measured = o.frames - o.warmup;
    const auto wRun = bench.run({"W", "all resident", everything, true, 1, o.frames, o.warmup});
    const Summary ws = summarize(wRun, f.slotBytes);
    const double w = ws.workingSet;
    if (!(w > 0)) throw std::runtime_error("the working set came out empty: nothing was sampled");
    BusModel model;
    model.workingSet = w;
    model.churn = ws.bytesUpPerFrame;
    std::printf(
        "\n## Working set W\n\nOne client, a pool with room for every brick (%s MiB); W = "
        "frame_working_set_bytes_sum / _count over the frames after the %d warm-up frames "
        "(bytes of the distinct non-constant bricks a frame's plan samples, %llu B each). "
        "Churn = bytes uploaded a frame with everything resident: bricks new to the view.\n",
        mib(double(everything)).c_str(), o.warmup, (unsigned long long)f.slotBytes);
    Table t2{"working_set",
             {"orbit", "frames (after warm-up)", "W = mean working set MiB", "W slots",
              "W / volume voxel bytes", "churn: MiB uploaded a frame", "render ms (mean)",
              "latency p50 ms"},
             {}};
    auto wRow = [&](const std::string& name, const Summary& x) {
        t2.rows.push_back({name, std::to_string(int(x.frames)), mib(x.workingSet),
                           fmt("%.1f", x.workingSet / double(f.slotBytes)),
                           pct(x.workingSet / double(f.voxelBytes)), mib(x.bytesUpPerFrame),
                           fmt("%.2f", x.renderMs), fmt("%.1f", x.p50)});
    };
    wRow(fmt("this one (distance %.2f, ", o.distance) + fmt("fov %.1f)", o.fovDeg), ws);
    if (o.distance != 1.0 || o.fovDeg != 30.0) { // the full view, for reference (shorter)
        RunSpec full{
            "W", "full view", everything, true, 1, std::max(o.warmup + 10, o.frames / 4), o.warmup};
        full.distance = 1.0;
        full.fovDeg = 30.0;
        wRow("reference: full view (distance 1, fov 30)", summarize(bench.run(full), f.slotBytes));
    }
    printTable(t2);

    // 3. Hit rate against budget; the nominal budget too.
    std::vector<BudgetRun> runs;
    std::vector<double> multiples = budgets;
    multiples.push_back(std::nan(""));
    for (double m : multiples) {
        const double bytes = std::isnan(m) ? nominal : m * w;
        const auto r = bench.run({"budget", std::isnan(m) ? "nominal" : fmt("%gW", m),
                                  std::uint64_t(std::max(bytes, double(f.slotBytes))), true, 1,
                                  o.frames, o.warmup});
        runs.push_back({m, summarize(r, f.slotBytes), true});
        std::fprintf(stderr, "bc_bench_bus: budget %s done (%.0f s so far)\n", r.spec.label.c_str(),
                     std::chrono::duration<double>(Clock::now() - runStart).count());
    }
    std::printf(
        "\n## Hit rate against the GPU budget\n\nOne client, %d frames a run: the first %d "
        "(cold pool) are warm-up, left out of every column except 'GPU hit rate incl. "
        "warm-up' and 'uploaded / distinct' (whole run: distinct = uploaded - re-fetched). "
        "The pool rounds its budget down to whole slots (one stored brick each, %u^3 "
        "voxels = %llu B): 'pool MiB' is what it got. Host budget %.0f MiB; the host cache "
        "is asked only for bricks the pool lacks, so once the pool holds W its requests are "
        "the churn, bricks it never held either: a host hit rate near 0 there is expected.\n",
        o.frames, o.warmup, f.storedEdge, (unsigned long long)f.slotBytes, o.hostBudgetMb);
    Table t3{"budget",
             {"budget", "asked MiB", "pool MiB (slots)", "volume / pool", "GPU hit rate",
              "GPU hit rate incl. warm-up", "uploads/frame", "MiB uploaded/frame",
              "uploaded / distinct", "host hit rate", "upload ms/frame", "render ms (mean)",
              "latency p50 ms", "latency p99 ms"},
             {}};
    for (const auto& b : runs) {
        const double asked = std::isnan(b.multiple) ? nominal : b.multiple * w;
        t3.rows.push_back({std::isnan(b.multiple) ? fmt("nominal (%.2f W)", nominal / w)
                                                  : fmt("%.2f W", b.multiple),
                           mib(asked), mib(b.s.poolBytes) + " (" + fmt("%.0f", b.s.slots) + ")",
                           fmt("%.1fx", double(f.voxelBytes) / b.s.poolBytes), pct(b.s.gpuHitRate),
                           pct(b.s.gpuHitRateAll), fmt("%.1f", b.s.uploadsPerFrame),
                           mib(b.s.bytesUpPerFrame), fmt("%.2f", b.s.movedOverDistinct),
                           pct(b.s.hostHitRate), fmt("%.2f", b.s.uploadMsPerFrame),
                           fmt("%.2f", b.s.renderMs), fmt("%.1f", b.s.p50), fmt("%.1f", b.s.p99)});
    }
    printTable(t3);
    // The target, over the budgets asked for (the pool may hold a slot less).
    std::string pass, fail, strict;
    for (const auto& b : runs) {
        const double m = std::isnan(b.multiple) ? nominal / w : b.multiple;
        if (m < 1.5) continue;
        const std::string name = (std::isnan(b.multiple) ? "nominal " : "") + fmt("%.2f W", m) +
                                 " (" + pct(b.s.gpuHitRate) + ")";
        (b.s.gpuHitRate >= 0.95 ? pass : fail) += " " + name;
        if (double(f.voxelBytes) >= 4 * b.s.poolBytes) strict += " " + name;
    }
    std::printf("\nTarget: GPU hit rate >= 95%% on the 1 degree/frame orbit when the budget "
                ">= 1.5 W: %s.%s%s\nOf those, budgets with the volume >= 4x the pool (the strict "
                "setting):%s\n",
                pass.empty() && fail.empty() ? "NOT CHECKED (no budget >= 1.5 W)"
                : fail.empty()               ? "HOLDS"
                                             : "FAILS",
                pass.empty() ? "" : (" Met at" + pass + ".").c_str(),
                fail.empty() ? "" : (" Missed at" + fail + ".").c_str(),
                strict.empty() ? " none" : strict.c_str());

    // 4. Clients at 2 W.
    std::vector<std::pair<int, Summary>> clientRuns;
    Table t4{"clients",
             {"clients", "frames/client (1 warm-up)", "frames measured", "frames/s (all)",
              "latency p50 ms", "latency p99 ms", "GPU hit rate", "MiB uploaded/frame",
              "render ms (mean)"},
             {}};
    for (int n : clientCounts) {
        const int frames = n > 16 ? o.manyClientFrames : o.clientFrames;
        const auto r =
            bench.run({"clients", std::to_string(n), std::uint64_t(2 * w), true, n, frames, 1});
        const Summary s = summarize(r, f.slotBytes);
        clientRuns.emplace_back(n, s);
        t4.rows.push_back({std::to_string(n), std::to_string(frames), fmt("%.0f", s.frames),
                           fmt("%.1f", s.fps), fmt("%.1f", s.p50), fmt("%.1f", s.p99),
                           pct(s.gpuHitRate), mib(s.bytesUpPerFrame), fmt("%.2f", s.renderMs)});
        std::fprintf(stderr, "bc_bench_bus: %d clients done (%.0f s so far)\n", n,
                     std::chrono::duration<double>(Clock::now() - runStart).count());
    }
    std::printf(
        "\n## Clients at a 2 W budget\n\nEach client its own orbit, phases 360/N degrees "
        "apart, one frame in flight each; every client's first frame is warm-up (counters "
        "read once all are warm). The pool is shared and the render thread takes sessions "
        "round robin: N orbits sample about N working sets, and a frame finds what the "
        "previous session's frame left (much when the phases are close, as with 64 clients, "
        "little at 90 degrees apart, as with 4).\n");
    printTable(t4);

    // 5. Prefetch on against off.
    if (!o.noPrefetchTable) {
        Table t5{"prefetch",
                 {"budget", "prefetch", "GPU hit rate", "frame hit rate", "uploads/frame (all)",
                  "uploads/frame during frames", "prefetch uploads/frame",
                  "MiB uploaded during frames/frame", "MiB uploaded/frame (all)",
                  "prefetch ms/frame", "latency p50 ms", "latency p99 ms"},
                 {}};
        for (double m : {1.5, 1.0})
            for (bool on : {true, false}) {
                const auto r = bench.run({"prefetch", fmt("%gW ", m) + (on ? "on" : "off"),
                                          std::uint64_t(m * w), on, 1, o.frames, o.warmup});
                const Summary s = summarize(r, f.slotBytes);
                t5.rows.push_back(
                    {fmt("%.2f W", m), on ? "on" : "off", pct(s.gpuHitRate), pct(s.frameHitRate),
                     fmt("%.2f", s.uploadsPerFrame), fmt("%.2f", s.frameUploadsPerFrame),
                     fmt("%.2f", s.prefetchUploadsPerFrame), mib(s.bytesUpDuringFrames),
                     mib(s.bytesUpPerFrame), fmt("%.2f", s.prefetchMsPerFrame), fmt("%.1f", s.p50),
                     fmt("%.1f", s.p99)});
            }
        std::printf(
            "\n## Prefetch on against off\n\nOne client, as in the budget table (fresh runs, "
            "warm-up left out). 'all' is the pool's counter; 'during frames' is what frames "
            "uploaded while they waited (gpu_frame_uploads_total; the MiB column sums the "
            "frame headers' bytesUploaded); 'prefetch' is gpu_prefetch_uploads_total and "
            "prefetch_ms_total (n/a where the server has no such counter). GPU hit rate = hits "
            "/ (hits + all uploads); frame hit rate = hits / (hits + uploads during frames), "
            "so a brick prefetched before it was needed is not a miss.\n");
        printTable(t5);
    }

    // 6. The bus model.
    double upBytes = 0, upMs = 0;
    for (const auto& b : runs)
        upBytes += b.s.bytesUploadedAll, upMs += b.s.uploadMsAll;
    model.upBytesPerMs = ratioOf(upBytes, upMs);
    model.diskBytesPerMs = f.diskBytesPerMs;
    model.renderMs =
        ws.renderMs - ws.uploadMsPerFrame - ws.diskBytesPerFrame / model.diskBytesPerMs;
    std::printf(
        "\n## Bus model\n\npredicted frame ms = R + U / B_up + D / B_disk. R = render ms at full "
        "residency = %.2f ms (the W run's mean render ms less its upload and disk terms). "
        "B_up = %.0f MiB/s (this machine: gpu_pool_bytes_uploaded_total / "
        "gpu_pool_upload_ms_total over the budget runs, %.0f MiB in %.0f ms). B_disk = %.0f "
        "MiB/s (read + decompress of every stored brick, above). D = host_cache_bytes_loaded "
        "a frame, measured. 'measured U' uses each run's uploads; 'model U' predicts them: the "
        "churn (%.2f MiB/frame, from the W run) when the pool holds W, else all of W (LRU on an "
        "orbit evicts bricks in the order it needs them again). Left out: below 1 W a frame "
        "is drawn in several batches (a pass each), a cost per batch that the model lacks.\n",
        model.renderMs, model.upBytesPerMs * 1000 / kMiB, upBytes / kMiB, upMs,
        model.diskBytesPerMs * 1000 / kMiB, model.churn / kMiB);
    Table t6{"model_check",
             {"budget", "measured render ms", "predicted (measured U)", "error",
              "model U MiB/frame", "predicted (model U)", "error"},
             {}};
    for (const auto& b : runs) {
        const double p1 = model.predictMs(b.s.bytesUpPerFrame, b.s.diskBytesPerFrame);
        const double u = model.uploadsFor(b.s.poolBytes, w, model.churn);
        const double p2 = model.predictMs(u, b.s.diskBytesPerFrame);
        t6.rows.push_back({std::isnan(b.multiple) ? "nominal" : fmt("%.2f W", b.multiple),
                           fmt("%.2f", b.s.renderMs), fmt("%.2f", p1),
                           fmt("%+.1f%%", 100 * (p1 - b.s.renderMs) / b.s.renderMs), mib(u),
                           fmt("%.2f", p2),
                           fmt("%+.1f%%", 100 * (p2 - b.s.renderMs) / b.s.renderMs)});
    }
    printTable(t6);

    const double pcie = o.pcieGBs * 1e6, nvme = o.nvmeGBs * 1e6; // bytes per ms
    const double volumeOverBudget = double(f.voxelBytes) / nominal,
                 wOverVolume = w / double(f.voxelBytes);
    const double churnOverW = model.churn / w;
    std::printf("\n## Bus model: planning for larger budgets\n\nAssumptions: host->GPU %.0f GB/s "
                "(PCIe 4), disk %.0f GB/s (NVMe, of decompressed bytes), both at full rate, no "
                "overlap with rendering. The volume keeps this run's volume/budget ratio (%.2fx); "
                "at the same brick size its working set W keeps its share of the volume (%s, a "
                "sparse vessel tree) and the orbit's churn its share of W (%s a frame); rows 'W = "
                "B/1.5' and 'W = 2B' put a denser working set in the same budget. Host RAM is "
                "assumed to hold W, so only bricks new to the view come from disk (churn), and "
                "re-fetches come from RAM. The bus ms is what the bus adds per frame; rendering on "
                "a real GPU is not modelled (R here is llvmpipe's).\n",
                o.pcieGBs, o.nvmeGBs, volumeOverBudget, pct(wOverVolume).c_str(),
                pct(churnOverW).c_str());
    Table t7{"model_plan",
             {"GPU budget GiB", "volume GiB", "working set", "W GiB", "budget / W",
              "upload MiB/frame", "upload ms", "disk ms", "bus ms/frame", "bus-bound frames/s"},
             {}};
    for (double gib : planGib) {
        const double b = gib * 1024 * kMiB, v = b * volumeOverBudget;
        const std::pair<const char*, double> scenarios[] = {
            {"scaled vessels", v * wOverVolume}, {"W = B/1.5", b / 1.5}, {"W = 2B", 2 * b}};
        for (const auto& [name, wb] : scenarios) {
            const double churn = wb * churnOverW, u = model.uploadsFor(b, wb, churn);
            const double upMsF = u / pcie, diskMsF = churn / nvme;
            t7.rows.push_back(
                {fmt("%g", gib), fmt("%.1f", v / (1024 * kMiB)), name,
                 fmt("%.2f", wb / (1024 * kMiB)), fmt("%.2f", b / wb), fmt("%.1f", u / kMiB),
                 fmt("%.2f", upMsF), fmt("%.2f", diskMsF), fmt("%.2f", upMsF + diskMsF),
                 upMsF + diskMsF > 1e-6 ? fmt("%.0f", 1000 / (upMsF + diskMsF)) : "unbounded"});
        }
    }
    printTable(t7);
    std::printf("\nTotal run: %.0f s (%d measured frames a single-client run).\n",
                std::chrono::duration<double>(Clock::now() - runStart).count(), measured);

    if (!o.plot.empty()) plots(o.plot, runs, clientRuns, model);
}

void writeCsv(const Bench& bench) {
    const std::string& path = bench.o.csv;
    std::ofstream out(path);
    out << "table,row,column,value\n";
    for (const auto& t : gTables)
        for (std::size_t r = 0; r < t.rows.size(); ++r)
            for (std::size_t c = 0; c < t.head.size() && c < t.rows[r].size(); ++c)
                out << t.id << ',' << r << ',' << csvCell(t.head[c]) << ',' << csvCell(t.rows[r][c])
                    << '\n';
    if (!out) throw std::runtime_error("--csv: cannot write " + path);
    const auto stem = std::filesystem::path(path);
    const std::string framesPath =
        (stem.parent_path() / (stem.stem().string() + "-frames" + stem.extension().string()))
            .string();
    std::ofstream frames(framesPath);
    frames << "table,run,budget_bytes,prefetch,clients,client,frame,warmup,latency_ms,render_ms,"
              "queue_ms,bytes_uploaded,bricks_drawn,level\n";
    for (const auto& row : bench.frameCsv) {
        for (std::size_t i = 0; i < row.size(); ++i)
            frames << (i ? "," : "") << csvCell(row[i]);
        frames << '\n';
    }
    if (!frames) throw std::runtime_error("--csv: cannot write " + framesPath);
    std::fprintf(stderr, "bc_bench_bus: wrote %s and %s\n", path.c_str(), framesPath.c_str());
}

void validate(const Options& o) {
    auto check = [](bool ok, const std::string& what) {
        if (!ok) throw std::invalid_argument(what);
    };
    check(o.gpuBudgetMb > 0 && o.gpuBudgetMb <= 1 << 20, "--gpu-budget-mb: (0, 1048576]");
    check(o.hostBudgetMb > 0 && o.hostBudgetMb <= 1 << 20, "--host-budget-mb: (0, 1048576]");
    check(o.edge >= 8 && o.edge <= 1024, "--edge: 8..1024 voxels (the catalog's limit)");
    check(o.warmup >= 0 && o.warmup < 1000, "--warmup: 0..999");
    check(o.frames > o.warmup && o.frames <= 100000,
          "--frames: more than --warmup, at most 100000");
    check(o.size >= 8 && o.size <= 4096, "--size: 8..4096");
    check(o.clientFrames >= 2 && o.clientFrames <= 100000,
          "--client-frames: 2..100000 (one is warm-up)");
    check(o.manyClientFrames >= 2 && o.manyClientFrames <= 100000,
          "--many-client-frames: 2..100000");
    check(o.distance > 0.05 && o.distance <= 10, "--distance: (0.05, 10]");
    check(o.fovDeg >= 1 && o.fovDeg <= 120, "--fov: 1..120 degrees");
    check(o.elevationDeg >= -89 && o.elevationDeg <= 89, "--elevation: -89..89 degrees");
    check(o.pcieGBs > 0 && o.nvmeGBs > 0, "--pcie-gbs, --nvme-gbs: positive");
    if (o.level != "auto") {
        const bool digits = !o.level.empty() && o.level.size() <= 2 &&
                            std::all_of(o.level.begin(), o.level.end(),
                                        [](char c) { return c >= '0' && c <= '9'; });
        check(digits && std::stoi(o.level) < 24, "--level: 0..23 or auto");
    }
    numberList(o.budgets, "--budgets");
    numberList(o.planGib, "--plan-budgets-gib");
    numberList(o.clients, "--clients");
    if (!o.plot.empty() &&
        !std::filesystem::is_directory(std::filesystem::absolute(o.plot).parent_path()))
        throw std::invalid_argument("--plot: no folder " +
                                    std::filesystem::absolute(o.plot).parent_path().string());
}

} // namespace

int main(int argc, char** argv) {
    CLI::App app{"Bus/residency benchmark: hit rates, bytes and latency against the GPU "
                 "budget and clients, prefetch, and a bandwidth model"};
    Options o;
    auto* gpu = app.add_option("--gpu-budget-mb", o.gpuBudgetMb,
                               "Nominal GPU budget (the volume should be >= 4x it)")
                    ->capture_default_str();
    app.add_option("--host-budget-mb", o.hostBudgetMb, "Host brick cache budget")
        ->capture_default_str();
    auto* edge = app.add_option("--edge", o.edge, "Generated vessels volume edge, voxels")
                     ->capture_default_str();
    auto* frames =
        app.add_option("--frames", o.frames, "Frames per single-client run (warm-up included)")
            ->capture_default_str();
    auto* warmup = app.add_option("--warmup", o.warmup, "Warm-up frames of each single-client run")
                       ->capture_default_str();
    app.add_option("--size", o.size, "Frame edge, pixels")->capture_default_str();
    auto* clients = app.add_option("--clients", o.clients, "Client counts, comma-separated")
                        ->capture_default_str();
    auto* cf =
        app.add_option("--client-frames", o.clientFrames, "Frames per client for up to 16 clients")
            ->capture_default_str();
    auto* mcf = app.add_option("--many-client-frames", o.manyClientFrames,
                               "Frames per client for more than 16")
                    ->capture_default_str();
    auto* budgets =
        app.add_option("--budgets", o.budgets, "GPU budgets as multiples of W, comma-separated")
            ->capture_default_str();
    app.add_option("--plan-budgets-gib", o.planGib, "Budgets the model plans for, GiB")
        ->capture_default_str();
    app.add_option("--pcie-gbs", o.pcieGBs, "Planned host->GPU rate, GB/s")->capture_default_str();
    app.add_option("--nvme-gbs", o.nvmeGBs, "Planned disk rate, GB/s")->capture_default_str();
    app.add_option("--level", o.level,
                   "Brick level to draw: 0..23, or auto (coarser when level 0 "
                   "exceeds the pool)")
        ->capture_default_str();
    app.add_option("--distance", o.distance, "Orbit distance, times the framing distance")
        ->capture_default_str();
    app.add_option("--fov", o.fovDeg,
                   "Vertical field of view, degrees (30 frames the whole volume at "
                   "distance 1; less zooms in on its centre)")
        ->capture_default_str();
    app.add_option("--elevation", o.elevationDeg, "Orbit elevation, degrees")
        ->capture_default_str();
    app.add_option("--csv", o.csv, "Write every table cell (and FILE-frames: every frame) as CSV");
    app.add_option("--plot", o.plot, "Write PREFIX_{hit_rate,bytes,latency,clients}.png (gnuplot)");
    app.add_flag("--no-prefetch-table", o.noPrefetchTable, "Skip the prefetch on/off runs");
    app.add_option("--store-dir", o.storeDir,
                   "Keep the ingested volume here and reuse it between runs");
    app.add_flag("--quick", o.quick,
                 "Smoke check: a 192^3 volume, 1 MiB budget, few frames (< 1 min)");
    CLI11_PARSE(app, argc, argv);
    if (o.quick) { // what the user did not set
        if (!gpu->count()) o.gpuBudgetMb = 1;
        if (!edge->count()) o.edge = 192;
        if (!frames->count()) o.frames = 16;
        if (!warmup->count()) o.warmup = 2;
        if (!clients->count()) o.clients = "1,4";
        if (!cf->count()) o.clientFrames = 6;
        if (!mcf->count()) o.manyClientFrames = 3;
        if (!budgets->count()) o.budgets = "0.5,1,1.5,2";
    }
    bool ownStore = false;
    try {
        validate(o);
        if (o.storeDir.empty()) {
            o.storeDir = (std::filesystem::temp_directory_path() /
                          ("bc-bus-bench-" + std::to_string(::getpid())))
                             .string();
            ownStore = true;
        }
        Bench bench{o, {}, {}};
        runAll(bench);
        if (!o.csv.empty()) writeCsv(bench);
        if (ownStore) std::filesystem::remove_all(o.storeDir);
        return 0;
    } catch (const std::invalid_argument& e) {
        std::fprintf(stderr, "bc_bench_bus: %s\n", e.what());
        if (ownStore) std::filesystem::remove_all(o.storeDir);
        return 2;
    } catch (const std::exception& e) {
        std::fprintf(stderr, "bc_bench_bus: %s\n", e.what());
        if (ownStore) std::filesystem::remove_all(o.storeDir);
        return 1;
    }
}
