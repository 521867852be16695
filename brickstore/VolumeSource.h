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

/// Input limits: the one place they live. No reader allocates from a size a file declares
/// before these, the file-size checks of its reader and ingest's memory budget (Ingest.h) have
/// passed. docs/guide/formats.md "Limits" and `brickcast ingest --help` list them.
constexpr std::uint64_t kMaxDimVoxels = 1ull << 20;    ///< any one edge
constexpr std::uint64_t kMaxSliceVoxels = 1ull << 30;  ///< x*y of a slice (32768 x 32768)
constexpr std::uint64_t kMaxVolumeVoxels = 1ull << 42; ///< x*y*z (about 4.4 T voxels)
constexpr std::uint64_t kMaxVolumeBytes = 1ull << 50;  ///< x*y*z*voxel bytes (1 PiB)
/// Largest expansion of the compressed inputs: deflate (gzip) at most 1032:1; zstd at most one
/// 128 KiB block from a 4-byte RLE block, 32768:1. A payload that would have to expand more
/// to fill the declared dims cannot hold them.
constexpr std::uint64_t kMaxGzipRatio = 1032;
constexpr std::uint64_t kMaxZstdRatio = 32768;
/// A volume up to this size is read whatever its input holds: that little work bounds itself.
constexpr std::uint64_t kExpansionFreeBytes = 64ull << 20;

/// The limits on what an input's header may ask of ingest that a user may set (the command
/// line's --max-volume-gb, --max-expansion, --max-chunks). A header is checked against them
/// when its reader opens it, before any slice is read: a few bytes of header must not buy
/// hours of ingest.
struct InputLimits {
    /// Most bytes of voxels a volume may hold (x*y*z*voxel bytes); at most kMaxVolumeBytes.
    std::uint64_t maxVolumeBytes = kMaxVolumeBytes;
    /// Most bytes of voxels a volume larger than kExpansionFreeBytes may declare per byte its
    /// input holds (chunk files present, an HDF5 dataset's allocated storage, the files of a
    /// TIFF, DICOM or VDB volume, compressed payloads). The default is the most any codec read
    /// here expands (zstd, kMaxZstdRatio): past it, voxels cannot all be stored, however well
    /// compressed, and the rest is chunks never written. Scans compress 2-20:1, sparse label
    /// maps some hundreds, a sparse store with whole chunks missing thousands; a header of a
    /// kilobyte declaring a terabyte, a hundred million.
    std::uint64_t maxExpansion = kMaxZstdRatio;
    /// Most chunks a chunked input (Zarr, HDF5) may declare: each costs a look-up (a file, an
    /// index entry) whether or not it is stored, so one-voxel chunks make hours of a tiny
    /// store. 2^20 holds a terabyte in chunks of a MiB, the size Zarr's guides advise.
    std::uint64_t maxChunks = 1ull << 20;
};
/// Sets the limits of later reader opens and validateVolumeInfo calls (process-wide, as
/// setParserSandboxLimits; a sandboxed reader's child inherits them).
/// @throw std::invalid_argument for a zero limit or maxVolumeBytes above kMaxVolumeBytes.
void setInputLimits(const InputLimits& limits);
InputLimits inputLimits();

/// Checks dims (non-zero, byte size without 64-bit overflow, within the limits above and
/// inputLimits().maxVolumeBytes) and spacing (finite, positive). `dimsField` names the header
/// field the dims came from ("dim[1..3]", "Rows/Columns").
/// @throw FormatError naming `file` and the field at fault.
void validateVolumeInfo(const VolumeInfo& info, const std::string& file,
                        const std::string& dimsField = "dims");

/// Checks that `payloadBytes` of `codec` data ("gzip", "zstd") can expand to the
/// `declaredBytes` the header promises, given the codec's largest ratio `maxRatio`, and that
/// the input holds them within inputLimits().maxExpansion (checkInputHolds).
/// @throw FormatError(file, dimsField) saying both sizes and the ratio.
void checkCompressedPayload(const VolumeInfo& info, std::uint64_t declaredBytes,
                            std::uint64_t payloadBytes, const char* codec, std::uint64_t maxRatio,
                            const std::string& file, const std::string& dimsField = "dims");

/// Checks that `inputBytes`, what the input holds of the volume (`inputWords` says what, as
/// errors name it: "the array's chunk files"), back the voxels `info` declares: a volume
/// above kExpansionFreeBytes may declare at most inputLimits().maxExpansion times them.
/// @throw FormatError(file, field) naming both sizes, the limit and how to raise it.
void checkInputHolds(const VolumeInfo& info, std::uint64_t inputBytes,
                     const std::string& inputWords, const std::string& file,
                     const std::string& field);

/// Checks the number of chunks a chunked input declares against inputLimits().maxChunks.
/// `chunkDims` is a chunk's extent (x, y, z). @throw FormatError(file, field) naming the count.
void checkChunkCount(const VolumeInfo& info, const std::array<std::uint64_t, 3>& chunkDims,
                     const std::string& file, const std::string& field);

/// "32767x32767x32767": dims as messages write them.
std::string dimsText(const std::array<std::uint64_t, 3>& dims);
/// "70.4 GB": a byte count as messages write it (decimal units).
std::string bytesText(double bytes);

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
