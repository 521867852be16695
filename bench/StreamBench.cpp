// Streaming load benchmark: a brickcastd in this process on loopback, N concurrent
// clients each flying its own orbit (one request per camera, the next camera once the frame
// is decoded), for N in --clients. Prints frames/s and request-to-decoded latency (p50, p99)
// against N; then, one client per codec, render ms against encode ms and bytes a frame.
// Figures are whole frames on whatever renders here (llvmpipe without a GPU): say which.
#include "brickstore/Ingest.h"
#include "client/Client.h"
#include "client/Orbit.h"
#include "server/Daemon.h"
#include "server/Log.h"

#include <CLI/CLI.hpp>

#include <algorithm>
#include <chrono>
#include <cstdio>
#include <filesystem>
#include <mutex>
#include <sstream>
#include <thread>

namespace {

using namespace bc;
using Clock = std::chrono::steady_clock;

struct Options {
    std::string clients = "1,2,4,8,16", renderer = "cpu", volume = "phantom", store;
    int frames = 24, size = 128;
    std::uint64_t edge = 192;
};

struct FrameSample {
    double latencyMs, renderMs, encodeMs, queueMs;
    std::uint64_t bytes;
};

double percentile(std::vector<double> v, double p) {
    if (v.empty()) return 0;
    std::sort(v.begin(), v.end());
    return v[std::min(v.size() - 1, std::size_t(p / 100.0 * double(v.size())))];
}

protocol::RenderOptions optionsOf(const Options& o, protocol::Codec codec) {
    protocol::RenderOptions r;
    r.width = r.height = std::uint16_t(o.size);
    r.codec = codec;
    r.quality = protocol::Quality::Refined;
    r.renderer =
        o.renderer == "gpu" ? protocol::Renderer::GpuRaycaster : protocol::Renderer::CpuRaycaster;
    return r;
}

/// One client's orbit; the samples of its frames (the first, which warms caches, dropped).
std::vector<FrameSample> fly(std::uint16_t port, const Options& o, protocol::Codec codec,
                             int seed) {
    client::ClientConfig cc;
    cc.port = port;
    cc.timeoutMs = 600000;
    client::Client c(cc);
    const auto info = c.openVolume(o.volume);
    c.setRenderOptions(optionsOf(o, codec));
    std::vector<FrameSample> out;
    for (int f = 0; f <= o.frames; ++f) {
        const auto start = Clock::now();
        c.setCamera(
            client::orbitCamera(info, 17.0 * seed + 3.0 * f, 20.0, 1.0, std::uint32_t(f + 1)));
        c.requestFrame();
        const auto frame = c.nextFrame();
        const double ms = std::chrono::duration<double, std::milli>(Clock::now() - start).count();
        if (f > 0)
            out.push_back({ms, frame.header.renderMs, frame.header.encodeMs, frame.header.queueMs,
                           frame.wireBytes});
    }
    c.bye();
    return out;
}

void loadTable(std::uint16_t port, const Options& o) {
    std::printf("\n| clients | frames | frames/s (all clients) | latency p50 ms | latency p99 ms | "
                "queue p50 ms | render p50 ms |\n|---|---|---|---|---|---|---|\n");
    std::stringstream list(o.clients);
    for (std::string item; std::getline(list, item, ',');) {
        const int n = std::stoi(item);
        std::vector<std::vector<FrameSample>> got{std::size_t(n)};
        const auto start = Clock::now();
        std::vector<std::thread> threads;
        for (int i = 0; i < n; ++i)
            threads.emplace_back(
                [&, i] { got[std::size_t(i)] = fly(port, o, protocol::Codec::Zstd, i); });
        for (auto& t : threads)
            t.join();
        const double seconds = std::chrono::duration<double>(Clock::now() - start).count();
        std::vector<double> latency, queue, render;
        for (const auto& g : got)
            for (const auto& s : g)
                latency.push_back(s.latencyMs), queue.push_back(s.queueMs),
                    render.push_back(s.renderMs);
        std::printf("| %d | %zu | %.1f | %.1f | %.1f | %.1f | %.1f |\n", n, latency.size(),
                    double(n * (o.frames + 1)) / seconds, percentile(latency, 50),
                    percentile(latency, 99), percentile(queue, 50), percentile(render, 50));
        std::fflush(stdout);
    }
}

void codecTable(std::uint16_t port, const Options& o) {
    std::printf("\n| codec | render ms (p50) | encode ms (p50) | encode / render | bytes a frame "
                "(median) | latency p50 ms |\n|---|---|---|---|---|---|\n");
    const std::pair<const char*, protocol::Codec> codecs[] = {
        {"raw", protocol::Codec::Raw},
        {"zstd", protocol::Codec::Zstd},
        {"zstd delta", protocol::Codec::ZstdDelta},
        {"JPEG", protocol::Codec::Jpeg}};
    for (const auto& [name, codec] : codecs) {
        const auto s = fly(port, o, codec, 0);
        std::vector<double> render, encode, bytes, latency;
        for (const auto& x : s)
            render.push_back(x.renderMs), encode.push_back(x.encodeMs),
                bytes.push_back(double(x.bytes)), latency.push_back(x.latencyMs);
        std::printf("| %s | %.2f | %.3f | %.3f | %.0f | %.1f |\n", name, percentile(render, 50),
                    percentile(encode, 50),
                    percentile(encode, 50) / std::max(percentile(render, 50), 1e-9),
                    percentile(bytes, 50), percentile(latency, 50));
        std::fflush(stdout);
    }
}

} // namespace

int main(int argc, char** argv) {
    CLI::App app{"Streaming load benchmark: frames/s and latency against clients, codecs"};
    Options o;
    app.add_option("--clients", o.clients, "Client counts, comma-separated")->capture_default_str();
    app.add_option("--frames", o.frames, "Frames per client (after one warm-up)")
        ->capture_default_str();
    app.add_option("--size", o.size, "Frame edge")->capture_default_str();
    app.add_option("--renderer", o.renderer, "cpu or gpu")->capture_default_str();
    app.add_option("--edge", o.edge, "Generated phantom edge (voxels)")->capture_default_str();
    app.add_option("--store", o.store, "Serve this brick store instead of the phantom");
    CLI11_PARSE(app, argc, argv);
    try {
        const auto dir = std::filesystem::temp_directory_path() /
                         ("bc-stream-bench-" + std::to_string(::getpid()));
        server::DaemonConfig config;
        config.source = "<bench>";
        config.listenPort = 0;
        config.maxClients = 1024;
        config.storeDir = dir.string();
        server::CatalogEntry e;
        e.name = o.volume;
        if (o.store.empty()) {
            e.generate = "phantom";
            e.dims = {o.edge, o.edge, o.edge};
        } else {
            e.store = o.store;
        }
        config.volumes.push_back(e);
        server::Log log(true);
        server::Daemon daemon(config, log);
        std::thread serving([&] { daemon.run(); });
        std::printf("Streaming over loopback: %s, %d^2 frames, %s raycaster, %u threads, %d "
                    "frames per client after a warm-up, zstd for the load table\n",
                    o.store.empty() ? ("generated phantom " + std::to_string(o.edge) + "^3").c_str()
                                    : o.store.c_str(),
                    o.size, o.renderer.c_str(), std::thread::hardware_concurrency(), o.frames);
        loadTable(daemon.port(), o);
        codecTable(daemon.port(), o);
        daemon.stop();
        serving.join();
        std::filesystem::remove_all(dir);
        return 0;
    } catch (const std::exception& e) {
        std::fprintf(stderr, "bc_bench_stream: %s\n", e.what());
        return 1;
    }
}
