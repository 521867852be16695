#pragma once
// A volume as a stream of z-slices: the one interface every reader and generator offers to
// ingest. Slices arrive strictly in order, each once, so a reader never needs the whole
// volume in memory (gzip and zstd inputs can only be read forwards anyway).
#include "brickstore/VoxelType.h"

#include <array>
#include <cstddef>
#include <cstdint>
#include <span>
#include <string>

namespace bc::brickstore {

struct VolumeInfo {
    std::array<std::uint64_t, 3> dims{};      ///< voxels along x, y, z
    VoxelType type = VoxelType::U8;           ///< native type as stored
    std::array<double, 3> spacingMm{1, 1, 1}; ///< voxel size along x, y, z
    std::array<double, 3> originMm{0, 0, 0};  ///< position of voxel (0,0,0)'s centre
    double background = 0.0;                  ///< value of regions with no data (VDB)
    /// Physical value = stored value * valueScale + valueOffset (NIfTI scl_slope/scl_inter
    /// kept beside native voxels rather than applied, so a u8 scan stays u8).
    double valueScale = 1.0;
    double valueOffset = 0.0;
    std::string description; ///< e.g. "NIfTI-1 CT_AVM.nii.gz, u8"

    std::uint64_t voxelCount() const { return dims[0] * dims[1] * dims[2]; }
    std::uint64_t sliceBytes() const { return dims[0] * dims[1] * voxelBytes(type); }
};

/// Largest edge accepted on any axis, and largest volume in bytes: no reader allocates from
/// a size beyond these, whatever a header promises.
constexpr std::uint64_t kMaxDimVoxels = 1ull << 20;
constexpr std::uint64_t kMaxVolumeBytes = 1ull << 50;

/// Checks dims (non-zero, byte size without 64-bit overflow, within the limits above) and
/// spacing (finite, positive). @throw FormatError naming `file` and the field at fault.
void validateVolumeInfo(const VolumeInfo& info, const std::string& file);

/// Sets `out` to dims[0]*dims[1]*dims[2]*bytesPerVoxel; false (out untouched) on 64-bit overflow.
bool checkedVolumeBytes(const std::array<std::uint64_t, 3>& dims, std::size_t bytesPerVoxel,
                        std::uint64_t& out);

/// Non-virtual interface: readSlices checks the arguments and keeps the slice cursor, so a
/// reader implements only readNextSlices and may rely on its arguments being in range.
class VolumeSource {
  public:
    virtual ~VolumeSource() = default;
    /// Dims, type, spacing; valid from construction on.
    virtual const VolumeInfo& info() const = 0;
    /// Reads the next `count` z-slices into `out` (x fastest, native type, host byte order,
    /// out.size() == count * info().sliceBytes()) and advances nextSlice() by `count`.
    /// @throw std::invalid_argument when out.size() != count * info().sliceBytes().
    /// @throw std::out_of_range when fewer than `count` slices remain.
    /// @throw FormatError when the input ends early or holds values it must not (NaN).
    void readSlices(std::uint64_t count, std::span<std::byte> out);
    /// Index of the slice the next readSlices call starts at (0 to info().dims[2]).
    std::uint64_t nextSlice() const { return mNextSlice; }

  protected:
    /// Reads slices nextSlice() .. nextSlice() + count - 1 into `out`, whose size readSlices
    /// has checked; nextSlice() advances only after this returns.
    virtual void readNextSlices(std::uint64_t count, std::span<std::byte> out) = 0;

  private:
    std::uint64_t mNextSlice = 0;
};

} // namespace bc::brickstore
