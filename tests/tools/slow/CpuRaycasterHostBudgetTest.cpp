// The CPU raycaster under the host budget on a 2.36 GiB volume (label "slow", not run by CI): the
// shared pancreas DICOM series mosaicked 3x3x4 (1536x1536x536 i16), rendered at 512^2 by the real
// `brickcast` with --host-budget-mb 256 and 4096. The peak anonymous memory (RssAnon, polled every
// 2 ms; the mapped store is file memory and not counted) stays within the budget plus the stated
// overhead, and the images are the same bytes.
#include "tests/TestSupport.h"

#include <chrono>
#include <cstdio>
#include <fstream>
#include <sys/wait.h>
#include <thread>
#include <unistd.h>

namespace {

// Measured on this store at 512^2 with a 1 MiB budget (one brick per batch): 72 MiB = the
// process with the store's index (9 MiB), the classification's octree tables (46 MiB: 5184
// bricks x 512 leaves x 17 B), the rays' state between batches and the image (17 MiB: 52 +
// 16 B per pixel), the cache's spare buffers (at most 8 bricks, 5 MiB) and the rest; and
// the classification's cell maps (FineOccupancy's pool, at most 64 MiB: 324 MiB
// peak with --cells 0, 374-395 MiB with them at 256 MiB). Stated with room for other builds.
constexpr long kFixedOverheadMiB = 160;
// Bricks the cache evicts are reused for its next loads (CacheCore::mSpare): freed, they stayed
// in glibc's per-thread arenas, 77 to 133 MiB over budget + fixed at 256 MiB.
constexpr long kBudgetMiB = 256;

struct ProcessRun {
    int exitCode = -1;
    long peakAnonKiB = 0;
    double seconds = 0;
    std::string output;
};

long rssAnonKiB(pid_t pid) {
    std::ifstream status("/proc/" + std::to_string(pid) + "/status");
    std::string line;
    while (std::getline(status, line))
        if (line.rfind("RssAnon:", 0) == 0) return std::stol(line.substr(8));
    return 0;
}

/// Runs `args` with `env` added to the environment, polling its RssAnon until it exits.
ProcessRun run(const std::vector<std::string>& args, const std::string& logPath,
               const std::vector<std::string>& env = {}) {
    std::vector<char*> argv;
    for (const auto& a : args)
        argv.push_back(const_cast<char*>(a.c_str()));
    argv.push_back(nullptr);
    const auto t0 = std::chrono::steady_clock::now();
    std::fflush(stdout); // or the child's stdout repeats what the parent has not written yet
    const pid_t pid = ::fork();
    if (pid == 0) {
        for (const auto& e : env)
            ::putenv(const_cast<char*>(e.c_str()));
        if (!std::freopen(logPath.c_str(), "w", stdout)) ::_exit(126);
        ::dup2(::fileno(stdout), 2);
        ::execv(argv[0], argv.data());
        ::_exit(127);
    }
    ProcessRun r;
    int status = 0;
    while (::waitpid(pid, &status, WNOHANG) == 0) {
        r.peakAnonKiB = std::max(r.peakAnonKiB, rssAnonKiB(pid));
        std::this_thread::sleep_for(std::chrono::milliseconds(2));
    }
    r.exitCode = WIFEXITED(status) ? WEXITSTATUS(status) : -1;
    r.seconds = std::chrono::duration<double>(std::chrono::steady_clock::now() - t0).count();
    std::ifstream log(logPath);
    r.output.assign(std::istreambuf_iterator<char>(log), {});
    return r;
}

TEST(CpuRaycasterHostBudget, MosaicOf236GiBRendersWithinTheBudgetAndTheSameImage) {
    const std::string dicom = bc::test::dataPath("tcia_pancreas_ct_dicom");
    if (!bc::test::haveData("tcia_pancreas_ct_dicom"))
        return bc::test::missingData("tcia_pancreas_ct_dicom");
    bc::test::TempDir dir;
    const std::string exe = BC_BRICKCAST_EXE, store = dir.file("mosaic.bcs");
    const ProcessRun ingest =
        run({exe, "ingest", dicom, "--mosaic", "3,3,4", "-q", "-o", store}, dir.file("ingest.log"));
    ASSERT_EQ(ingest.exitCode, 0) << ingest.output;
    auto render = [&](long budgetMiB, const std::string& name) {
        const ProcessRun r =
            run({exe, "render", store, "-o", dir.file(name), "--renderer", "cpu", "--size",
                 "512,512", "--host-budget-mb", std::to_string(budgetMiB)},
                dir.file(name + ".log"));
        EXPECT_EQ(r.exitCode, 0) << r.output;
        std::printf("--host-budget-mb %ld: peak RssAnon %.0f MiB, %.1f s\n  %s", budgetMiB,
                    r.peakAnonKiB / 1024.0, r.seconds, r.output.c_str());
        return r;
    };
    const ProcessRun bounded = render(kBudgetMiB, "bounded.png");
    const ProcessRun unbounded = render(4096, "unbounded.png");
    EXPECT_LE(bounded.peakAnonKiB, (kBudgetMiB + kFixedOverheadMiB) << 10);
    // The unbounded frame pins every planned brick (about 2 GiB): the bound is what kept the
    // bounded one small, not the view.
    EXPECT_GT(unbounded.peakAnonKiB, 1024l << 10);
    const auto a = bc::test::readFile(dir.file("bounded.png"));
    EXPECT_FALSE(a.empty());
    EXPECT_TRUE(a == bc::test::readFile(dir.file("unbounded.png")));
}

} // namespace
