// The "auto" host budget's inputs: control group limit files parsed strictly (a file that
// says anything unexpected means no limit, never a tiny or a huge budget), and the quarter
// with its floor.
#include "brickstore/HostMemory.h"

#include <gtest/gtest.h>

#include <cstdlib>
#include <string>
#include <utility>
#include <vector>

using bc::brickstore::autoHostBudgetBytes;
using bc::brickstore::HostMemory;
using bc::brickstore::kMinAutoHostBudgetBytes;
using bc::brickstore::parseCgroupLimit;

TEST(HostMemoryTest, CgroupLimitFilesParseToBytesOrNoLimit) {
    EXPECT_EQ(parseCgroupLimit("2147483648\n"), 2147483648u);
    EXPECT_EQ(parseCgroupLimit("4096"), 4096u);
    EXPECT_EQ(parseCgroupLimit("max\n"), std::nullopt) << "cgroup v2: no limit";
    EXPECT_EQ(parseCgroupLimit("9223372036854771712\n"), std::nullopt) << "cgroup v1: no limit";
    EXPECT_EQ(parseCgroupLimit(""), std::nullopt);
    EXPECT_EQ(parseCgroupLimit("0\n"), std::nullopt);
    EXPECT_EQ(parseCgroupLimit("-1\n"), std::nullopt);
    EXPECT_EQ(parseCgroupLimit("12 34\n"), std::nullopt);
    EXPECT_EQ(parseCgroupLimit("1k\n"), std::nullopt);
    EXPECT_EQ(parseCgroupLimit("99999999999999999999999\n"), std::nullopt) << "overflows";
}

TEST(HostMemoryTest, UsableIsTheLowerOfPhysicalAndTheLimit) {
    HostMemory m;
    m.physicalBytes = 8ull << 30;
    EXPECT_EQ(m.usableBytes(), 8ull << 30);
    m.cgroupLimitBytes = 2ull << 30;
    EXPECT_EQ(m.usableBytes(), 2ull << 30);
    m.cgroupLimitBytes = 64ull << 30;
    EXPECT_EQ(m.usableBytes(), 8ull << 30);
    m.physicalBytes = 0;
    EXPECT_EQ(m.usableBytes(), 64ull << 30);
    m.localRanks = 4;
    EXPECT_EQ(m.perProcessBytes(), 16ull << 30) << "an MPI job's ranks on one machine share it";
}

TEST(HostMemoryTest, AutoBudgetIsAQuarterInWholeMiBWithAFloor) {
    EXPECT_EQ(autoHostBudgetBytes(24ull << 30), 6ull << 30);
    EXPECT_EQ(autoHostBudgetBytes((4ull << 30) + 5), 1ull << 30) << "rounded down to a MiB";
    EXPECT_EQ(autoHostBudgetBytes(512ull << 20), kMinAutoHostBudgetBytes);
    EXPECT_EQ(autoHostBudgetBytes(0), kMinAutoHostBudgetBytes) << "memory unknown";
}

// mpirun tells each rank how many of the job's ranks share its machine; each then takes its
// part of the machine. A value that does not parse is one rank, never a division by zero.
TEST(HostMemoryTest, AnMpiJobsRanksOnOneMachineShareIt) {
    const char* saved = std::getenv("OMPI_COMM_WORLD_LOCAL_SIZE");
    const std::string keep = saved ? saved : "";
    for (const auto& [text, ranks] : std::vector<std::pair<const char*, std::uint32_t>>{
             {"4", 4}, {"1", 1}, {"0", 1}, {"-2", 1}, {"4x", 1}, {"", 1}, {"5000", 1}}) {
        ::setenv("OMPI_COMM_WORLD_LOCAL_SIZE", text, 1);
        EXPECT_EQ(bc::brickstore::hostMemory().localRanks, ranks) << "'" << text << "'";
    }
    if (saved)
        ::setenv("OMPI_COMM_WORLD_LOCAL_SIZE", keep.c_str(), 1);
    else
        ::unsetenv("OMPI_COMM_WORLD_LOCAL_SIZE");
}

TEST(HostMemoryTest, ThisMachineReportsItsMemory) {
    const HostMemory m = bc::brickstore::hostMemory();
    EXPECT_GT(m.physicalBytes, 64ull << 20);
    EXPECT_GT(m.usableBytes(), 0u);
    if (m.cgroupLimitBytes) {
        EXPECT_FALSE(m.cgroupFile.empty());
    }
}
