// brickcast loadtest: N clients against a running brickcastd on loopback (issue 7). Each
// client flies its own camera path (round robin over --paths):
//   orbit     1 degree a frame about the volume (the slow orbit of the bus-model benchmark)
//   zoom      from 2.5 to 0.4 times the framing distance over the run, slowly turning
//   jumps     a random view every frame (seeded per client): the worst case for caches
//   tf-sweep  the orbit under a transfer-function window that slides across the value range,
//             a new function every --tf-every frames (octrees rebuild on the server)
// Clients that share a path start it 1/pi degree of azimuth apart (client i on its path's
// lap i / paths), so that each asks for views of its own: the server's frame cache answers a
// view asked for before without drawing it, which would make a crowd flying in step a test of
// the cache, not of rendering (the report counts the frames it answered all the same).
// Every frame is requested and awaited (one in flight per client), for --frames frames or
// --duration-s seconds, whichever ends first; --timeout-s bounds the whole run. Before and
// after, the server's counters (the Stats message) are read, and the report gives their
// change: host and GPU hit rates, bytes read from disk and uploaded, re-fetches, and bytes
// uploaded over bytes of distinct bricks (uploads that were not re-fetches). Per path and
// overall: frames, frames/s, latency p50/p99, bytes a frame. --csv writes every frame.
#include "client/Client.h"
#include "client/Error.h"
#include "client/Orbit.h"
#include "server/DaemonConfig.h"
#include "tools/Parse.h"
#include "tools/brickcast/Commands.h"

#include <CLI/CLI.hpp>

#include <algorithm>
#include <atomic>
#include <chrono>
#include <cmath>
#include <cstdio>
#include <fstream>
#include <map>
#include <mutex>
#include <random>
#include <thread>

namespace bc::cli {
namespace {

using Clock = std::chrono::steady_clock;

struct LoadtestOptions {
    std::string host = "127.0.0.1", token, volume = "phantom", paths = "orbit,zoom,jumps,tf-sweep",
                size = "128,128", renderer = "auto", codec = "zstd", quality = "refined", csv;
    std::uint16_t port = 7411;
    std::uint32_t clients = 4, frames = 60, tfEvery = 10;
    double durationS = 0, timeoutS = 600, step = 1.0;
};

const std::vector<std::string> kPaths = {"orbit", "zoom", "jumps", "tf-sweep"};

struct FrameRow {
    std::uint32_t client = 0, frame = 0;
    std::string path;
    double latencyMs = 0, renderMs = 0, queueMs = 0;
    std::uint64_t bytes = 0, bytesUploaded = 0, bricksDrawn = 0;
    bool cached = false; ///< answered from the server's frame cache
};

protocol::Renderer rendererOf(const std::string& name) {
    if (name == "auto") return protocol::Renderer::Auto;
    if (name == "gpu") return protocol::Renderer::GpuRaycaster;
    if (name == "cpu") return protocol::Renderer::CpuRaycaster;
    if (name == "splat") return protocol::Renderer::Splatter;
    if (name == "splat-gpu") return protocol::Renderer::GpuSplatter;
    throw std::invalid_argument("--renderer: '" + name +
                                "' is not auto, gpu, cpu, splat or splat-gpu");
}

protocol::Codec codecOf(const std::string& name) {
    if (name == "raw") return protocol::Codec::Raw;
    if (name == "zstd") return protocol::Codec::Zstd;
    if (name == "delta") return protocol::Codec::ZstdDelta;
    if (name == "jpeg") return protocol::Codec::Jpeg;
    if (name == "png") return protocol::Codec::Png;
    throw std::invalid_argument("--codec: '" + name + "' is not raw, zstd, delta, jpeg or png");
}

protocol::Quality qualityOf(const std::string& name) {
    if (name == "refined") return protocol::Quality::Refined;
    if (name == "interactive") return protocol::Quality::Interactive;
    throw std::invalid_argument("--quality: '" + name + "' is not refined or interactive");
}

/// A window ramp over fractions [lo, lo + 0.25] of the value range.
protocol::SetTransferFunction windowTf(double lo) {
    protocol::SetTransferFunction tf;
    tf.kind = protocol::TfKind::Points;
    tf.shadingSource = protocol::ShadingSource::Message;
    tf.shading = true;
    auto point = [](double f, float a) {
        return protocol::TfPoint{
            protocol::Placement::Fraction, std::clamp(f, 0.0, 1.0), {1.0f, 0.85f, 0.7f, a}};
    };
    tf.points = {point(lo, 0.0f), point(lo + 0.05, 0.04f), point(lo + 0.25, 0.3f),
                 point(std::min(lo + 0.3, 1.0), 0.0f)};
    return tf;
}

/// The camera of `path` at frame f of n, for the client on lap `lap` of the paths.
protocol::SetCamera cameraOf(const std::string& path, const protocol::VolumeInfo& v,
                             std::uint32_t f, std::uint32_t n, std::uint32_t lap,
                             std::mt19937& rng) {
    const std::uint32_t id = f + 1;
    // Views of its own (see the top of the file): laps start 1/pi degree apart, which no whole
    // number of any path's steps (1 and 0.2 degrees) makes up.
    const double start = 30.0 + lap / 3.141592653589793;
    if (path == "zoom") {
        const double t = n > 1 ? double(f) / double(n - 1) : 0.0;
        return client::orbitCamera(v, start + 0.2 * f, 20.0, 2.5 * std::pow(0.4 / 2.5, t), id);
    }
    if (path == "jumps") {
        std::uniform_real_distribution<double> az(0, 360), el(-70, 70), dist(0.7, 1.4);
        const double a = az(rng), e = el(rng), d = dist(rng);
        return client::orbitCamera(v, a, e, d, id);
    }
    return client::orbitCamera(v, start + 1.0 * f, 20.0, 1.0, id); // orbit, tf-sweep
}

double quantile(std::vector<double> v, double q) {
    if (v.empty()) return std::nan("");
    std::sort(v.begin(), v.end());
    return v[std::min(v.size() - 1, std::size_t(q * double(v.size())))];
}

/// Counter `name` for `volume` (labelled volume="..."); with volume empty, the sum of every
/// sample of `name` whatever its labels.
double counterOf(const std::vector<std::pair<std::string, double>>& stats, const std::string& name,
                 const std::string& volume) {
    double sum = 0;
    const std::string labelled = name + "{volume=\"" + volume + "\"}";
    for (const auto& [k, v] : stats)
        if (volume.empty() ? (k == name || k.starts_with(name + "{")) : k == labelled) sum += v;
    return sum;
}

std::string percent(double part, double whole) {
    if (!(whole > 0)) return "n/a";
    char b[32];
    std::snprintf(b, sizeof b, "%.1f%%", 100.0 * part / whole);
    return b;
}

std::string ratio(double a, double b) {
    if (!(b > 0)) return "n/a";
    char t[32];
    std::snprintf(t, sizeof t, "%.2f", a / b);
    return t;
}

struct ServerDelta {
    std::vector<std::pair<std::string, double>> before, after;
    double of(const std::string& name, const std::string& volume) const {
        return counterOf(after, name, volume) - counterOf(before, name, volume);
    }
};

void printReport(const LoadtestOptions& o, const std::vector<FrameRow>& rows, double wallS,
                 const ServerDelta& d, std::uint32_t failures) {
    std::printf("\n## brickcast loadtest: %u clients on %s (%s, %s), %.1f s\n\n", o.clients,
                o.volume.c_str(), o.renderer.c_str(), o.size.c_str(), wallS);
    std::printf(
        "| Path | Clients | Frames | Frames/s (all its clients) | Latency p50 ms | p99 ms | "
        "Render p50 ms | Bytes/frame | From the frame cache "
        "|\n|---|---|---|---|---|---|---|---|---|"
        "\n");
    auto line = [&](const std::string& path) {
        std::vector<double> latency, render;
        std::map<std::uint32_t, bool> clients;
        double bytes = 0;
        std::size_t cached = 0;
        for (const auto& r : rows)
            if (path == "all" || r.path == path) {
                latency.push_back(r.latencyMs);
                render.push_back(r.renderMs);
                bytes += double(r.bytes);
                cached += r.cached;
                clients[r.client] = true;
            }
        if (latency.empty()) return;
        std::printf("| %s | %zu | %zu | %.1f | %.1f | %.1f | %.1f | %.0f | %zu |\n", path.c_str(),
                    clients.size(), latency.size(), double(latency.size()) / wallS,
                    quantile(latency, 0.5), quantile(latency, 0.99), quantile(render, 0.5),
                    bytes / double(latency.size()), cached);
    };
    for (const auto& p : kPaths)
        line(p);
    line("all");
    const std::string& v = o.volume;
    const double hHits = d.of("host_cache_hits_total", v),
                 hMiss = d.of("host_cache_misses_total", v);
    const double gHits = d.of("gpu_pool_hits_total", v), gUp = d.of("gpu_pool_uploads_total", v);
    const double upBytes = d.of("gpu_pool_bytes_uploaded_total", v);
    const double upRefetched = d.of("gpu_pool_bytes_refetched_total", v);
    const double loaded = d.of("host_cache_bytes_loaded_total", v);
    const double reloaded = d.of("host_cache_bytes_refetched_total", v);
    std::printf("\n| Tier | Hits | Misses | Hit rate | Bytes moved | Of them re-fetched | "
                "Moved / distinct |\n|---|---|---|---|---|---|---|\n");
    std::printf("| disk -> host | %.0f | %.0f | %s | %s | %s | %s |\n", hHits, hMiss,
                percent(hHits, hHits + hMiss).c_str(), tools::formatBytes(loaded).c_str(),
                tools::formatBytes(reloaded).c_str(), ratio(loaded, loaded - reloaded).c_str());
    std::printf("| host -> GPU | %.0f | %.0f | %s | %s | %s | %s |\n", gHits, gUp,
                percent(gHits, gHits + gUp).c_str(), tools::formatBytes(upBytes).c_str(),
                tools::formatBytes(upRefetched).c_str(),
                ratio(upBytes, upBytes - upRefetched).c_str());
    std::printf("\nServer: %.0f frames, %.0f from the frame cache, %.0f render errors, %.0f ms "
                "rendering, %s sent; %u client failures.\n",
                d.of("frames_total", ""), d.of("frame_cache_hits_total", ""),
                d.of("render_errors_total", ""), d.of("render_ms_total", ""),
                tools::formatBytes(d.of("frame_bytes_total", "")).c_str(), failures);
}

void runLoadtest(const LoadtestOptions& o) {
    if (!server::isLoopback(o.host))
        throw std::invalid_argument("--host: '" + o.host +
                                    "' is not loopback: loadtest drives local servers only");
    if (o.clients < 1 || o.clients > 1024) throw std::invalid_argument("--clients: 1..1024");
    if (o.frames < 1 || o.frames > 1000000) throw std::invalid_argument("--frames: 1..1000000");
    if (!(o.durationS >= 0 && o.durationS <= 86400))
        throw std::invalid_argument("--duration-s: 0..86400 (0: --frames alone)");
    if (!(o.timeoutS > 0 && o.timeoutS <= 86400))
        throw std::invalid_argument("--timeout-s: (0, 86400]");
    if (o.tfEvery < 1) throw std::invalid_argument("--tf-every: at least 1");
    const auto paths = tools::splitList(o.paths);
    if (paths.empty()) throw std::invalid_argument("--paths: none given");
    for (const auto& p : paths)
        if (std::find(kPaths.begin(), kPaths.end(), p) == kPaths.end())
            throw std::invalid_argument("--paths: '" + p +
                                        "' is not orbit, zoom, jumps or tf-sweep");
    const auto size = tools::parseNumbers(o.size, "--size", 2, 2);
    if (size[0] < 1 || size[1] < 1 || size[0] > 4096 || size[1] > 4096 ||
        size[0] != std::floor(size[0]) || size[1] != std::floor(size[1]))
        throw std::invalid_argument("--size: W,H whole numbers 1..4096");
    protocol::RenderOptions ro;
    ro.width = std::uint16_t(size[0]);
    ro.height = std::uint16_t(size[1]);
    ro.renderer = rendererOf(o.renderer);
    ro.codec = codecOf(o.codec);
    ro.stepVoxels = float(o.step);
    ro.quality = qualityOf(o.quality);

    client::ClientConfig cc;
    cc.host = o.host;
    cc.port = o.port;
    cc.token = o.token;
    cc.timeoutMs = std::uint32_t(std::min(o.timeoutS, 3600.0) * 1000);
    client::Client control(cc); // counters before and after, outside the measured clients
    ServerDelta delta;
    delta.before = control.stats();

    const auto start = Clock::now();
    const auto deadline = start + std::chrono::duration_cast<Clock::duration>(
                                      std::chrono::duration<double>(o.timeoutS));
    const auto endBy = o.durationS > 0 ? start + std::chrono::duration_cast<Clock::duration>(
                                                     std::chrono::duration<double>(o.durationS))
                                       : deadline;
    std::mutex mutex;
    std::vector<FrameRow> rows;
    std::vector<std::string> errors;
    std::vector<std::thread> threads;
    for (std::uint32_t i = 0; i < o.clients; ++i)
        threads.emplace_back([&, i] {
            const std::string path = paths[i % paths.size()];
            std::vector<FrameRow> mine;
            try {
                client::Client c(cc);
                const auto v = c.openVolume(o.volume);
                c.setRenderOptions(ro);
                std::mt19937 rng(20261201u + i);
                for (std::uint32_t f = 0; f < o.frames; ++f) {
                    const auto now = Clock::now();
                    if (now >= endBy || now >= deadline) break;
                    if (path == "tf-sweep" && f % o.tfEvery == 0)
                        c.setTransferFunction(
                            windowTf(0.1 + 0.6 * std::fmod(double(f / o.tfEvery) * 0.15, 1.0)));
                    c.setCamera(
                        cameraOf(path, v, f, o.frames, std::uint32_t(i / paths.size()), rng));
                    const auto sent = Clock::now();
                    c.requestFrame();
                    const auto frame = c.nextFrame();
                    FrameRow r;
                    r.client = i;
                    r.frame = f;
                    r.path = path;
                    r.latencyMs =
                        std::chrono::duration<double, std::milli>(Clock::now() - sent).count();
                    r.renderMs = frame.header.renderMs;
                    r.queueMs = frame.header.queueMs;
                    r.bytes = frame.wireBytes;
                    r.bytesUploaded = frame.header.bytesUploaded;
                    r.bricksDrawn = frame.header.bricksDrawn;
                    r.cached = frame.header.cached;
                    mine.push_back(r);
                }
                c.bye();
            } catch (const std::exception& e) {
                std::lock_guard lock(mutex);
                errors.push_back("client " + std::to_string(i) + " (" + path + "): " + e.what());
            }
            std::lock_guard lock(mutex);
            rows.insert(rows.end(), mine.begin(), mine.end());
        });
    for (auto& t : threads)
        t.join();
    const double wallS = std::chrono::duration<double>(Clock::now() - start).count();
    delta.after = control.stats();
    control.bye();
    for (const auto& e : errors)
        std::fprintf(stderr, "loadtest: %s\n", e.c_str());
    std::sort(rows.begin(), rows.end(), [](const FrameRow& a, const FrameRow& b) {
        return a.client != b.client ? a.client < b.client : a.frame < b.frame;
    });
    printReport(o, rows, wallS, delta, std::uint32_t(errors.size()));
    if (!o.csv.empty()) {
        std::ofstream out(o.csv);
        out << "client,path,frame,latency_ms,render_ms,queue_ms,bytes,bytes_uploaded,bricks_"
               "drawn,cached\n";
        for (const auto& r : rows)
            out << r.client << ',' << r.path << ',' << r.frame << ',' << r.latencyMs << ','
                << r.renderMs << ',' << r.queueMs << ',' << r.bytes << ',' << r.bytesUploaded << ','
                << r.bricksDrawn << ',' << int(r.cached) << '\n';
        if (!out) throw std::runtime_error(o.csv + ": cannot write the CSV");
    }
    if (!errors.empty())
        throw std::runtime_error(std::to_string(errors.size()) + " of " +
                                 std::to_string(o.clients) + " clients failed (above)");
}

} // namespace

void addLoadtestCommand(CLI::App& app) {
    auto o = std::make_shared<LoadtestOptions>();
    auto* cmd = app.add_subcommand(
        "loadtest", "Drive a running brickcastd (loopback) with N clients on camera paths and "
                    "report latency, throughput and the cache tiers' traffic");
    cmd->add_option("--host", o->host, "Server address (loopback only)")->capture_default_str();
    cmd->add_option("--port", o->port, "Server port")->capture_default_str();
    cmd->add_option("--token", o->token, "Token, when the server wants one");
    cmd->add_option("--volume", o->volume, "Catalog name to open")->capture_default_str();
    cmd->add_option("--clients", o->clients, "Concurrent clients")->capture_default_str();
    cmd->add_option("--paths", o->paths,
                    "Camera paths, one per client in turn: orbit, zoom, "
                    "jumps, tf-sweep")
        ->capture_default_str();
    cmd->add_option("--frames", o->frames, "Frames per client")->capture_default_str();
    cmd->add_option("--duration-s", o->durationS, "Stop after this long (0: --frames decides)")
        ->capture_default_str();
    cmd->add_option("--timeout-s", o->timeoutS, "Hard bound on the whole run")
        ->capture_default_str();
    cmd->add_option("--tf-every", o->tfEvery, "tf-sweep: frames between transfer functions")
        ->capture_default_str();
    cmd->add_option("--size", o->size, "Frame W,H")->capture_default_str();
    cmd->add_option("--renderer", o->renderer,
                    "auto (the server's choice: gpu on a hardware GPU, else cpu), gpu, cpu, splat "
                    "or splat-gpu")
        ->capture_default_str();
    cmd->add_option("--codec", o->codec, "raw, zstd, delta or jpeg")->capture_default_str();
    cmd->add_option("--step", o->step, "Sample step, voxels")->capture_default_str();
    cmd->add_option("--quality", o->quality,
                    "refined (every frame at full quality) or interactive (every frame as a "
                    "moving camera's: half size, or the server's frame-time budget)")
        ->capture_default_str();
    cmd->add_option("--csv", o->csv, "Write every frame as CSV");
    cmd->callback([o] { runLoadtest(*o); });
}

} // namespace bc::cli
