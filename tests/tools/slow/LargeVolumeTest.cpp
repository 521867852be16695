// Gigabyte ingests (label "slow", not run by CI): peak memory of an ingest must not grow with
// the volume's depth, and a 4 GiB store must verify. Runs the real `brickcast` binary and
// reads its peak RSS from the kernel (wait4).
#include "tests/TestSupport.h"

#include <chrono>
#include <cstdio>
#include <sys/resource.h>
#include <sys/wait.h>
#include <unistd.h>

namespace {

struct RunResult {
    int exitCode = -1;
    long peakRssKiB = 0;
    double seconds = 0;
};

RunResult run(const std::vector<std::string>& args) {
    std::vector<char*> argv;
    for (const auto& a : args)
        argv.push_back(const_cast<char*>(a.c_str()));
    argv.push_back(nullptr);
    auto t0 = std::chrono::steady_clock::now();
    pid_t pid = ::fork();
    if (pid == 0) {
        ::execv(argv[0], argv.data());
        ::_exit(127);
    }
    int status = 0;
    struct rusage usage {};
    ::wait4(pid, &status, 0, &usage);
    RunResult r;
    r.exitCode = WIFEXITED(status) ? WEXITSTATUS(status) : -1;
    r.peakRssKiB = usage.ru_maxrss;
    r.seconds = std::chrono::duration<double>(std::chrono::steady_clock::now() - t0).count();
    return r;
}

TEST(LargeVolumeTest, FourGiBPhantomIngestsInMemoryThatDoesNotGrowWithDepthAndVerifies) {
    bc::test::TempDir dir;
    const std::string exe = BC_BRICKCAST_EXE;
    // Same slice area, 3.2x the depth: 1.25 GiB and 4 GiB of u16 (both deeper than the ring of
    // 2B + 2A = 132 slices a level keeps, which a thinner volume does not fill).
    auto small = run({exe, "ingest", "synth:phantom", "--dims", "2048,2048,160", "-q", "-o",
                      dir.file("small.bcs")});
    ASSERT_EQ(small.exitCode, 0);
    std::filesystem::remove(dir.file("small.bcs"));
    auto large = run({exe, "ingest", "synth:phantom", "--dims", "2048,2048,512", "-q", "-o",
                      dir.file("large.bcs")});
    ASSERT_EQ(large.exitCode, 0);
    std::printf("ingest 2048x2048x160 u16 (1.25 GiB): %.1f s, peak RSS %.0f MiB\n", small.seconds,
                small.peakRssKiB / 1024.0);
    std::printf("ingest 2048x2048x512 u16 (4 GiB): %.1f s, peak RSS %.0f MiB\n", large.seconds,
                large.peakRssKiB / 1024.0);
    EXPECT_LT(double(large.peakRssKiB), 1.25 * double(small.peakRssKiB));
    auto verify = run({exe, "verify", dir.file("large.bcs")});
    std::printf("verify 4 GiB store: %.1f s, peak RSS %.0f MiB\n", verify.seconds,
                verify.peakRssKiB / 1024.0);
    EXPECT_EQ(verify.exitCode, 0);
}

} // namespace
