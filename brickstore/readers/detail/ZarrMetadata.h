#pragma once
// What the JSON of a Zarr v2 store says about the one array the Zarr reader streams: the
// array's .zarray (shape, chunks, dtype, fill value, compressor, chunk key separator) and, for
// an OME-Zarr image, the .zattrs "multiscales" that pick the array of a level and give its
// spacing. Every file named by the metadata is resolved inside the store's folder first
// (ZarrMetadata.cpp).
#include "brickstore/Readers.h"
#include "brickstore/readers/detail/FolderPath.h"

#include <array>
#include <cstddef>
#include <cstdint>
#include <string>
#include <vector>

namespace bc::brickstore::detail {

/// Decoded bytes of one chunk past which an array is refused: a chunk is decoded whole, by each
/// decoding thread, so it must fit in memory many times over.
constexpr std::uint64_t kZarrMaxChunkBytes = 1ull << 30;

enum class ZarrCodec { None, Zlib, Gzip, Zstd, Blosc };

/// One Zarr v2 array, checked: 3 axes, or more whose leading ones have one element.
struct ZarrArray {
    std::string root;          ///< canonical path of the store's folder, which nothing leaves
    std::string folder;        ///< canonical path of the array's folder
    std::string displayFolder; ///< the array's folder as errors name it (the path given)
    std::string metaFile;      ///< its .zarray, named in errors about the metadata
    /// Extents and chunk extents, slowest axis first, as the .zarray lists them; the last
    /// three are z, y, x.
    std::vector<std::uint64_t> shape;
    std::vector<std::uint64_t> chunks;
    VoxelType type = VoxelType::U8;
    Endian endian = Endian::Little;
    std::array<std::byte, 4> fillValue{}; ///< one voxel of the fill value, host byte order
    ZarrCodec codec = ZarrCodec::None;
    std::string codecName;        ///< for descriptions: "zstd", "blosc/lz4"
    char separator = '.';         ///< between the chunk indices of a chunk's key
    std::uint64_t chunkBytes = 0; ///< decoded bytes of one (whole) chunk

    /// Extent of axis `a` of the volume (0 = x, 1 = y, 2 = z).
    std::uint64_t dim(int a) const { return shape[shape.size() - 1 - a]; }
    /// Chunk extent along axis `a` of the volume (0 = x, 1 = y, 2 = z).
    std::uint64_t chunkDim(int a) const { return chunks[chunks.size() - 1 - a]; }
};

/// The array a level of a store stands for, and what the volume made of it is.
struct ZarrImage {
    ZarrArray array;
    VolumeInfo info; ///< dims, type, spacing, origin and description; validated
};

/// Opens the metadata of the Zarr v2 array at `path` (a folder with .zarray), or of level
/// `level` of the OME-Zarr image at `path` (a folder whose .zattrs holds "multiscales").
/// @throw FormatError naming the metadata file and the field at fault.
ZarrImage readZarrImage(const std::string& path, std::uint32_t level);

} // namespace bc::brickstore::detail
