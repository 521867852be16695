// Time to the first frame after a transfer-function change, with N sessions on one volume
// (one shared classification): a brickcastd in this process on loopback serves a store (or a
// generated phantom); N clients each open it and draw one warm frame; then, round after round,
// every client sets the same new transfer function (a threshold that moves each round, so every
// round is a function no one has seen) and asks for a frame. Prints, per round, the time from
// the change to the first and to the last session's frame, and medians over the rounds.
#include "client/Client.h"
#include "client/Orbit.h"
#include "server/Daemon.h"
#include "server/Log.h"

#include <CLI/CLI.hpp>

#include <algorithm>
#include <chrono>
#include <cstdio>
#include <filesystem>
#include <thread>

namespace {

using namespace bc;
using Clock = std::chrono::steady_clock;

struct Options {
    std::string store, renderer = "cpu";
    int sessions = 8, rounds = 6, size = 256;
    std::uint64_t edge = 192;
};

double msBetween(Clock::time_point a, Clock::time_point b) {
    return std::chrono::duration<double, std::milli>(b - a).count();
}

double median(std::vector<double> v) {
    std::sort(v.begin(), v.end());
    return v.empty() ? 0.0 : v[v.size() / 2];
}

/// Round r's function: transparent below a percentile threshold that moves with r, bone-white
/// above it.
protocol::SetTransferFunction roundTf(int r) {
    protocol::SetTransferFunction tf;
    tf.kind = protocol::TfKind::Points;
    tf.shadingSource = protocol::ShadingSource::Message;
    const double at = 60.0 + 3.0 * r;
    tf.points = {{protocol::Placement::Percentile, at, {1, 1, 1, 0}},
                 {protocol::Placement::Percentile, at + 5.0, {1, 0.95f, 0.9f, 0.6f}}};
    return tf;
}

server::DaemonConfig configOf(const Options& o, const std::string& scratch) {
    server::DaemonConfig c;
    c.source = "<bench>";
    c.storeDir = scratch;
    c.maxClients = std::uint32_t(o.sessions + 1);
    server::CatalogEntry e;
    e.name = "v";
    if (o.store.empty()) {
        e.generate = "phantom";
        e.dims = {o.edge, o.edge, o.edge};
    } else {
        e.store = std::filesystem::absolute(o.store).string();
    }
    c.volumes.push_back(e);
    return c;
}

} // namespace

int main(int argc, char** argv) {
    Options o;
    CLI::App app{"Time to the first frame after a transfer-function change, N sessions"};
    app.add_option("--store", o.store, "a .bcs store (default: a generated phantom)");
    app.add_option("--edge", o.edge, "edge of the generated phantom")->check(CLI::Range(16, 512));
    app.add_option("--sessions", o.sessions, "sessions on the volume")->check(CLI::Range(1, 64));
    app.add_option("--rounds", o.rounds, "transfer-function changes")->check(CLI::Range(1, 100));
    app.add_option("--size", o.size, "frame edge in pixels")->check(CLI::Range(16, 2048));
    app.add_option("--renderer", o.renderer, "cpu or gpu")->check(CLI::IsMember({"cpu", "gpu"}));
    CLI11_PARSE(app, argc, argv);

    const auto scratch = std::filesystem::temp_directory_path() / "bc-bench-tfchange";
    std::filesystem::create_directories(scratch);
    server::Log log(true);
    server::DaemonConfig config = configOf(o, scratch.string());
    config.listenPort = 0;
    server::Daemon daemon(config, log);
    std::thread serving([&] { daemon.run(); });

    protocol::RenderOptions ro;
    ro.width = ro.height = std::uint16_t(o.size);
    ro.quality = protocol::Quality::Refined;
    ro.renderer =
        o.renderer == "gpu" ? protocol::Renderer::GpuRaycaster : protocol::Renderer::CpuRaycaster;
    std::vector<std::unique_ptr<client::Client>> clients;
    protocol::VolumeInfo info;
    for (int i = 0; i < o.sessions; ++i) {
        client::ClientConfig cc;
        cc.port = daemon.port();
        cc.timeoutMs = 600000;
        clients.push_back(std::make_unique<client::Client>(cc));
        info = clients.back()->openVolume("v");
        clients.back()->setRenderOptions(ro);
        clients.back()->setTransferFunction(roundTf(-10));
        clients.back()->setCamera(client::orbitCamera(info, 30.0 + i, 20.0, 1.0, 1));
        clients.back()->requestFrame();
        clients.back()->nextFrame(); // warm: bricks cached, the first function built
    }
    std::printf("# Time to the first frame after a TF change: %d sessions, %s renderer, %dx%d, "
                "volume %s\n\n| round | first frame ms | last frame ms |\n|---|---|---|\n",
                o.sessions, o.renderer.c_str(), o.size, o.size,
                o.store.empty() ? ("phantom " + std::to_string(o.edge) + "^3").c_str()
                                : o.store.c_str());
    std::vector<double> firsts, lasts;
    for (int r = 0; r < o.rounds; ++r) {
        std::vector<double> ms(std::size_t(o.sessions));
        const auto start = Clock::now();
        std::vector<std::thread> threads;
        for (int i = 0; i < o.sessions; ++i)
            threads.emplace_back([&, i] {
                client::Client& c = *clients[std::size_t(i)];
                c.setTransferFunction(roundTf(r));
                c.setCamera(client::orbitCamera(info, 30.0 + i, 20.0, 1.0, std::uint32_t(r + 2)));
                c.requestFrame();
                c.nextFrame();
                ms[std::size_t(i)] = msBetween(start, Clock::now());
            });
        for (auto& t : threads)
            t.join();
        firsts.push_back(*std::min_element(ms.begin(), ms.end()));
        lasts.push_back(*std::max_element(ms.begin(), ms.end()));
        std::printf("| %d | %.1f | %.1f |\n", r + 1, firsts.back(), lasts.back());
    }
    std::printf("| median | %.1f | %.1f |\n", median(firsts), median(lasts));
    clients.clear();
    daemon.stop();
    serving.join();
    return 0;
}
