#pragma once
// Voxel arithmetic on one stored brick or slice, per native type: value ranges, leaf
// summaries, constant detection, 2x2x2 downsampling. Shared by ingest and verify so that a
// scrub recomputes summaries exactly as they were written.
#include "brickstore/BrickStore.h"

#include <array>
#include <cstddef>
#include <cstdint>
#include <span>
#include <vector>

namespace bc::brickstore::detail {

/// True when all `count` voxels of `data` are bitwise equal.
bool isConstant(std::span<const std::byte> data, std::size_t voxelBytes);

/// Min/max over all voxels of a stored brick.
ValueRange brickRange(VoxelType type, std::span<const std::byte> brick);

/// Per-leaf ranges of a stored brick (FORMAT.md "Leaf table"), x fastest: every leaf.
std::vector<ValueRange> leafRanges(VoxelType type, std::span<const std::byte> brick,
                                   const BrickGeometry& geometry);
/// The same for the first `inside` leaves along each axis only (StoreLayout::leavesInside:
/// the leaves a version-2 store keeps), in the same order; reads only the voxels their
/// windows cover. @throw std::invalid_argument on 0 or more than ⌈B/L⌉ leaves on an axis.
std::vector<ValueRange> leafRanges(VoxelType type, std::span<const std::byte> brick,
                                   const BrickGeometry& geometry,
                                   const std::array<std::uint32_t, 3>& inside);

/// A full n³ table from a clipped one: a leaf outside the volume takes the range of the
/// nearest leaf inside (index clamped per axis). That range contains the outside leaf's own
/// (its window reads clamped copies of voxels the inside leaf's window reads), so skipping
/// by it stays conservative; and no sample lies outside the volume.
/// @throw std::invalid_argument when `clipped` is not inside[0]·inside[1]·inside[2] long.
std::vector<ValueRange> expandLeafTable(std::span<const ValueRange> clipped, std::uint32_t n,
                                        const std::array<std::uint32_t, 3>& inside);

/// Leaf table bytes (min f32, max f32 per leaf).
std::vector<std::byte> encodeLeafTable(std::span<const ValueRange> leaves);
std::vector<ValueRange> decodeLeafTable(std::span<const std::byte> bytes);

/// One slice of the next pyramid level from slices z0 and z1 (equal at an odd end) of
/// this one: 2x2x2 means, clamped at odd x/y edges, integers rounded half up.
void downsampleSlices(VoxelType type, const std::byte* z0, const std::byte* z1, std::uint64_t dimX,
                      std::uint64_t dimY, std::byte* out);

/// Fills `out` with `value` converted to the native type.
void fillConstant(VoxelType type, double value, std::span<std::byte> out);

/// Counts voxels into `bins` equal bins over [lo, hi] (8/16-bit types through a table).
class HistogramBinner {
  public:
    HistogramBinner(VoxelType type, double lo, double hi, std::size_t bins);
    /// Adds the voxels of box [origin, origin+extent) of a stored brick of edge `edge`.
    void add(std::span<const std::byte> brick, std::uint32_t edge,
             const std::array<std::uint32_t, 3>& origin, const std::array<std::uint64_t, 3>& extent,
             std::span<std::uint64_t> counts) const;

    /// Adds counts per raw value (countsValues types: `valueCounts[v]` voxels of the value
    /// whose bits, read as unsigned, are v), exactly as add() would have binned them.
    void addValueCounts(std::span<const std::uint64_t> valueCounts,
                        std::span<std::uint64_t> counts) const;

  private:
    VoxelType mType;
    double mLo, mHi;
    std::size_t mBins;
    std::vector<std::uint32_t> mTable;
};

/// Whether voxels of `type` can be counted per value before the histogram's range is known
/// (8- and 16-bit integers: 2^8 or 2^16 counters), which lets ingest count them as it
/// compresses instead of decompressing every brick again.
bool countsValues(VoxelType type);
/// The number of counters countValues() takes for `type` (0 unless countsValues).
std::size_t valueCountSize(VoxelType type);
/// Counts the voxels of box [origin, origin+extent) of a stored brick of edge `edge` per raw
/// value into `valueCounts` (valueCountSize(type) long).
void countValues(VoxelType type, std::span<const std::byte> brick, std::uint32_t edge,
                 const std::array<std::uint32_t, 3>& origin,
                 const std::array<std::uint64_t, 3>& extent, std::span<std::uint64_t> valueCounts);

/// The histogram bin of `value` (clamped into range).
std::size_t histogramBin(double value, double lo, double hi, std::size_t binCount);

} // namespace bc::brickstore::detail
