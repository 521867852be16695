// `brickcast loadtest` against a daemon in this process: every path flown by its client, the
// frames in the CSV, the cache tiers' traffic taken from the server's counters; bad options
// named, and a server that is not loopback refused before connecting.
#include "tests/server/ServerTestSupport.h"

#include <cstdio>
#include <fstream>
#include <set>
#include <sstream>
#include <vector>

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
              "cached,refined,level,scale");
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

// Frames on a budget: clients fly in continuous mode under a frame-time target, then
// rest until a refined pass's estimate reaches the bound, and each such pass is measured
// against the true image the server draws.
TEST(LoadtestCli, AdaptiveClientsRestUntilTheBoundAndThePassIsMeasured) {
    TempDir dir;
    TestDaemon d(generatedConfig(dir, {{"lt", 48}}));
    const auto [status, out] =
        run(std::string(BC_BRICKCAST_EXE) + " loadtest --port " + std::to_string(d.port) +
            " --volume lt --paths orbit --clients 2 --frames 6 --warmup 1 --size 48,48 "
            "--quality adaptive --interactive-ms 66 --rest-psnr 40 --truth-step 0.125");
    ASSERT_EQ(status, 0) << out;
    EXPECT_NE(out.find("| orbit | 2 | 10 |"), std::string::npos) << out;
    const auto table = out.find("### Moving, then at rest under a 40 dB bound");
    ASSERT_NE(table, std::string::npos) << out;
    std::istringstream rows(out.substr(table));
    std::string line;
    int clients = 0;
    while (std::getline(rows, line)) {
        if (!line.starts_with("| 0 |") && !line.starts_with("| 1 |")) continue;
        ++clients;
        std::vector<std::string> cells;
        std::istringstream cellsIn(line.substr(1));
        for (std::string cell; std::getline(cellsIn, cell, '|');)
            cells.push_back(cell);
        ASSERT_GE(cells.size(), 8u) << line;
        EXPECT_NE(cells[5].find_first_of("0123456789"), std::string::npos)
            << "the bound was not reached: " << line;
        EXPECT_GE(std::stod(cells[6]), 40.0) << "estimate: " << line;
        EXPECT_GE(std::stod(cells[7]), 40.0) << "measured: " << line;
    }
    EXPECT_EQ(clients, 2) << out;
}

TEST(LoadtestCli, BadOptionsAndServersOffLoopbackAreNamed) {
    const std::string exe = std::string(BC_BRICKCAST_EXE) + " loadtest";
    const auto [hostStatus, host] = run(exe + " --host 10.1.2.3 --port 1");
    EXPECT_NE(hostStatus, 0);
    EXPECT_NE(host.find("--host: '10.1.2.3' is not loopback"), std::string::npos) << host;
    const auto [pathStatus, path] = run(exe + " --paths orbit,spiral --port 1");
    EXPECT_NE(pathStatus, 0);
    EXPECT_NE(path.find("'spiral'"), std::string::npos) << path;
    const auto [qualityStatus, quality] = run(exe + " --quality steady --port 1");
    EXPECT_NE(qualityStatus, 0);
    EXPECT_NE(quality.find("--quality: 'steady' is not refined, interactive or adaptive"),
              std::string::npos)
        << quality;
    for (const auto& [options, message] : std::vector<std::pair<std::string, std::string>>{
             {"--quality adaptive --rest-psnr 60", "--rest-psnr: 0 (none) or 20..50 dB"},
             {"--quality adaptive --rest-psnr 19", "--rest-psnr: 0 (none) or 20..50 dB"},
             {"--rest-psnr 40", "--rest-psnr: needs --quality adaptive"},
             {"--interactive-ms 10001", "--interactive-ms: 0..10000"},
             {"--frames 5 --warmup 5", "--warmup: fewer than --frames"},
             {"--quality adaptive --rest-psnr 40 --truth-step 0", "--truth-step: 0.01..1"}}) {
        const auto [status, text] = run(exe + " " + options + " --port 1");
        EXPECT_NE(status, 0) << options;
        EXPECT_NE(text.find(message), std::string::npos) << options << ": " << text;
    }
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
