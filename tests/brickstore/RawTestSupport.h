#pragma once
// Shared helpers of the raw and NRRD reader tests: voxel patterns in both byte orders, whole
// volume reads as plain bytes, and the FormatError check both suites apply to bad inputs.
#include "brickstore/Error.h"
#include "brickstore/VoxelType.h"
#include "tests/TestSupport.h"
#include "tests/brickstore/VolumeTestSupport.h"

#include <gtest/gtest.h>

#include <algorithm>
#include <chrono>
#include <cstddef>
#include <cstdint>
#include <cstring>
#include <filesystem>
#include <string>
#include <vector>

namespace bc::test {

using Bytes = std::vector<std::uint8_t>;

/// Host-order bytes of a volume whose voxels differ in both bytes of multi-byte types.
inline Bytes patternVoxels(brickstore::VoxelType type, std::uint64_t count) {
    using brickstore::VoxelType;
    const std::size_t size = brickstore::voxelBytes(type);
    Bytes out(count * size);
    for (std::uint64_t i = 0; i < count; ++i) {
        std::uint8_t* p = out.data() + i * size;
        if (type == VoxelType::U8) {
            p[0] = static_cast<std::uint8_t>(i * 37 + 11);
        } else if (type == VoxelType::U16) {
            auto v = static_cast<std::uint16_t>(i * 1237 + 5);
            std::memcpy(p, &v, 2);
        } else if (type == VoxelType::I16) {
            auto v = static_cast<std::int16_t>(static_cast<std::int64_t>(i * 997) - 20000);
            std::memcpy(p, &v, 2);
        } else {
            float v = static_cast<float>(i) * 0.25f - 3.5f;
            std::memcpy(p, &v, 4);
        }
    }
    return out;
}

/// The same voxels with each one's bytes reversed (big-endian on this little-endian host).
inline Bytes swapped(const Bytes& host, brickstore::VoxelType type) {
    Bytes out = host;
    const std::size_t n = brickstore::voxelBytes(type);
    for (std::size_t i = 0; i + n <= out.size(); i += n)
        std::reverse(out.begin() + i, out.begin() + i + n);
    return out;
}

/// Reads the whole volume, `counts` slices at a time (cycling through the list), as bytes.
inline Bytes readAllBytes(brickstore::VolumeSource& source,
                          const std::vector<std::uint64_t>& counts = {1}) {
    const std::vector<std::byte> all = readAllSlices(source, counts);
    const auto* first = reinterpret_cast<const std::uint8_t*>(all.data());
    return Bytes(first, first + all.size());
}

/// Runs `f`, which must throw FormatError whose what() names the file (by its name) and
/// `field`; returns that what() (empty when nothing was thrown).
template <class F>
std::string expectFormatError(F&& f, const std::string& path, const std::string& field) {
    try {
        f();
        ADD_FAILURE() << "no FormatError for " << path << " (field " << field << ")";
    } catch (const brickstore::FormatError& e) {
        std::string what = e.what();
        std::string name = std::filesystem::path(path).filename().string();
        EXPECT_NE(what.find(name), std::string::npos) << what;
        EXPECT_NE(what.find(field), std::string::npos) << what;
        EXPECT_EQ(e.field(), field) << what;
        return what;
    }
    return {};
}

/// expectFormatError for a refusal that must come at once: `f` (opening an input whose header
/// asks for more work than its bytes back) throws within a few seconds, before any slice.
template <class F>
std::string expectRefusedAtOnce(F&& f, const std::string& path, const std::string& field) {
    const auto start = std::chrono::steady_clock::now();
    std::string what = expectFormatError(f, path, field);
    const double seconds =
        std::chrono::duration<double>(std::chrono::steady_clock::now() - start).count();
    EXPECT_LT(seconds, 3.0 * timeScale()) << what;
    return what;
}

} // namespace bc::test
