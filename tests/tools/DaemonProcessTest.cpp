// SIGTERM drains a real brickcastd process with clients attached: each gets Bye (shutting
// down) before the close, and the daemon exits 0, also in the middle of the heaviest frame
// the protocol allows. Without EGL, GPU frames get an error saying why and the CPU renderers
// serve.
#include "tests/server/ServerTestSupport.h"

#include <csignal>
#include <fstream>
#include <optional>
#include <string>
#include <sys/wait.h>
#include <utility>
#include <vector>

namespace bc::server::test {
namespace {

/// A brickcastd process started by startDaemon.
struct DaemonChild {
    pid_t pid = -1;
    bool started = false; ///< it wrote its port file within 15 s
    client::ClientConfig client;
};

/// Writes `configToml` to `dir`/brickcastd.toml and runs brickcastd on it as a child process
/// (`--quiet`), with the variables `env` set in the child only; waits up to 15 s for the
/// port file the daemon writes once it listens.
DaemonChild startDaemon(const TempDir& dir, const std::string& configToml,
                        const std::vector<std::pair<std::string, std::string>>& env = {}) {
    const std::string config = dir.file("brickcastd.toml"), port = dir.file("port");
    std::ofstream(config) << configToml;
    DaemonChild d;
    d.pid = ::fork();
    if (d.pid == 0) {
        for (const auto& [name, value] : env)
            ::setenv(name.c_str(), value.c_str(), 1);
        ::execl(BC_BRICKCASTD_EXE, BC_BRICKCASTD_EXE, "--config", config.c_str(), "--port-file",
                port.c_str(), "--quiet", nullptr);
        std::_Exit(127);
    }
    for (int i = 0; i < 300 && !std::filesystem::exists(port); ++i)
        std::this_thread::sleep_for(std::chrono::milliseconds(50));
    d.started = std::filesystem::exists(port);
    if (d.started) std::ifstream(port) >> d.client.port;
    return d;
}

/// A daemon config serving a generated 32^3 phantom "p" (ingested into `dir`).
std::string phantomConfig(const TempDir& dir) {
    return "[server]\nlisten = \"127.0.0.1:0\"\nstore_dir = \"" + dir.path().string() +
           "\"\n[[volume]]\nname = \"p\"\ngenerate = \"phantom\"\ndims = [32, 32, 32]\n";
}

/// The wait status of child `pid` once it exits within `timeoutMs`; nullopt, the child
/// killed (SIGKILL) and reaped, when it does not.
std::optional<int> waitForExit(pid_t pid, int timeoutMs) {
    int status = 0;
    for (int waitedMs = 0; waitedMs < timeoutMs; waitedMs += 25) {
        if (::waitpid(pid, &status, WNOHANG) == pid) return status;
        std::this_thread::sleep_for(std::chrono::milliseconds(25));
    }
    if (::waitpid(pid, &status, WNOHANG) == pid) return status;
    ::kill(pid, SIGKILL);
    ::waitpid(pid, &status, 0);
    return std::nullopt;
}

TEST(DaemonProcess, SigtermDrainsAttachedClientsAndExitsCleanly) {
    TempDir dir;
    const DaemonChild daemon = startDaemon(dir, phantomConfig(dir));
    ASSERT_TRUE(daemon.started) << "brickcastd did not start";
    client::Client a(daemon.client), b(daemon.client);
    const auto v = a.openVolume("p");
    a.setRenderOptions(smallCpuFrames(32));
    a.setCamera(orbitCamera(v, 0, 1));
    a.requestFrame();
    a.nextFrame();
    ASSERT_EQ(::kill(daemon.pid, SIGTERM), 0);
    for (auto* c : {&a, &b}) {
        bool bye = false;
        try {
            for (;;) {
                auto m = c->nextMessage();
                if (auto* x = std::get_if<protocol::Bye>(&m)) {
                    bye = x->reason == protocol::ByeReason::ShuttingDown;
                    break;
                }
            }
        } catch (const client::ClientError&) {
        }
        EXPECT_TRUE(bye) << "no Bye (shutting down) before the close";
    }
    const std::optional<int> status = waitForExit(daemon.pid, 5000);
    ASSERT_TRUE(status) << "brickcastd still running 5 s after SIGTERM";
    ASSERT_TRUE(WIFEXITED(*status)) << "status " << *status;
    EXPECT_EQ(WEXITSTATUS(*status), 0);
}

TEST(DaemonProcess, SigtermDuringTheHeaviestFrameExitsWithinFiveSeconds) {
    TempDir dir;
    const std::string raw = bc::test::dataPath("stanford_cthead_256x256x113_uint16.raw");
    if (!std::filesystem::exists(raw)) return bc::test::missingData("scan cthead");
    const std::string store = dir.file("cthead.bcs");
    const auto ingest = bc::test::runCommand(std::string(BC_BRICKCAST_EXE) + " ingest " + raw +
                                             " --spacing 1,1,2 -o " + store);
    ASSERT_EQ(ingest.exitCode, 0) << ingest.text;
    // The cap is raised so that the frame is drawn (the default refuses it).
    const std::string frames = "[frames]\nmax_frame_gsamples = 65536\n";
    const std::string volume = "[[volume]]\nname = \"cthead\"\nstore = \"" + store + "\"\n";
    const DaemonChild daemon =
        startDaemon(dir, "[server]\nlisten = \"127.0.0.1:0\"\n" + frames + volume);
    ASSERT_TRUE(daemon.started) << "brickcastd did not start";
    client::Client c(daemon.client);
    const auto v = c.openVolume("cthead");
    protocol::RenderOptions o;
    o.width = o.height = 4096;
    o.stepVoxels = 0.0101f; // the smallest step the renderers take is 0.01
    o.renderer = protocol::Renderer::Reference;
    o.quality = protocol::Quality::Refined;
    c.setRenderOptions(o);
    c.setCamera(orbitCamera(v, 30, 1));
    c.requestFrame();
    // Mid-frame: its first slice has been drawn, and the rest is to come.
    ASSERT_EQ(waitForStat(c, "render_frames_in_progress", [](double n) { return n > 0; }), 1.0)
        << "the frame did not start";
    const auto start = std::chrono::steady_clock::now();
    ASSERT_EQ(::kill(daemon.pid, SIGTERM), 0);
    const std::optional<int> status = waitForExit(daemon.pid, 5000);
    const double ms =
        std::chrono::duration<double, std::milli>(std::chrono::steady_clock::now() - start).count();
    if (!status) FAIL() << "brickcastd still running 5 s after SIGTERM";
    std::printf("[sigterm] brickcastd exited %.0f ms after SIGTERM, mid-frame\n", ms);
    ASSERT_TRUE(WIFEXITED(*status));
    EXPECT_EQ(WEXITSTATUS(*status), 0);
}

TEST(DaemonProcess, WithoutEglAGpuFrameGetsAnErrorSayingWhyAndTheCpuRenderersServe) {
    TempDir dir;
    // GLVND finds no EGL vendor: every EGL display fails, as on a host without a driver.
    const DaemonChild daemon =
        startDaemon(dir, phantomConfig(dir),
                    {{"__EGL_VENDOR_LIBRARY_FILENAMES", "/nonexistent/egl_vendor.json"}});
    ASSERT_TRUE(daemon.started) << "brickcastd did not start";
    {
        client::Client gpu(daemon.client), cpu(daemon.client);
        const auto v = gpu.openVolume("p");
        cpu.openVolume("p");
        auto options = smallCpuFrames(32);
        cpu.setRenderOptions(options);
        options.renderer = protocol::Renderer::GpuRaycaster;
        gpu.setRenderOptions(options);
        gpu.setCamera(orbitCamera(v, 0, 1));
        gpu.requestFrame();
        try {
            gpu.nextFrame();
            ADD_FAILURE() << "a GPU frame was drawn without EGL";
        } catch (const client::ServerError& e) {
            EXPECT_EQ(e.code(), protocol::ErrorCode::RenderFailed);
            EXPECT_NE(std::string(e.what()).find("no OpenGL 4.5 context: "), std::string::npos)
                << e.what();
            EXPECT_NE(std::string(e.what()).find("EGL"), std::string::npos)
                << "the error does not say what failed: " << e.what();
        }
        for (auto* c : {&gpu, &cpu}) { // CPU frames still come, also in the GPU session
            c->setRenderOptions(smallCpuFrames(32));
            c->setCamera(orbitCamera(v, 20, 2));
            c->requestFrame();
            EXPECT_EQ(c->nextFrame().header.cameraId, 2u);
        }
        // Now it is known: later Hellos leave the GPU out and GPU options are refused, saying
        // why.
        client::Client later(daemon.client);
        EXPECT_FALSE(later.server().capabilities & protocol::kCapGpuRenderer);
        for (auto renderer : {protocol::Renderer::GpuRaycaster, protocol::Renderer::GpuSplatter}) {
            options.renderer = renderer;
            later.setRenderOptions(options);
            const auto m = later.nextMessage();
            const auto* e = std::get_if<protocol::Error>(&m);
            ASSERT_TRUE(e) << "GPU options accepted";
            EXPECT_EQ(e->code, protocol::ErrorCode::OutOfRange);
            EXPECT_NE(e->message.find("no OpenGL 4.5 context"), std::string::npos) << e->message;
        }
        // auto, the default, is the CPU raycaster here: the same frame as asking for it.
        client::Client automatic(daemon.client), cpuAgain(daemon.client);
        std::vector<std::vector<std::uint8_t>> images;
        for (auto* c : {&automatic, &cpuAgain}) {
            c->openVolume("p");
            auto o = smallCpuFrames(32);
            o.renderer = c == &automatic ? protocol::Renderer::Auto : o.renderer;
            c->setRenderOptions(o);
            c->setCamera(orbitCamera(v, 40, 3));
            c->requestFrame();
            images.push_back(c->nextFrame().rgba);
        }
        EXPECT_TRUE(images[0] == images[1]) << "auto without EGL is not the CPU raycaster";
    }
    ASSERT_EQ(::kill(daemon.pid, SIGTERM), 0);
    const std::optional<int> status = waitForExit(daemon.pid, 5000);
    ASSERT_TRUE(status) << "brickcastd still running 5 s after SIGTERM";
    ASSERT_TRUE(WIFEXITED(*status)) << "status " << *status;
    EXPECT_EQ(WEXITSTATUS(*status), 0);
}

} // namespace
} // namespace bc::server::test
