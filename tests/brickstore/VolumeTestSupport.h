#pragma once
// Shared helpers of the brickstore tests that read volumes: whole-volume reads through the
// slice stream, an in-memory source, and input limits set for one test.
#include "brickstore/VolumeSource.h"

#include <algorithm>
#include <cstddef>
#include <cstdint>
#include <cstring>
#include <span>
#include <utility>
#include <vector>

namespace bc::test {

/// Sets the process's input limits (brickstore::setInputLimits) while it lives.
class InputLimitsGuard {
  public:
    explicit InputLimitsGuard(const brickstore::InputLimits& limits)
        : mSaved(brickstore::inputLimits()) {
        brickstore::setInputLimits(limits);
    }
    ~InputLimitsGuard() { brickstore::setInputLimits(mSaved); }
    InputLimitsGuard(const InputLimitsGuard&) = delete;
    InputLimitsGuard& operator=(const InputLimitsGuard&) = delete;

  private:
    brickstore::InputLimits mSaved;
};

/// Reads the whole volume, `chunkSlices[k % size]` slices at the k-th call (the list cycles;
/// a chunk is cut short at the last slice), so uneven steps exercise slab boundaries.
inline std::vector<std::byte> readAllSlices(brickstore::VolumeSource& source,
                                            const std::vector<std::uint64_t>& chunkSlices) {
    const brickstore::VolumeInfo& info = source.info();
    std::vector<std::byte> bytes(info.voxelCount() * brickstore::voxelBytes(info.type));
    std::uint64_t z = 0;
    for (std::size_t k = 0; z < info.dims[2]; ++k) {
        const std::uint64_t n = std::min(chunkSlices[k % chunkSlices.size()], info.dims[2] - z);
        source.readSlices(n,
                          std::span(bytes).subspan(z * info.sliceBytes(), n * info.sliceBytes()));
        z += n;
    }
    return bytes;
}

/// Reads the whole volume, `chunkSlices` slices at a time (the last chunk may be shorter).
inline std::vector<std::byte> readAllSlices(brickstore::VolumeSource& source,
                                            std::uint64_t chunkSlices) {
    return readAllSlices(source, std::vector<std::uint64_t>{chunkSlices});
}

/// A volume held in memory, served as a slice stream, forwards only like a file reader (the
/// test double for every reader).
class VectorSource final : public brickstore::VolumeSource {
  public:
    VectorSource(brickstore::VolumeInfo info, std::vector<std::byte> voxels)
        : mInfo(std::move(info)), mVoxels(std::move(voxels)) {}
    const brickstore::VolumeInfo& info() const override { return mInfo; }

  private:
    void readNextSlices(std::uint64_t, std::span<std::byte> out) override {
        if (out.empty()) return; // memcpy wants non-null pointers even for 0 bytes
        std::memcpy(out.data(), mVoxels.data() + nextSlice() * mInfo.sliceBytes(), out.size());
    }

    brickstore::VolumeInfo mInfo;
    std::vector<std::byte> mVoxels;
};

} // namespace bc::test
