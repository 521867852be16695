#pragma once
// What the libFuzzer targets of tests/fuzz share (scripts/fuzz.sh builds and runs them): a
// private scratch folder for parsers that only take a path, file helpers, a hard failure for
// a broken property, and the seed-writing hooks (BC_FUZZ_SEED_DIR: the corpus folder the
// binary writes its seeds into at start; BC_SHARED_DATA_DIR: the real scans seeds come from).
#include <cstdint>
#include <cstdio>
#include <cstdlib>
#include <filesystem>
#include <fstream>
#include <iterator>
#include <span>
#include <string>
#include <vector>

namespace bc::fuzz {

using Bytes = std::vector<std::uint8_t>;

/// A broken property is a finding: abort, so libFuzzer keeps the input.
inline void require(bool ok, const char* what) {
    if (ok) return;
    std::fprintf(stderr, "fuzz target: %s\n", what);
    std::abort();
}

/// The folder named by an environment variable, or empty.
inline std::string envFolder(const char* name) {
    const char* value = std::getenv(name);
    return value ? std::string(value) : std::string();
}

/// A folder of this process's own, in BC_FUZZ_SCRATCH (scripts/fuzz.sh makes one under /dev/shm
/// and removes it afterwards) or else /dev/shm; removed at a normal exit (libFuzzer leaves some
/// paths with _Exit, so the script's folder is what reliably goes away).
inline const std::filesystem::path& scratchDir() {
    static const std::filesystem::path dir = [] {
        std::string parent = envFolder("BC_FUZZ_SCRATCH");
        if (parent.empty())
            parent = std::filesystem::is_directory("/dev/shm")
                         ? std::string("/dev/shm")
                         : std::filesystem::temp_directory_path().string();
        std::string pattern = parent + "/bc-fuzz-XXXXXX";
        require(mkdtemp(pattern.data()) != nullptr, "cannot make a scratch folder");
        std::atexit([] { std::filesystem::remove_all(scratchDir()); });
        return std::filesystem::path(pattern);
    }();
    return dir;
}

inline void writeFile(const std::filesystem::path& path, std::span<const std::uint8_t> bytes) {
    std::ofstream out(path, std::ios::binary | std::ios::trunc);
    out.write(reinterpret_cast<const char*>(bytes.data()), std::streamsize(bytes.size()));
    require(bool(out), "cannot write a scratch file");
}

inline Bytes readFile(const std::filesystem::path& path) {
    std::ifstream in(path, std::ios::binary);
    return Bytes(std::istreambuf_iterator<char>(in), std::istreambuf_iterator<char>());
}

/// The first `maxBytes` bytes of a file (all of it when shorter); empty when unreadable.
inline Bytes readPrefix(const std::filesystem::path& path, std::size_t maxBytes) {
    std::ifstream in(path, std::ios::binary);
    Bytes bytes(maxBytes);
    in.read(reinterpret_cast<char*>(bytes.data()), std::streamsize(maxBytes));
    bytes.resize(std::size_t(in.gcount()));
    return bytes;
}

/// The voxels of the corner box [0,cx)x[0,cy)x[0,cz) of a raw volume (x fastest, `x` by `y`
/// voxels per slice, `bytes` each) starting at `offset` in `whole`; empty when too short.
inline Bytes cropVoxels(const Bytes& whole, std::size_t offset, std::size_t x, std::size_t y,
                        std::size_t bytes, std::size_t cx, std::size_t cy, std::size_t cz) {
    Bytes out;
    for (std::size_t z = 0; z < cz; ++z)
        for (std::size_t row = 0; row < cy; ++row) {
            const std::size_t at = offset + ((z * y + row) * x) * bytes;
            if (at + cx * bytes > whole.size()) return {};
            out.insert(out.end(), whole.begin() + std::ptrdiff_t(at),
                       whole.begin() + std::ptrdiff_t(at + cx * bytes));
        }
    return out;
}

/// The real scans (../shared/data), when BC_SHARED_DATA_DIR names a folder that exists.
inline std::string sharedData() {
    std::string dir = envFolder("BC_SHARED_DATA_DIR");
    if (dir.empty() || !std::filesystem::is_directory(dir)) {
        std::fprintf(stderr, "fuzz target: no BC_SHARED_DATA_DIR; seeds from scans skipped\n");
        return {};
    }
    return dir;
}

/// Writes seed `name` into the corpus folder `dir`.
inline void writeSeed(const std::string& dir, const std::string& name,
                      std::span<const std::uint8_t> bytes) {
    writeFile(std::filesystem::path(dir) / ("seed-" + name), bytes);
}

inline Bytes textBytes(const std::string& text) {
    return Bytes(text.begin(), text.end());
}

} // namespace bc::fuzz
