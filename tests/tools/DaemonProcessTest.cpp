// SIGTERM drains a real brickcastd process with clients attached: each gets Bye (shutting
// down) before the close, and the daemon exits 0, also in the middle of the heaviest frame
// the protocol allows. Without EGL, GPU frames get an error saying why and the CPU renderers
// serve.
#include "tests/server/ServerTestSupport.h"

#include <csignal>
#include <fstream>
#include <sys/wait.h>

namespace bc::server::test {
namespace {

TEST(DaemonProcess, SigtermDrainsAttachedClientsAndExitsCleanly) {
    TempDir dir;
    const std::string config = dir.file("brickcastd.toml"), port = dir.file("port");
    std::ofstream(config)
        << "[server]\nlisten = \"127.0.0.1:0\"\nstore_dir = \"" << dir.path().string()
        << "\"\n[[volume]]\nname = \"p\"\ngenerate = \"phantom\"\ndims = [32, 32, 32]\n";
    const pid_t pid = ::fork();
    if (pid == 0) {
        ::execl(BC_BRICKCASTD_EXE, BC_BRICKCASTD_EXE, "--config", config.c_str(), "--port-file",
                port.c_str(), "--quiet", nullptr);
        std::_Exit(127);
    }
    for (int i = 0; i < 300 && !std::filesystem::exists(port); ++i)
        std::this_thread::sleep_for(std::chrono::milliseconds(50));
    ASSERT_TRUE(std::filesystem::exists(port)) << "brickcastd did not start";
    client::ClientConfig cc;
    std::ifstream(port) >> cc.port;
    client::Client a(cc), b(cc);
    const auto v = a.openVolume("p");
    a.setRenderOptions(smallCpuFrames(32));
    a.setCamera(orbitCamera(v, 0, 1));
    a.requestFrame();
    a.nextFrame();
    ASSERT_EQ(::kill(pid, SIGTERM), 0);
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
    int status = 0;
    for (int i = 0; i < 100 && ::waitpid(pid, &status, WNOHANG) == 0; ++i)
        std::this_thread::sleep_for(std::chrono::milliseconds(50));
    ASSERT_TRUE(WIFEXITED(status)) << "brickcastd still running 5 s after SIGTERM";
    EXPECT_EQ(WEXITSTATUS(status), 0);
}

TEST(DaemonProcess, SigtermDuringTheHeaviestFrameExitsWithinFiveSeconds) {
    TempDir dir;
    const std::string raw = bc::test::dataPath("stanford_cthead_256x256x113_uint16.raw");
    if (!std::filesystem::exists(raw)) return bc::test::missingData("scan cthead");
    const std::string store = dir.file("cthead.bcs");
    const auto ingest = bc::test::runCommand(std::string(BC_BRICKCAST_EXE) + " ingest " + raw +
                                             " --spacing 1,1,2 -o " + store);
    ASSERT_EQ(ingest.exitCode, 0) << ingest.text;
    const std::string config = dir.file("brickcastd.toml"), port = dir.file("port");
    // The cap is raised so that the frame is drawn (the default refuses it).
    std::ofstream(config) << "[server]\nlisten = \"127.0.0.1:0\"\n[frames]\n"
                          << "max_frame_gsamples = 65536\n[[volume]]\nname = \"cthead\"\n"
                          << "store = \"" << store << "\"\n";
    const pid_t pid = ::fork();
    if (pid == 0) {
        ::execl(BC_BRICKCASTD_EXE, BC_BRICKCASTD_EXE, "--config", config.c_str(), "--port-file",
                port.c_str(), "--quiet", nullptr);
        std::_Exit(127);
    }
    for (int i = 0; i < 300 && !std::filesystem::exists(port); ++i)
        std::this_thread::sleep_for(std::chrono::milliseconds(50));
    ASSERT_TRUE(std::filesystem::exists(port)) << "brickcastd did not start";
    client::ClientConfig cc;
    std::ifstream(port) >> cc.port;
    client::Client c(cc);
    const auto v = c.openVolume("cthead");
    protocol::RenderOptions o;
    o.width = o.height = 4096;
    o.stepVoxels = 0.0101f; // the smallest step the renderers take is 0.01
    o.renderer = protocol::Renderer::Reference;
    o.quality = protocol::Quality::Refined;
    c.setRenderOptions(o);
    c.setCamera(orbitCamera(v, 30, 1));
    c.requestFrame();
    std::this_thread::sleep_for(std::chrono::seconds(2)); // well into the frame
    const auto start = std::chrono::steady_clock::now();
    ASSERT_EQ(::kill(pid, SIGTERM), 0);
    int status = 0;
    bool exited = false;
    for (int i = 0; i < 200 && !exited; ++i) {
        exited = ::waitpid(pid, &status, WNOHANG) == pid;
        if (!exited) std::this_thread::sleep_for(std::chrono::milliseconds(25));
    }
    const double ms =
        std::chrono::duration<double, std::milli>(std::chrono::steady_clock::now() - start).count();
    if (!exited) {
        ::kill(pid, SIGKILL);
        ::waitpid(pid, &status, 0);
        FAIL() << "brickcastd still running 5 s after SIGTERM";
    }
    std::printf("[sigterm] brickcastd exited %.0f ms after SIGTERM, mid-frame\n", ms);
    ASSERT_TRUE(WIFEXITED(status));
    EXPECT_EQ(WEXITSTATUS(status), 0);
}

TEST(DaemonProcess, WithoutEglAGpuFrameGetsAnErrorSayingWhyAndTheCpuRenderersServe) {
    TempDir dir;
    const std::string config = dir.file("brickcastd.toml"), port = dir.file("port");
    std::ofstream(config)
        << "[server]\nlisten = \"127.0.0.1:0\"\nstore_dir = \"" << dir.path().string()
        << "\"\n[[volume]]\nname = \"p\"\ngenerate = \"phantom\"\ndims = [32, 32, 32]\n";
    const pid_t pid = ::fork();
    if (pid == 0) {
        // GLVND finds no EGL vendor: every EGL display fails, as on a host without a driver.
        ::setenv("__EGL_VENDOR_LIBRARY_FILENAMES", "/nonexistent/egl_vendor.json", 1);
        ::execl(BC_BRICKCASTD_EXE, BC_BRICKCASTD_EXE, "--config", config.c_str(), "--port-file",
                port.c_str(), "--quiet", nullptr);
        std::_Exit(127);
    }
    for (int i = 0; i < 300 && !std::filesystem::exists(port); ++i)
        std::this_thread::sleep_for(std::chrono::milliseconds(50));
    ASSERT_TRUE(std::filesystem::exists(port)) << "brickcastd did not start";
    client::ClientConfig cc;
    std::ifstream(port) >> cc.port;
    {
        client::Client gpu(cc), cpu(cc);
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
        client::Client later(cc);
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
    }
    ASSERT_EQ(::kill(pid, SIGTERM), 0);
    int status = 0;
    for (int i = 0; i < 100 && ::waitpid(pid, &status, WNOHANG) == 0; ++i)
        std::this_thread::sleep_for(std::chrono::milliseconds(50));
    ASSERT_TRUE(WIFEXITED(status)) << "brickcastd still running 5 s after SIGTERM";
    EXPECT_EQ(WEXITSTATUS(status), 0);
}

} // namespace
} // namespace bc::server::test
