#pragma once
// How much memory this process may use, for budgets left to the machine ("auto"): the
// physical memory, or its control group's limit where that is lower (a container's), shared
// with the other ranks of its MPI job on the same machine.
#include <cstdint>
#include <optional>
#include <string>
#include <string_view>

namespace bc::brickstore {

struct HostMemory {
    std::uint64_t physicalBytes = 0;               ///< 0 when the system does not say
    std::optional<std::uint64_t> cgroupLimitBytes; ///< none: no limit, or no control group
    std::string cgroupFile;                        ///< the file the limit was read from, for logs
    /// Processes of one MPI job on this machine, which share it (Open MPI's
    /// OMPI_COMM_WORLD_LOCAL_SIZE, MPICH's MPI_LOCALNRANKS); 1 outside a job.
    std::uint32_t localRanks = 1;

    /// The lower of the two; 0 when neither is known.
    std::uint64_t usableBytes() const;
    /// This process's part of usableBytes(): divided among the job's local ranks.
    std::uint64_t perProcessBytes() const { return usableBytes() / localRanks; }
};

/// Reads sysconf, and the lowest memory.max of the process's control group and its ancestors
/// (cgroup v2) or memory/memory.limit_in_bytes (v1).
/// Never throws: a file that is missing or does not parse counts as no limit, an environment
/// variable that does not parse (or says over 4096) as one rank.
HostMemory hostMemory();

/// A control group memory file's text as a limit: a number of bytes, or none for "max" (v2),
/// for v1's "no limit" (a page-rounded LLONG_MAX, anything over 2^60) and for anything else.
std::optional<std::uint64_t> parseCgroupLimit(std::string_view text);

/// A host brick cache budget for a machine with this much usable memory: a quarter of it,
/// at least kMinAutoHostBudgetBytes (the machine's other users keep the rest: the page cache
/// that holds the compressed stores, the frames, other processes).
inline constexpr std::uint64_t kMinAutoHostBudgetBytes = 256ull << 20;
std::uint64_t autoHostBudgetBytes(std::uint64_t usableBytes);

} // namespace bc::brickstore
