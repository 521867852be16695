// `brickcast loadtest` against a daemon in this process: every path flown by its client, the
// frames in the CSV, the cache tiers' traffic taken from the server's counters; bad options
// named, and a server that is not loopback refused before connecting.
#include "tests/server/ServerTestSupport.h"

#include <cstdio>
#include <fstream>
#include <set>
#include <sstream>

namespace bc::server::test {
namespace {

/// Runs a command; its exit status and everything it printed.
std::pair<int, std::string> run(const std::string& command) {
    auto out = bc::test::runCommand(command);
    return {out.exitCode, std::move(out.text)};
}

TEST(LoadtestCli, FliesEveryPathAndReportsLatencyAndTheCacheTiers) {
    TempDir dir;
    TestDaemon d(generatedConfig(dir, {{"lt", 96}}));
    const std::string csv = dir.file("frames.csv");
    const std::string exe =
        std::string(BC_BRICKCAST_EXE) + " loadtest --port " + std::to_string(d.port);
    const auto [status, out] = run(exe +
                                   " --volume lt --clients 4 --frames 5 --size 40,32 "
                                   "--tf-every 2 --csv " +
                                   csv);
    ASSERT_EQ(status, 0) << out;
    for (const char* path : {"| orbit | 1 | 5 |", "| zoom | 1 | 5 |", "| jumps | 1 | 5 |",
                             "| tf-sweep | 1 | 5 |", "| all | 4 | 20 |"})
        EXPECT_NE(out.find(path), std::string::npos) << path << "\n" << out;
    EXPECT_NE(out.find("| disk -> host |"), std::string::npos) << out;
    EXPECT_NE(out.find("Server: 20 frames, 0 from the frame cache, 0 render errors"),
              std::string::npos)
        << out;
    std::ifstream f(csv);
    std::string line;
    std::getline(f, line);
    EXPECT_EQ(line,
              "client,path,frame,latency_ms,render_ms,queue_ms,bytes,bytes_uploaded,bricks_drawn,"
              "cached");
    std::set<std::string> paths;
    int frames = 0;
    while (std::getline(f, line)) {
        ++frames;
        paths.insert(line.substr(line.find(',') + 1,
                                 line.find(',', line.find(',') + 1) - line.find(',') - 1));
    }
    EXPECT_EQ(frames, 20);
    EXPECT_EQ(paths, (std::set<std::string>{"orbit", "zoom", "jumps", "tf-sweep"}));
}

// Clients on the same path fly views of their own: each frame is drawn, none is answered by
// the server's frame cache (which would answer a crowd flying in step).
TEST(LoadtestCli, ClientsSharingAPathAskForViewsOfTheirOwn) {
    TempDir dir;
    TestDaemon d(generatedConfig(dir, {{"lt", 48}}));
    const auto [status, out] =
        run(std::string(BC_BRICKCAST_EXE) + " loadtest --port " + std::to_string(d.port) +
            " --volume lt --paths orbit --clients 3 --frames 3 --size 24,24");
    ASSERT_EQ(status, 0) << out;
    EXPECT_NE(out.find("| orbit | 3 | 9 |"), std::string::npos) << out;
    EXPECT_NE(out.find("Server: 9 frames, 0 from the frame cache"), std::string::npos) << out;
}

TEST(LoadtestCli, BadOptionsAndServersOffLoopbackAreNamed) {
    const std::string exe = std::string(BC_BRICKCAST_EXE) + " loadtest";
    const auto [hostStatus, host] = run(exe + " --host 10.1.2.3 --port 1");
    EXPECT_NE(hostStatus, 0);
    EXPECT_NE(host.find("--host: '10.1.2.3' is not loopback"), std::string::npos) << host;
    const auto [pathStatus, path] = run(exe + " --paths orbit,spiral --port 1");
    EXPECT_NE(pathStatus, 0);
    EXPECT_NE(path.find("'spiral'"), std::string::npos) << path;
    const auto [qualityStatus, quality] = run(exe + " --quality adaptive --port 1");
    EXPECT_NE(qualityStatus, 0);
    EXPECT_NE(quality.find("--quality: 'adaptive' is not refined or interactive"),
              std::string::npos)
        << quality;
    const auto [clientsStatus, clients] = run(exe + " --clients 0 --port 1");
    EXPECT_NE(clientsStatus, 0);
    EXPECT_NE(clients.find("--clients"), std::string::npos) << clients;
    TempDir dir;
    TestDaemon d(generatedConfig(dir, {{"lt", 24}}));
    const auto [volStatus, vol] =
        run(exe + " --port " + std::to_string(d.port) + " --volume nosuch --clients 2 --frames 2");
    EXPECT_NE(volStatus, 0);
    EXPECT_NE(vol.find("nosuch"), std::string::npos) << vol;
    EXPECT_NE(vol.find("2 of 2 clients failed"), std::string::npos) << vol;
}

} // namespace
} // namespace bc::server::test
