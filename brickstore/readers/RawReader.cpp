// Headerless raw volumes, plain or zstd-compressed (the streams are in detail/RawStream.cpp).
// The file size, or the zstd frame's declared size, is checked against dims x type first.
#include "brickstore/Error.h"
#include "brickstore/Readers.h"
#include "brickstore/detail/RegularFile.h"
#include "brickstore/readers/detail/RawStream.h"

#include <algorithm>
#include <array>
#include <bit>
#include <cerrno>
#include <cmath>
#include <cstdio>
#include <cstring>
#include <filesystem>
#include <limits>
#include <new>
#include <stdexcept>
#include <vector>

#include <sys/types.h>

namespace bc::brickstore {

namespace {

bool endsWith(const std::string& s, const std::string& suffix) {
    return s.size() >= suffix.size() &&
           s.compare(s.size() - suffix.size(), suffix.size(), suffix) == 0;
}

std::string describeRaw(const std::string& path, const RawLayout& layout, bool zstd) {
    std::string d = "raw " + std::filesystem::path(path).filename().string() + ", " +
                    std::string(voxelTypeName(layout.type));
    if (voxelBytes(layout.type) > 1)
        d += layout.endian == Endian::Big ? ", big-endian" : ", little-endian";
    return zstd ? d + ", zstd" : d;
}

} // namespace

std::unique_ptr<VolumeSource> openRaw(const std::string& path, const RawLayout& layout) {
    detail::requireRegularFile(path); // a pipe never was an input: its size is checked first
    VolumeInfo info;
    info.dims = layout.dims;
    info.type = layout.type;
    info.spacingMm = layout.spacingMm;
    validateVolumeInfo(info, path);
    const bool zstd = endsWith(path, ".zst");
    info.description = describeRaw(path, layout, zstd);
    const std::uint64_t expected = info.voxelCount() * voxelBytes(info.type);
    const std::string claim = "dims " + std::to_string(info.dims[0]) + "x" +
                              std::to_string(info.dims[1]) + "x" + std::to_string(info.dims[2]) +
                              " of " + std::string(voxelTypeName(info.type)) + " promise";
    auto file = detail::openFileStream(path, 0);
    if (!zstd) {
        std::uint64_t held = detail::fileBytes(path);
        if (held != expected)
            throw FormatError(path, "size",
                              claim + " " + std::to_string(expected) + " bytes, file holds " +
                                  std::to_string(held));
        return detail::makeRawVoxelSource(std::move(file), info, layout.endian, path, claim);
    }
    // The frames' declared sizes, summed, must be the volume's; where a frame declares none,
    // the file must at least be large enough for zstd's largest expansion.
    const detail::ZstdFrames frames = detail::zstdFrames(path);
    if (frames.contentBytes && *frames.contentBytes != expected)
        throw FormatError(path, "size",
                          claim + " " + std::to_string(expected) +
                              " bytes, the zstd frames declare " +
                              std::to_string(*frames.contentBytes));
    checkCompressedPayload(info, expected, frames.fileBytes, "zstd", kMaxZstdRatio, path);
    return detail::makeRawVoxelSource(detail::openZstdStream(std::move(file), path), info,
                                      layout.endian, path, claim);
}

} // namespace bc::brickstore
