// brickcast-client: connects to brickcastd, opens a volume, flies a camera path (an orbit or
// a file), optionally switches the transfer function mid-flight, saves frames as PNG and
// prints per-frame latency (request sent -> frame decoded), frames/s and bytes received.
#include "client/Client.h"
#include "client/Error.h"
#include "client/Orbit.h"

#include <CLI/CLI.hpp>
#include <png.h>

#include <algorithm>
#include <chrono>
#include <cmath>
#include <cstdio>
#include <filesystem>
#include <fstream>
#include <new>
#include <optional>
#include <sstream>
#include <string>
#include <utility>
#include <vector>

namespace {

using namespace bc;

struct Options {
    std::string host = "127.0.0.1", token, volume, tf, tfSwitch, codec = "zstd", renderer = "auto",
                outputDir, cameraFile, size = "256,256", tlsCa, mode = "composite";
    std::optional<double> iso;
    std::uint16_t port = 7411;
    int frames = 36, saveEvery = 1, quality = 0;
    double step = 1.0, elevation = 20.0, distance = 1.0;
    bool list = false, continuous = false, tls = false, tlsInsecure = false;
    std::uint32_t timeoutMs = 60000;
};

/// A camera path file: one camera a line, "ex ey ez tx ty tz ux uy uz [fov]"; '#' comments.
std::vector<protocol::SetCamera> readPath(const std::string& path) {
    std::ifstream in(path);
    if (!in) throw std::runtime_error(path + ": cannot read");
    std::vector<protocol::SetCamera> out;
    std::string line;
    for (int n = 1; std::getline(in, line); ++n) {
        if (line.empty() || line[0] == '#') continue;
        std::istringstream s(line);
        protocol::SetCamera c;
        for (auto* v : {&c.eye, &c.target, &c.up})
            for (double& x : *v)
                if (!(s >> x))
                    throw std::runtime_error(path + ":" + std::to_string(n) + ": need 9 numbers");
        s >> c.fovYDeg;
        out.push_back(c);
    }
    if (out.empty()) throw std::runtime_error(path + ": no camera in the file");
    return out;
}

void writePng(const std::string& path, const client::ReceivedFrame& f) {
    png_image image{};
    image.version = PNG_IMAGE_VERSION;
    image.width = f.header.width;
    image.height = f.header.height;
    image.format = PNG_FORMAT_RGBA;
    if (!png_image_write_to_file(&image, path.c_str(), 0, f.rgba.data(), 0, nullptr))
        throw std::runtime_error(path + ": " + image.message);
}

protocol::Codec codecOf(const std::string& s) {
    if (s == "raw") return protocol::Codec::Raw;
    if (s == "zstd") return protocol::Codec::Zstd;
    if (s == "delta") return protocol::Codec::ZstdDelta;
    if (s == "jpeg") return protocol::Codec::Jpeg;
    if (s == "png") return protocol::Codec::Png;
    throw CLI::ValidationError("--codec", "one of raw, zstd, delta, jpeg, png");
}

protocol::SetTransferFunction preset(const std::string& name) {
    protocol::SetTransferFunction tf;
    tf.kind = protocol::TfKind::Preset;
    tf.shadingSource = protocol::ShadingSource::Preset;
    tf.preset = name;
    return tf;
}

double percentile(std::vector<double> v, double p) {
    if (v.empty()) return 0;
    std::sort(v.begin(), v.end());
    return v[std::min(v.size() - 1, std::size_t(p / 100.0 * double(v.size())))];
}

protocol::RenderOptions renderOptions(const Options& o) {
    protocol::RenderOptions r;
    unsigned w = 0, h = 0;
    if (std::sscanf(o.size.c_str(), "%u,%u", &w, &h) != 2)
        throw CLI::ValidationError("--size", "W,H");
    r.width = std::uint16_t(w);
    r.height = std::uint16_t(h);
    r.stepVoxels = float(o.step);
    r.codec = codecOf(o.codec);
    r.codecQuality = std::uint8_t(o.quality);
    r.quality = protocol::Quality::Refined;
    const auto renderer = protocol::rendererNamed(o.renderer);
    if (!renderer)
        throw CLI::ValidationError("--renderer", "auto, gpu, cpu, splat, splat-gpu or reference");
    r.renderer = *renderer;
    return r;
}

/// Why the server's auto drew with what it did, from its counters (the gauge
/// auto_renderer{renderer="cpu",reason="auto: cpu (...)"}, cut at 128 bytes by the protocol);
/// empty before it has decided.
std::string autoRendererOf(const std::vector<std::pair<std::string, double>>& counters) {
    const std::string prefix = "auto_renderer{renderer=\"", key = "reason=\"";
    for (const auto& [name, value] : counters) {
        const auto at = name.find(key);
        if (!name.starts_with(prefix) || at == std::string::npos) continue;
        std::string reason = name.substr(at + key.size());
        if (reason.ends_with("\"}"))
            reason.resize(reason.size() - 2);
        else
            reason += "...";
        return reason;
    }
    return {};
}

int fly(const Options& o) {
    client::ClientConfig config;
    config.host = o.host;
    config.port = o.port;
    config.token = o.token;
    config.timeoutMs = o.timeoutMs;
    config.tls = o.tls || !o.tlsCa.empty() || o.tlsInsecure;
    config.tlsCaFile = o.tlsCa;
    config.tlsVerify = !o.tlsInsecure;
    client::Client c(config);
    const auto volumes = c.listVolumes();
    if (o.list) {
        for (const auto& v : volumes)
            std::printf("%s  %ux%ux%u  %.3g..%.3g  %u levels\n", v.name.c_str(), v.dims[0],
                        v.dims[1], v.dims[2], v.valueMin, v.valueMax, v.levels);
        c.bye();
        return 0;
    }
    if (volumes.empty()) throw std::runtime_error("the server has no volumes");
    const auto info = c.openVolume(o.volume.empty() ? volumes.front().name : o.volume);
    c.setRenderOptions(renderOptions(o));
    if (!o.tf.empty()) c.setTransferFunction(preset(o.tf));
    const auto mode = protocol::blendModeNamed(o.mode);
    if (!mode)
        throw std::invalid_argument("--mode: '" + o.mode +
                                    "' is not one of composite, mip, minip, average, iso");
    if ((*mode == protocol::BlendMode::Isosurface) != o.iso.has_value())
        throw std::invalid_argument(o.iso ? "--iso: only with --mode iso"
                                          : "--mode iso: needs --iso VALUE");
    if (*mode != protocol::BlendMode::Composite) {
        protocol::SetModeAndClip m;
        m.mode = *mode;
        m.isoValue = o.iso.value_or(0.0);
        c.setModeAndClip(m);
    }
    std::string switchTo;
    int switchAt = -1;
    if (!o.tfSwitch.empty()) {
        const auto at = o.tfSwitch.find('@');
        if (at == std::string::npos) throw CLI::ValidationError("--tf-switch", "PRESET@FRAME");
        switchTo = o.tfSwitch.substr(0, at);
        switchAt = std::stoi(o.tfSwitch.substr(at + 1));
    }
    const auto path =
        o.cameraFile.empty() ? std::vector<protocol::SetCamera>() : readPath(o.cameraFile);
    const int frames = path.empty() ? o.frames : int(path.size());
    if (!o.outputDir.empty()) std::filesystem::create_directories(o.outputDir);
    std::vector<double> latency;
    std::uint64_t bytes = 0;
    const auto start = std::chrono::steady_clock::now();
    if (o.continuous) c.requestFrame(protocol::FrameMode::ContinuousOn);
    for (int f = 0; f < frames; ++f) {
        if (f == switchAt) c.setTransferFunction(preset(switchTo));
        protocol::SetCamera cam =
            path.empty() ? client::orbitCamera(info, 360.0 * f / frames, o.elevation, o.distance)
                         : path[std::size_t(f)];
        cam.cameraId = std::uint32_t(f + 1);
        const auto sent = std::chrono::steady_clock::now();
        c.setCamera(cam);
        if (!o.continuous) c.requestFrame();
        client::ReceivedFrame frame = c.nextFrame();
        while (frame.header.cameraId != cam.cameraId)
            frame = c.nextFrame(); // older views
        const double ms =
            std::chrono::duration<double, std::milli>(std::chrono::steady_clock::now() - sent)
                .count();
        latency.push_back(ms);
        bytes += frame.wireBytes;
        std::printf(
            "frame %3d  camera %3u  %.1f ms  render %.1f ms  encode %.2f ms  %llu bytes%s%s\n", f,
            frame.header.cameraId, ms, frame.header.renderMs, frame.header.encodeMs,
            (unsigned long long)frame.wireBytes, frame.header.refined ? "" : "  (interactive)",
            frame.header.cached ? "  (from the server's frame cache)" : "");
        if (!o.outputDir.empty() && f % std::max(o.saveEvery, 1) == 0) {
            char name[64];
            std::snprintf(name, sizeof name, "frame_%04d.png", f);
            writePng((std::filesystem::path(o.outputDir) / name).string(), frame);
        }
    }
    const double seconds =
        std::chrono::duration<double>(std::chrono::steady_clock::now() - start).count();
    std::printf("\n%d frames of %s in %.2f s: %.2f frames/s; latency p50 %.1f ms, p99 %.1f ms, max "
                "%.1f ms; %.2f MiB received (%.1f KiB a frame)\n",
                frames, info.name.c_str(), seconds, frames / seconds, percentile(latency, 50),
                percentile(latency, 99), percentile(latency, 100),
                double(c.bytesReceived()) / (1 << 20),
                double(bytes) / 1024.0 / std::max(frames, 1));
    if (o.renderer == "auto") {
        const std::string why = autoRendererOf(c.stats());
        std::printf("renderer %s\n",
                    why.empty() ? "auto (the server did not say which)" : why.c_str());
    }
    c.bye();
    return 0;
}

} // namespace

int main(int argc, char** argv) {
    CLI::App app{"brickcast-client: fly a camera through a volume served by brickcastd"};
    Options o;
    app.add_option("--host", o.host, "Server address")->capture_default_str();
    app.add_option("--port", o.port, "Server port")->capture_default_str();
    app.add_option("--token", o.token, "Token, when the server requires one");
    app.add_flag(
        "--tls", o.tls,
        "Speak TLS (a server with tls_cert), trusting the system's certificate authorities");
    app.add_option(
           "--tls-ca", o.tlsCa,
           "Speak TLS, trusting this PEM file (a CA, or the server's self-signed certificate)")
        ->check(CLI::ExistingFile);
    app.add_flag(
        "--tls-insecure", o.tlsInsecure,
        "Speak TLS without checking the server's certificate (encrypted, not authenticated)");
    app.add_flag("--list", o.list, "List the server's volumes and exit");
    app.add_option("--volume", o.volume, "Catalog name (default: the first)");
    app.add_option("--frames", o.frames, "Orbit frames")
        ->capture_default_str()
        ->check(CLI::Range(1, 100000));
    app.add_option("--elevation", o.elevation, "Orbit elevation, degrees")->capture_default_str();
    app.add_option("--distance", o.distance, "Orbit distance (1 = the volume fills the view)")
        ->capture_default_str();
    app.add_option("--camera-path", o.cameraFile,
                   "Camera file instead of the orbit (ex ey ez tx ty tz ux uy uz [fov] a line)");
    app.add_option("--size", o.size, "Frame W,H")->capture_default_str();
    app.add_option("--step", o.step, "Sample step, voxels")->capture_default_str();
    app.add_option("--tf", o.tf, "Transfer-function preset");
    app.add_option("--mode", o.mode, "composite, mip, minip, average or iso")
        ->capture_default_str();
    app.add_option("--iso", o.iso, "With --mode iso: the surface's value, in the volume's units");
    app.add_option("--tf-switch", o.tfSwitch,
                   "PRESET@FRAME: switch the transfer function mid-flight");
    app.add_option("--codec", o.codec, "raw, zstd, delta, jpeg or png")->capture_default_str();
    app.add_option("--quality", o.quality, "JPEG quality or zstd level (0 = default)")
        ->check(CLI::Range(0, 100));
    app.add_option("--renderer", o.renderer,
                   "auto (the server's choice: gpu on a hardware GPU, else cpu), gpu, cpu, "
                   "splat, splat-gpu or reference")
        ->capture_default_str();
    app.add_flag("--continuous", o.continuous, "Continuous mode instead of one request a frame");
    app.add_option("-o,--output-dir", o.outputDir, "Save frames as PNG here");
    app.add_option("--save-every", o.saveEvery, "Save every Nth frame")->capture_default_str();
    app.add_option("--timeout-ms", o.timeoutMs, "Longest wait for any reply")
        ->capture_default_str();
    CLI11_PARSE(app, argc, argv);
    try {
        return fly(o);
    } catch (const std::bad_alloc&) {
        std::fprintf(stderr,
                     "brickcast-client: out of memory (std::bad_alloc) flying volume %s on %s\n",
                     o.volume.c_str(), o.host.c_str());
        return 1;
    } catch (const std::exception& e) {
        std::fprintf(stderr, "brickcast-client: %s\n", e.what());
        return 1;
    }
}
