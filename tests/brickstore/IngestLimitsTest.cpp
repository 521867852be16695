// The input limits of VolumeSource.h and ingest's memory budget, checked before
// anything is allocated.
#include "brickstore/Error.h"
#include "brickstore/Ingest.h"
#include "brickstore/Readers.h"
#include "tests/TestSupport.h"
#include "tests/brickstore/VolumeTestSupport.h"

#include <csignal>
#include <filesystem>
#include <stdexcept>
#include <string>

#include <sys/resource.h>
#include <sys/wait.h>
#include <unistd.h>

namespace bc::brickstore {
namespace {

VolumeInfo infoOf(std::array<std::uint64_t, 3> dims, VoxelType type = VoxelType::U8) {
    VolumeInfo info;
    info.dims = dims;
    info.type = type;
    return info;
}

/// `call` throws FormatError naming `file` and `field`, whose message holds `part`.
template <typename F>
void expectError(F&& call, const std::string& file, const std::string& field,
                 const std::string& part) {
    try {
        call();
        FAIL() << "no FormatError";
    } catch (const FormatError& e) {
        EXPECT_EQ(e.file(), file) << e.what();
        EXPECT_EQ(e.field(), field) << e.what();
        EXPECT_NE(std::string(e.what()).find(part), std::string::npos) << e.what();
    }
}

TEST(IngestLimitsTest, SliceAndVolumeLimitsAreCheckedBeforeByteSizes) {
    // Each within the edge limit and 1 PiB, but over the slice or the voxel limit.
    expectError(
        [] {
            validateVolumeInfo(infoOf({40000, 40000, 4}), "a.raw");
        },
        "a.raw", "dims", "a slice of 1600000000 voxels exceeds the limit");
    expectError(
        [] {
            validateVolumeInfo(infoOf({32768, 32768, 8192}), "b.raw");
        },
        "b.raw", "dims", "exceed the limit of 4398046511104 voxels");
    EXPECT_NO_THROW(validateVolumeInfo(infoOf({32768, 32768, 4096}), "c.raw"));
}

TEST(IngestLimitsTest, MaximumVolumeSizeIsConfigurable) {
    EXPECT_NO_THROW(validateVolumeInfo(infoOf({2048, 2048, 2048}), "a.raw"));
    InputLimits limits;
    limits.maxVolumeBytes = 1ull << 30;
    const test::InputLimitsGuard guard(limits);
    expectError(
        [] {
            validateVolumeInfo(infoOf({2048, 2048, 2048}), "a.raw");
        },
        "a.raw", "dims",
        "8.6 GB of voxels exceed the limit of 1.1 GB a volume may hold (--max-volume-gb)");
    EXPECT_NO_THROW(validateVolumeInfo(infoOf({1024, 1024, 1024}), "b.raw"));
}

TEST(IngestLimitsTest, InputLimitsOutsideTheirRangesAreRefused) {
    const InputLimits before = inputLimits();
    for (const InputLimits bad : {InputLimits{0, 1, 1}, InputLimits{kMaxVolumeBytes + 1, 1, 1},
                                  InputLimits{1, 0, 1}, InputLimits{1, 1, 0}})
        EXPECT_THROW(setInputLimits(bad), std::invalid_argument);
    EXPECT_EQ(inputLimits().maxExpansion, before.maxExpansion);
    EXPECT_EQ(inputLimits().maxChunks, before.maxChunks);
}

TEST(IngestLimitsTest, MemoryEstimateCoversTheSlabRingsOfEveryLevel) {
    IngestConfig config;
    config.threads = 1;
    const std::uint64_t small = ingestMemoryBytes(infoOf({256, 256, 256}), config);
    const std::uint64_t wide = ingestMemoryBytes(infoOf({4096, 4096, 256}), config);
    // Level 0's ring alone: 2B + 2A = 132 slices of 4096 x 4096 u8 (the B + 2A a row of
    // bricks reads, and B more that the next row fills while the workers cut it).
    EXPECT_GT(wide, 132ull * 4096 * 4096);
    EXPECT_LT(wide, 2 * 132ull * 4096 * 4096); // the coarser levels add a third, not more
    EXPECT_GT(small, 132ull * 256 * 256);
    EXPECT_LT(small, wide);
    EXPECT_GT(ingestMemoryBytes(infoOf({4096, 4096, 256}, VoxelType::F32), config), 4 * wide / 2);
}

TEST(IngestLimitsTest, IngestOverBudgetThrowsBeforeWritingAnything) {
    test::TempDir dir;
    auto source = makeSynthetic(SynthKind::Checker, {1024, 1024, 8}, 1);
    IngestConfig config;
    config.memoryBudgetBytes = 16ull << 20;
    config.inputName = "synth:checker";
    const std::string store = dir.file("s.bcs");
    expectError([&] { ingest(*source, store, config); }, "synth:checker", "dims",
                "over the ingest memory budget of 16.8 MB (--memory-budget-mb)");
    EXPECT_TRUE(std::filesystem::is_empty(dir.path()));
    // The same volume fits a budget above its estimate.
    config.memoryBudgetBytes = ingestMemoryBytes(source->info(), config) + 1;
    EXPECT_NO_THROW(ingest(*source, store, config));
}

TEST(IngestLimitsTest, DefaultBudgetIsPositiveAndBoundedByPhysicalMemory) {
    const std::uint64_t budget = defaultIngestMemoryBudgetBytes();
    EXPECT_GE(budget, 64ull << 20);
    EXPECT_LT(budget, 1ull << 50);
}

TEST(IngestLimitsTest, CancelledIngestRemovesItsPartialFile) {
    test::TempDir dir;
    auto source = makeSynthetic(SynthKind::Phantom, {64, 64, 64}, 1);
    std::atomic<bool> cancel{true};
    IngestConfig config;
    config.cancel = &cancel;
    EXPECT_THROW(ingest(*source, dir.file("c.bcs"), config), IngestCancelled);
    EXPECT_TRUE(std::filesystem::is_empty(dir.path()));
}

/// Ingests a small phantom into `store` in a child process whose files may not grow past
/// `limitBytes` (RLIMIT_FSIZE, SIGXFSZ ignored: a write past it fails with EFBIG, as one on a
/// full disk fails with ENOSPC). Returns what the ingest threw, as the child saw it.
std::string ingestWithFileSizeLimit(const std::string& store, rlim_t limitBytes) {
    int fds[2];
    if (::pipe(fds) != 0) return "pipe failed";
    const pid_t pid = ::fork();
    if (pid == 0) {
        ::close(fds[0]);
        std::string what = "no error";
        rlimit limit{};
        ::getrlimit(RLIMIT_FSIZE, &limit);
        limit.rlim_cur = limitBytes;
        std::signal(SIGXFSZ, SIG_IGN);
        try {
            if (::setrlimit(RLIMIT_FSIZE, &limit) != 0) throw std::runtime_error("setrlimit");
            auto source = makeSynthetic(SynthKind::Phantom, {128, 128, 128}, 1);
            IngestConfig config;
            config.threads = 2;
            ingest(*source, store, config);
        } catch (const StoreIoError& e) {
            what = e.what();
        } catch (const std::exception& e) {
            what = std::string("not a StoreIoError: ") + e.what();
        }
        const ssize_t written = ::write(fds[1], what.data(), what.size());
        ::_exit(written == ssize_t(what.size()) ? 0 : 1);
    }
    ::close(fds[1]);
    std::string what;
    char buffer[1024];
    for (ssize_t n; (n = ::read(fds[0], buffer, sizeof buffer)) > 0;)
        what.append(buffer, std::size_t(n));
    ::close(fds[0]);
    int status = 0;
    ::waitpid(pid, &status, 0);
    EXPECT_TRUE(WIFEXITED(status) && WEXITSTATUS(status) == 0) << status;
    return what;
}

TEST(IngestLimitsTest, FailedWriteRemovesThePartialFileAndNamesTheStore) {
    // 0: the very first write (the header's zeros) fails; 64 KiB: a worker's append does.
    for (const rlim_t limit : {rlim_t(0), rlim_t(64 << 10)}) {
        test::TempDir dir;
        const std::string store = dir.file("s.bcs");
        const std::string what = ingestWithFileSizeLimit(store, limit);
        EXPECT_EQ(what.rfind(store + ": ", 0), 0u) << what;
        EXPECT_NE(what.find("File too large"), std::string::npos) << what;
        std::string left;
        for (const auto& entry : std::filesystem::directory_iterator(dir.path()))
            left += entry.path().filename().string() + " (" + std::to_string(entry.file_size()) +
                    " bytes) ";
        EXPECT_EQ(left, "") << "limit " << limit;
    }
}

} // namespace
} // namespace bc::brickstore
