// Issue 16: the input limits of VolumeSource.h and ingest's memory budget, checked before
// anything is allocated.
#include "brickstore/Error.h"
#include "brickstore/Ingest.h"
#include "brickstore/Readers.h"
#include "tests/TestSupport.h"

#include <filesystem>
#include <string>

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

} // namespace
} // namespace bc::brickstore
