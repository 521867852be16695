// brickcast-client end to end against a daemon in this process: listing, a camera path file,
// PNG frames and the latency summary; a bad camera file is named with its line.
#include "tests/server/ServerTestSupport.h"

#include <cstdio>
#include <fstream>

namespace bc::server::test {
namespace {

/// Runs a command; its exit status and everything it printed.
std::pair<int, std::string> run(const std::string& command) {
    auto out = bc::test::runCommand(command);
    return {out.exitCode, std::move(out.text)};
}

TEST(ClientCli, ListsFliesACameraFileSavesPngsAndPrintsLatency) {
    TempDir dir;
    TestDaemon d(generatedConfig(dir, {{"alpha", 32}, {"beta", 24}}));
    const std::string exe = std::string(BC_CLIENT_EXE) + " --port " + std::to_string(d.port);
    const auto [listStatus, list] = run(exe + " --list");
    EXPECT_EQ(listStatus, 0) << list;
    EXPECT_NE(list.find("alpha  32x32x32"), std::string::npos) << list;
    EXPECT_NE(list.find("beta  24x24x24"), std::string::npos) << list;

    const std::string path = dir.file("path.txt"), frames = dir.file("frames");
    std::ofstream(path) << "# eye target up fov\n"
                        << "120 16 40  16 16 16  0 0 1\n"
                        << "16 120 40  16 16 16  0 0 1 25\n"
                        << "-80 16 40  16 16 16  0 0 1\n";
    const auto [status, out] =
        run(exe + " --volume alpha --camera-path " + path +
            " --size 40,32 --renderer cpu --codec delta -o " + frames + " --tf-switch ct-bone@1");
    EXPECT_EQ(status, 0) << out;
    EXPECT_NE(out.find("3 frames of alpha"), std::string::npos) << out;
    EXPECT_NE(out.find("latency p50"), std::string::npos) << out;
    for (const char* f : {"frame_0000.png", "frame_0001.png", "frame_0002.png"})
        EXPECT_TRUE(std::filesystem::exists(std::filesystem::path(frames) / f)) << f;

    std::ofstream(path) << "120 16 40  16 16\n";
    const auto [badStatus, bad] = run(exe + " --volume alpha --camera-path " + path);
    EXPECT_EQ(badStatus, 1);
    EXPECT_NE(bad.find(path + ":1: need 9 numbers"), std::string::npos) << bad;
    const auto [missingStatus, missing] = run(exe + " --volume nope --frames 1");
    EXPECT_EQ(missingStatus, 1);
    EXPECT_NE(missing.find("UnknownVolume"), std::string::npos) << missing;
}

// Without --renderer the client asks for auto (the main job does), and prints the server's
// choice and why: on llvmpipe (the dev VM, CI) the CPU raycaster.
TEST(ClientCli, WithoutARendererAsksForAutoAndPrintsTheServersChoice) {
    TempDir dir;
    TestDaemon d(generatedConfig(dir, {{"alpha", 32}}));
    const std::string exe = std::string(BC_CLIENT_EXE) + " --port " + std::to_string(d.port);
    const auto [status, out] = run(exe + " --volume alpha --frames 2 --size 40,32");
    EXPECT_EQ(status, 0) << out;
    EXPECT_NE(out.find("2 frames of alpha"), std::string::npos) << out;
    const auto at = out.find("renderer auto: ");
    ASSERT_NE(at, std::string::npos) << out;
    const std::string line = out.substr(at, out.find('\n', at) - at);
    EXPECT_TRUE(line.starts_with("renderer auto: cpu (") ||
                line.starts_with("renderer auto: gpu ("))
        << line;
    if (line.find("llvmpipe") != std::string::npos) {
        EXPECT_TRUE(line.starts_with("renderer auto: cpu (GL_RENDERER 'llvmpipe")) << line;
        EXPECT_TRUE(line.ends_with("' is a software rasteriser)")) << line;
    }
    const auto [namedStatus, named] = run(exe + " --volume alpha --frames 1 --renderer cpu");
    EXPECT_EQ(namedStatus, 0) << named;
    EXPECT_EQ(named.find("renderer auto"), std::string::npos) << "printed for a named renderer";
}

} // namespace
} // namespace bc::server::test
