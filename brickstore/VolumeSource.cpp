#include "brickstore/VolumeSource.h"

#include "brickstore/Error.h"

#include <atomic>
#include <cmath>
#include <cstdio>
#include <limits>
#include <stdexcept>

namespace bc::brickstore {

bool checkedVolumeBytes(const std::array<std::uint64_t, 3>& dims, std::size_t bytesPerVoxel,
                        std::uint64_t& out) {
    std::uint64_t total = bytesPerVoxel;
    for (std::uint64_t d : dims) {
        if (d != 0 && total > std::numeric_limits<std::uint64_t>::max() / d) return false;
        total *= d;
    }
    out = total;
    return true;
}

std::string dimsText(const std::array<std::uint64_t, 3>& dims) {
    return std::to_string(dims[0]) + "x" + std::to_string(dims[1]) + "x" + std::to_string(dims[2]);
}

std::string bytesText(double bytes) {
    static const char* kUnits[] = {"bytes", "kB", "MB", "GB", "TB", "PB", "EB"};
    int unit = 0;
    while (bytes >= 1000.0 && unit < 6) {
        bytes /= 1000.0;
        ++unit;
    }
    char text[32];
    std::snprintf(text, sizeof text, unit == 0 ? "%.0f %s" : "%.1f %s", bytes, kUnits[unit]);
    return text;
}

namespace {

const char* kAxis[3] = {"x", "y", "z"};

std::atomic<std::uint64_t> gMaxVolumeBytes{InputLimits{}.maxVolumeBytes};
std::atomic<std::uint64_t> gMaxExpansion{InputLimits{}.maxExpansion};
std::atomic<std::uint64_t> gMaxChunks{InputLimits{}.maxChunks};

std::uint64_t volumeBytes(const VolumeInfo& info) {
    return info.voxelCount() * voxelBytes(info.type); // within kMaxVolumeBytes: validated
}

/// "1024x1024x1048576 u8 (1.1 TB)": a volume as the limits' errors name it.
std::string volumeText(const VolumeInfo& info) {
    return dimsText(info.dims) + " " + std::string(voxelTypeName(info.type)) + " (" +
           bytesText(double(volumeBytes(info))) + ")";
}

/// Dims within the edge, slice and volume limits (bytes computed without overflow).
void checkDims(const VolumeInfo& info, const std::string& file, const std::string& field) {
    const std::string dims = dimsText(info.dims);
    for (int a = 0; a < 3; ++a) {
        if (info.dims[a] == 0)
            throw FormatError(file, field, dims + ": dimension " + kAxis[a] + " is zero");
    }
    for (int a = 0; a < 3; ++a) {
        if (info.dims[a] > kMaxDimVoxels)
            throw FormatError(file, field,
                              dims + ": dimension " + kAxis[a] + " = " +
                                  std::to_string(info.dims[a]) + " exceeds the limit of " +
                                  std::to_string(kMaxDimVoxels) + " voxels per edge");
    }
    // Each edge is at most 2^20, so the products below cannot overflow.
    const std::uint64_t slice = info.dims[0] * info.dims[1];
    if (slice > kMaxSliceVoxels)
        throw FormatError(file, field,
                          dims + ": a slice of " + std::to_string(slice) +
                              " voxels exceeds the limit of " + std::to_string(kMaxSliceVoxels) +
                              " voxels (32768 x 32768)");
    const std::uint64_t voxels = slice * info.dims[2];
    if (voxels > kMaxVolumeVoxels)
        throw FormatError(file, field,
                          dims + ": " + std::to_string(voxels) + " voxels exceed the limit of " +
                              std::to_string(kMaxVolumeVoxels) + " voxels (2^42)");
    std::uint64_t bytes = 0;
    if (!checkedVolumeBytes(info.dims, voxelBytes(info.type), bytes) || bytes > kMaxVolumeBytes)
        throw FormatError(file, field, dims + ": the volume's bytes exceed the limit of 1 PiB");
    const std::uint64_t limit = gMaxVolumeBytes.load();
    if (bytes > limit)
        throw FormatError(file, field,
                          dims + " " + std::string(voxelTypeName(info.type)) + ": " +
                              bytesText(double(bytes)) + " of voxels exceed the limit of " +
                              bytesText(double(limit)) + " a volume may hold (--max-volume-gb)");
}

} // namespace

void validateVolumeInfo(const VolumeInfo& info, const std::string& file,
                        const std::string& dimsField) {
    checkDims(info, file, dimsField);
    for (int a = 0; a < 3; ++a) {
        double s = info.spacingMm[a];
        if (!std::isfinite(s) || s <= 0.0)
            throw FormatError(file, "spacing",
                              std::string("spacing along ") + kAxis[a] + " is " +
                                  std::to_string(s) + "; it must be finite and positive");
    }
}

void setInputLimits(const InputLimits& limits) {
    if (limits.maxVolumeBytes == 0 || limits.maxVolumeBytes > kMaxVolumeBytes)
        throw std::invalid_argument("maxVolumeBytes must be 1 byte to 1 PiB");
    if (limits.maxExpansion == 0 || limits.maxChunks == 0)
        throw std::invalid_argument("maxExpansion and maxChunks must be at least 1");
    gMaxVolumeBytes = limits.maxVolumeBytes;
    gMaxExpansion = limits.maxExpansion;
    gMaxChunks = limits.maxChunks;
}

InputLimits inputLimits() {
    return {gMaxVolumeBytes.load(), gMaxExpansion.load(), gMaxChunks.load()};
}

void checkInputHolds(const VolumeInfo& info, std::uint64_t inputBytes,
                     const std::string& inputWords, const std::string& file,
                     const std::string& field) {
    const std::uint64_t declared = volumeBytes(info), ratio = gMaxExpansion.load();
    // inputBytes * ratio >= declared, without overflow.
    if (declared <= kExpansionFreeBytes || inputBytes >= (declared + ratio - 1) / ratio) return;
    throw FormatError(file, field,
                      volumeText(info) + " declared, but " + inputWords + " hold only " +
                          bytesText(double(inputBytes)) + ", under 1/" + std::to_string(ratio) +
                          " of it: the header declares voxels the input does not hold (a "
                          "volume over " +
                          bytesText(double(kExpansionFreeBytes)) + " may expand " +
                          std::to_string(ratio) +
                          " times its input at most; --max-expansion raises that for a "
                          "volume truly this sparse)");
}

void checkChunkCount(const VolumeInfo& info, const std::array<std::uint64_t, 3>& chunkDims,
                     const std::string& file, const std::string& field) {
    std::uint64_t chunks = 1; // at most 2^42: each count is at most its axis's dims
    for (int a = 0; a < 3; ++a)
        chunks *= (info.dims[a] + chunkDims[a] - 1) / chunkDims[a];
    const std::uint64_t limit = gMaxChunks.load();
    if (chunks <= limit) return;
    throw FormatError(file, field,
                      dimsText(info.dims) + " voxels in chunks of " + dimsText(chunkDims) +
                          " make " + std::to_string(chunks) + " chunks, over the limit of " +
                          std::to_string(limit) +
                          ": each is looked up whether stored or not (--max-chunks raises the "
                          "limit for a store truly this finely chunked)");
}

void checkCompressedPayload(const VolumeInfo& info, std::uint64_t declaredBytes,
                            std::uint64_t payloadBytes, const char* codec, std::uint64_t maxRatio,
                            const std::string& file, const std::string& dimsField) {
    // payloadBytes * maxRatio >= declaredBytes, without overflow.
    if (payloadBytes >= (declaredBytes + maxRatio - 1) / maxRatio)
        return checkInputHolds(info, payloadBytes, std::string(codec) + " data", file, dimsField);
    throw FormatError(file, dimsField,
                      dimsText(info.dims) + " " + std::string(voxelTypeName(info.type)) +
                          " voxels need " + bytesText(double(declaredBytes)) + ", but " +
                          bytesText(double(payloadBytes)) + " of " + codec +
                          " data expand to at most " +
                          bytesText(double(payloadBytes) * double(maxRatio)) + " (" + codec +
                          " expands at most " + std::to_string(maxRatio) +
                          ":1); the header's dims are wrong or the file is truncated");
}

void VolumeSource::readSlices(std::uint64_t count, std::span<std::byte> out) {
    const VolumeInfo& volume = info();
    if (out.size() != count * volume.sliceBytes())
        throw std::invalid_argument("readSlices: a buffer of " + std::to_string(out.size()) +
                                    " bytes for " + std::to_string(count) + " slices of " +
                                    std::to_string(volume.sliceBytes()) + " bytes of " +
                                    volume.description);
    if (count > volume.dims[2] - mNextSlice)
        throw std::out_of_range("readSlices: " + std::to_string(count) + " slices from slice " +
                                std::to_string(mNextSlice) + " read past the last slice of " +
                                volume.description);
    readNextSlices(count, out);
    mNextSlice += count;
}

} // namespace bc::brickstore
