// brickcast loadtest: N clients against a running brickcastd on loopback. Each
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
//
// Frames on a budget: --quality adaptive flies in continuous mode, each camera's
// frame awaited before the next camera is sent, as a viewer's drag; --interactive-ms sets the
// session's frame-time target (SetFrameBudget). With --rest-psnr DB each client, after its
// flight, rests: the time from its last camera to the refined pass whose estimated PSNR
// reaches DB is measured, and that frame is compared with the true image, which the same
// server draws at that camera with the CPU raycaster at --truth-step voxels, without jitter or
// early termination, once every client has rested (it would take turns with their passes).
// The first --warmup frames of each client are left out of the report.
#include "client/Client.h"
#include "client/Error.h"
#include "client/Orbit.h"
#include "render/RefinementEstimate.h"
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
#include <latch>
#include <map>
#include <mutex>
#include <random>
#include <thread>

namespace bc::cli {
namespace {

using Clock = std::chrono::steady_clock;

struct LoadtestOptions {
    std::string host = "127.0.0.1", token, volume = "phantom", paths = "orbit,zoom,jumps,tf-sweep",
                size = "128,128", renderer = "auto", codec = "zstd", quality = "refined", csv,
                mode = "composite";
    std::uint16_t port = 7411;
    std::uint32_t clients = 4, frames = 60, tfEvery = 10, warmup = 0;
    std::uint32_t interactiveMs = 0, restPsnrDb = 0;
    double durationS = 0, timeoutS = 600, step = 1.0, truthStep = 1.0 / 32.0;
};

/// A client's rest after its flight (--rest-psnr).
struct RestRow {
    std::uint32_t client = 0;
    double movingFps = 0, intervalP50 = 0, intervalP99 = 0; ///< its flight, warm-up left out
    bool reached = false;                                   ///< a pass's estimate reached the bound
    double restMs = 0;                                      ///< from its last camera to that pass
    std::uint32_t passes = 0;
    std::string passMs; ///< each pass's render ms, "a+b+..."
    double estimatedDb = 0, measuredDb = 0;
};

const std::vector<std::string> kPaths = {"orbit", "zoom", "jumps", "tf-sweep"};

struct FrameRow {
    std::uint32_t client = 0, frame = 0;
    std::string path;
    double latencyMs = 0, renderMs = 0, queueMs = 0;
    std::uint64_t bytes = 0, bytesUploaded = 0, bricksDrawn = 0;
    bool cached = false; ///< answered from the server's frame cache
    bool refined = false;
    std::uint32_t level = 0, scale = 0; ///< drawn at; scale 0 from servers before 2026-12-06
};

protocol::Renderer rendererOf(const std::string& name) {
    const auto renderer = protocol::rendererNamed(name);
    if (renderer && *renderer != protocol::Renderer::Reference) return *renderer;
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
    if (name == "adaptive") return protocol::Quality::Adaptive;
    throw std::invalid_argument("--quality: '" + name +
                                "' is not refined, interactive or adaptive");
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
    std::printf("\n## brickcast loadtest: %u clients on %s (%s, %s, %s), %.1f s\n\n", o.clients,
                o.volume.c_str(), o.renderer.c_str(), o.mode.c_str(), o.size.c_str(), wallS);
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

/// Each client's one turn at a latch, whatever happens to it: arrive() waits for the others;
/// a client that never gets there (it failed, or does not rest) counts down as it ends.
class LatchTurn {
  public:
    explicit LatchTurn(std::latch& latch) : mLatch(latch) {}
    ~LatchTurn() {
        if (!mDone) mLatch.count_down();
    }
    LatchTurn(const LatchTurn&) = delete;
    LatchTurn& operator=(const LatchTurn&) = delete;
    void arrive() {
        if (mDone) return;
        mDone = true;
        mLatch.arrive_and_wait();
    }

  private:
    std::latch& mLatch;
    bool mDone = false;
};

/// After a client's flight: waits, with the camera at rest, for the refinement pass whose estimate
/// reaches --rest-psnr (or the last pass the server draws), then has the server draw the true
/// image at that camera and measures the pass against it.
RestRow restAndCompare(const LoadtestOptions& o, const protocol::RenderOptions& ro,
                       client::Client& c, std::uint32_t index, std::uint32_t camera,
                       Clock::time_point lastSent, LatchTurn& rested) {
    RestRow rest;
    rest.client = index;
    // The passes the server draws: the session's step, halved while not finer than 1/16.
    std::uint32_t most = 1;
    while (render::refineFurther(-1, o.restPsnrDb, render::refinementStep(ro.stepVoxels, most - 1)))
        ++most;
    client::ReceivedFrame pass;
    while (rest.passes < most) {
        client::ReceivedFrame f = c.nextFrame();
        if (!f.header.refined || f.header.cameraId != camera) continue;
        pass = std::move(f);
        ++rest.passes;
        rest.passMs += (rest.passMs.empty() ? "" : "+") +
                       std::to_string(int(std::lround(pass.header.renderMs)));
        rest.restMs = std::chrono::duration<double, std::milli>(Clock::now() - lastSent).count();
        rest.estimatedDb = pass.header.estimatedPsnrDb;
        if (pass.header.estimatedPsnrDb >= o.restPsnrDb) {
            rest.reached = true;
            break;
        }
    }
    c.requestFrame(protocol::FrameMode::ContinuousOff);
    // The true images (long frames) only once every client has rested: they would take turns
    // with the others' frames at rest.
    rested.arrive();
    protocol::RenderOptions truth = ro;
    truth.quality = protocol::Quality::Refined;
    truth.renderer = protocol::Renderer::CpuRaycaster;
    truth.stepVoxels = float(o.truthStep);
    truth.techniques =
        protocol::kTechAll & ~(protocol::kTechJitter | protocol::kTechEarlyTermination);
    truth.codec = protocol::Codec::Zstd;
    truth.codecQuality = 0;
    truth.refinedCodec.reset();
    c.setRenderOptions(truth);
    const std::uint32_t id = c.requestFrame();
    client::ReceivedFrame t;
    do
        t = c.nextFrame();
    while (t.request != id);
    rest.measuredDb = render::psnrRgb8(pass.rgba, t.rgba);
    return rest;
}

void printRests(const LoadtestOptions& o, const std::vector<RestRow>& rests) {
    std::printf("\n### Moving, then at rest under a %u dB bound (true image: the CPU raycaster at "
                "%.4g voxel, no jitter or early termination; %u warm-up frames left out)\n\n",
                unsigned(o.restPsnrDb), o.truthStep, o.warmup);
    std::printf(
        "| Client | Moving frames/s | Interval p50 ms | p99 ms | Passes at rest (render ms) | "
        "Bound "
        "reached after ms | Estimated dB | Measured dB |\n|---|---|---|---|---|---|---|---|\n");
    for (const RestRow& r : rests)
        std::printf("| %u | %.1f | %.1f | %.1f | %u (%s) | %s | %.0f | %.1f |\n", r.client,
                    r.movingFps, r.intervalP50, r.intervalP99, r.passes, r.passMs.c_str(),
                    r.reached ? std::to_string(int(std::lround(r.restMs))).c_str() : "not reached",
                    r.estimatedDb, r.measuredDb);
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
    if (o.warmup >= o.frames) throw std::invalid_argument("--warmup: fewer than --frames");
    if (o.interactiveMs > protocol::kMaxInteractiveMs)
        throw std::invalid_argument("--interactive-ms: 0..10000 (0: the server's)");
    if (o.restPsnrDb != 0 &&
        (o.restPsnrDb < protocol::kMinRestPsnrDb || o.restPsnrDb > protocol::kMaxRestPsnrDb))
        throw std::invalid_argument("--rest-psnr: 0 (none) or 20..50 dB");
    if (o.restPsnrDb != 0 && o.quality != "adaptive")
        throw std::invalid_argument("--rest-psnr: needs --quality adaptive (a camera that rests)");
    if (!(o.truthStep >= 0.01 && o.truthStep <= 1))
        throw std::invalid_argument("--truth-step: 0.01..1 voxels");
    if (!protocol::blendModeNamed(o.mode))
        throw std::invalid_argument("--mode: '" + o.mode +
                                    "' is not one of composite, mip, minip, average, iso");
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
    std::vector<RestRow> rests;
    std::vector<std::string> errors;
    std::vector<std::thread> threads;
    std::latch rested(o.clients);
    for (std::uint32_t i = 0; i < o.clients; ++i)
        threads.emplace_back([&, i] {
            const std::string path = paths[i % paths.size()];
            std::vector<FrameRow> mine;
            LatchTurn turn(rested);
            try {
                client::Client c(cc);
                const auto v = c.openVolume(o.volume);
                c.setRenderOptions(ro);
                if (const auto mode = *protocol::blendModeNamed(o.mode);
                    mode != protocol::BlendMode::Composite) { // an iso surface at the middle value
                    protocol::SetModeAndClip m;
                    m.mode = mode;
                    m.isoValue = 0.5 * (v.valueMin + v.valueMax);
                    c.setModeAndClip(m);
                }
                if (o.interactiveMs > 0 || o.restPsnrDb > 0)
                    c.setFrameBudget({std::uint16_t(o.interactiveMs), std::uint8_t(o.restPsnrDb)});
                const bool adaptive = ro.quality == protocol::Quality::Adaptive;
                if (adaptive) c.requestFrame(protocol::FrameMode::ContinuousOn);
                std::mt19937 rng(20261201u + i);
                std::uint32_t lastCamera = 0;
                Clock::time_point lastSent{}, lastArrival{}, flightStart{};
                std::vector<double> intervals;
                for (std::uint32_t f = 0; f < o.frames; ++f) {
                    const auto now = Clock::now();
                    if (now >= endBy || now >= deadline) break;
                    if (path == "tf-sweep" && f % o.tfEvery == 0)
                        c.setTransferFunction(
                            windowTf(0.1 + 0.6 * std::fmod(double(f / o.tfEvery) * 0.15, 1.0)));
                    const auto camera =
                        cameraOf(path, v, f, o.frames, std::uint32_t(i / paths.size()), rng);
                    c.setCamera(camera);
                    lastCamera = camera.cameraId;
                    const auto sent = lastSent = Clock::now();
                    client::ReceivedFrame frame;
                    if (adaptive) { // continuous: the frame answering this camera
                        do
                            frame = c.nextFrame();
                        while (frame.header.cameraId != camera.cameraId);
                    } else {
                        c.requestFrame();
                        frame = c.nextFrame();
                    }
                    const auto arrival = Clock::now();
                    if (f == o.warmup) flightStart = sent;
                    if (f > o.warmup)
                        intervals.push_back(
                            std::chrono::duration<double, std::milli>(arrival - lastArrival)
                                .count());
                    lastArrival = arrival;
                    if (f < o.warmup) continue;
                    FrameRow r;
                    r.client = i;
                    r.frame = f;
                    r.path = path;
                    r.latencyMs = std::chrono::duration<double, std::milli>(arrival - sent).count();
                    r.renderMs = frame.header.renderMs;
                    r.queueMs = frame.header.queueMs;
                    r.bytes = frame.wireBytes;
                    r.bytesUploaded = frame.header.bytesUploaded;
                    r.bricksDrawn = frame.header.bricksDrawn;
                    r.cached = frame.header.cached;
                    r.refined = frame.header.refined;
                    r.level = frame.header.level;
                    r.scale = frame.header.scale;
                    mine.push_back(r);
                }
                if (adaptive && o.restPsnrDb > 0 && lastCamera > 0) {
                    RestRow rest = restAndCompare(o, ro, c, i, lastCamera, lastSent, turn);
                    const double flightS =
                        std::chrono::duration<double>(lastArrival - flightStart).count();
                    rest.movingFps = flightS > 0 ? double(intervals.size()) / flightS : 0.0;
                    rest.intervalP50 = quantile(intervals, 0.5);
                    rest.intervalP99 = quantile(intervals, 0.99);
                    std::lock_guard lock(mutex);
                    rests.push_back(rest);
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
    if (!rests.empty()) printRests(o, rests);
    if (!o.csv.empty()) {
        std::ofstream out(o.csv);
        out << "client,path,frame,latency_ms,render_ms,queue_ms,bytes,bytes_uploaded,bricks_"
               "drawn,cached,refined,level,scale\n";
        for (const auto& r : rows)
            out << r.client << ',' << r.path << ',' << r.frame << ',' << r.latencyMs << ','
                << r.renderMs << ',' << r.queueMs << ',' << r.bytes << ',' << r.bytesUploaded << ','
                << r.bricksDrawn << ',' << int(r.cached) << ',' << int(r.refined) << ',' << r.level
                << ',' << r.scale << '\n';
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
                    "refined (every frame at full quality), interactive (every frame as a "
                    "moving camera's: half size, or the server's frame-time budget) or adaptive "
                    "(continuous mode: interactive frames while moving, refined at rest)")
        ->capture_default_str();
    cmd->add_option("--mode", o->mode,
                    "What a ray makes of its samples: composite, mip, minip, average, iso (the "
                    "surface at the middle of the volume's values)")
        ->capture_default_str();
    cmd->add_option("--csv", o->csv, "Write every frame as CSV");
    cmd->add_option("--warmup", o->warmup, "Frames of each client left out of the report")
        ->capture_default_str();
    cmd->add_option("--interactive-ms", o->interactiveMs,
                    "The session's frame-time target for interactive frames (SetFrameBudget; 0: "
                    "the server's frames.interactive_ms)")
        ->capture_default_str();
    cmd->add_option("--rest-psnr", o->restPsnrDb,
                    "With --quality adaptive: after its flight each client rests until a refined "
                    "pass's estimated PSNR reaches this (20..50 dB), and that pass is measured "
                    "against the true image")
        ->capture_default_str();
    cmd->add_option("--truth-step", o->truthStep,
                    "--rest-psnr: the true image's step (voxels), CPU raycaster, no jitter or "
                    "early termination")
        ->capture_default_str();
    cmd->callback([o] { runLoadtest(*o); });
}

} // namespace bc::cli
