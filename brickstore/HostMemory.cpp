#include "brickstore/HostMemory.h"
#include <algorithm>
#include <charconv>
#include <cstdlib>
#include <fstream>
#include <unistd.h>

namespace bc::brickstore {

namespace {

std::optional<std::string> readSmallFile(const std::string& path) {
    std::ifstream in(path);
    if (!in) return std::nullopt;
    std::string text(64, '\0');
    in.read(text.data(), std::streamsize(text.size()));
    text.resize(std::size_t(in.gcount()));
    return text;
}

/// `text` as a whole non-negative number (no sign, no suffix), or nullopt.
std::optional<std::uint64_t> wholeNumber(std::string_view text) {
    std::uint64_t v = 0;
    const auto [end, ec] = std::from_chars(text.data(), text.data() + text.size(), v);
    if (text.empty() || ec != std::errc() || end != text.data() + text.size()) return std::nullopt;
    return v;
}

} // namespace

std::optional<std::uint64_t> parseCgroupLimit(std::string_view text) {
    while (!text.empty() && (text.back() == '\n' || text.back() == ' '))
        text.remove_suffix(1);
    const auto bytes = wholeNumber(text);
    if (!bytes || *bytes == 0 || *bytes > (1ull << 60)) return std::nullopt;
    return bytes;
}

std::uint64_t HostMemory::usableBytes() const {
    if (!cgroupLimitBytes) return physicalBytes;
    if (physicalBytes == 0) return *cgroupLimitBytes;
    return std::min(physicalBytes, *cgroupLimitBytes);
}

namespace {

/// The process's group under one hierarchy of /proc/self/cgroup ("ID:CONTROLLERS:PATH"): v2's
/// has no controllers, v1's memory hierarchy lists "memory".
std::string cgroupPath(bool v2) {
    std::ifstream in("/proc/self/cgroup");
    std::string line;
    while (std::getline(in, line)) {
        const auto first = line.find(':'), second = line.find(':', first + 1);
        if (first == std::string::npos || second == std::string::npos) continue;
        const std::string controllers = line.substr(first + 1, second - first - 1);
        const bool match = v2 ? controllers.empty()
                              : ("," + controllers + ",").find(",memory,") != std::string::npos;
        if (match) return line.substr(second + 1);
    }
    return {};
}

/// The lowest limit of the group and its ancestors: a parent's limit holds its children too.
void readCgroupLimit(HostMemory& m, const std::string& mount, const std::string& group,
                     const char* fileName) {
    if (group.empty() || group[0] != '/') return;
    for (std::string p = group;; p = p.substr(0, std::max<std::size_t>(p.rfind('/'), 1))) {
        const std::string file = mount + (p == "/" ? std::string() : p) + "/" + fileName;
        if (auto text = readSmallFile(file))
            if (auto limit = parseCgroupLimit(*text);
                limit && (!m.cgroupLimitBytes || *limit < *m.cgroupLimitBytes)) {
                m.cgroupLimitBytes = limit;
                m.cgroupFile = file;
            }
        if (p == "/") break;
    }
}

} // namespace

HostMemory hostMemory() {
    HostMemory m;
    const long pages = sysconf(_SC_PHYS_PAGES);
    const long pageBytes = sysconf(_SC_PAGESIZE);
    if (pages > 0 && pageBytes > 0)
        m.physicalBytes = std::uint64_t(pages) * std::uint64_t(pageBytes);
    // A container sees its own group as the root of the mount; the walk covers both cases.
    readCgroupLimit(m, "/sys/fs/cgroup", cgroupPath(true), "memory.max");
    if (!m.cgroupLimitBytes)
        readCgroupLimit(m, "/sys/fs/cgroup/memory", cgroupPath(false), "memory.limit_in_bytes");
    for (const char* name : {"OMPI_COMM_WORLD_LOCAL_SIZE", "MPI_LOCALNRANKS"})
        if (const char* text = std::getenv(name)) {
            if (const auto ranks = wholeNumber(text); ranks && *ranks >= 1 && *ranks <= 4096)
                m.localRanks = std::uint32_t(*ranks);
            break;
        }
    return m;
}

std::uint64_t autoHostBudgetBytes(std::uint64_t usableBytes) {
    const std::uint64_t mib = 1ull << 20;
    return std::max(kMinAutoHostBudgetBytes, usableBytes / 4 / mib * mib);
}

} // namespace bc::brickstore
