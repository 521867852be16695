#include "brickstore/VolumeSource.h"

#include "brickstore/Error.h"

#include <cmath>
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

void validateVolumeInfo(const VolumeInfo& info, const std::string& file) {
    static const char* kAxis[3] = {"x", "y", "z"};
    for (int a = 0; a < 3; ++a) {
        if (info.dims[a] == 0)
            throw FormatError(file, "dims", std::string("dimension ") + kAxis[a] + " is zero");
    }
    std::uint64_t bytes = 0;
    if (!checkedVolumeBytes(info.dims, voxelBytes(info.type), bytes))
        throw FormatError(file, "dims", "byte size of the volume overflows 64 bits");
    for (int a = 0; a < 3; ++a) {
        if (info.dims[a] > kMaxDimVoxels)
            throw FormatError(file, "dims",
                              std::string("dimension ") + kAxis[a] + " = " +
                                  std::to_string(info.dims[a]) + " exceeds the limit of " +
                                  std::to_string(kMaxDimVoxels));
    }
    if (bytes > kMaxVolumeBytes)
        throw FormatError(file, "dims",
                          "volume of " + std::to_string(bytes) +
                              " bytes exceeds the limit of 1 PiB");
    for (int a = 0; a < 3; ++a) {
        double s = info.spacingMm[a];
        if (!std::isfinite(s) || s <= 0.0)
            throw FormatError(file, "spacing",
                              std::string("spacing along ") + kAxis[a] + " is " +
                                  std::to_string(s) + "; it must be finite and positive");
    }
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
