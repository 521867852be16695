// SIGTERM drains a real brickcastd process with clients attached: each gets Bye (shutting
// down) before the close, and the daemon exits 0.
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

} // namespace
} // namespace bc::server::test
