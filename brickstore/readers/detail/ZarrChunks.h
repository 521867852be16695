#pragma once
// The chunk files of a Zarr v2 array: opened inside the array's folder (never through a
// symlink out of the store), size-checked against the codec's bound before they are read, and
// decoded (zlib, gzip, zstd, blosc or none) to exactly one chunk's bytes (ZarrChunks.cpp).
#include "brickstore/readers/detail/ZarrMetadata.h"

#include <array>
#include <cstddef>
#include <cstdint>
#include <span>
#include <string>
#include <vector>

struct ZSTD_DCtx_s;

namespace bc::brickstore::detail {

/// An open folder; the chunk files are opened relative to it.
class ZarrFolder {
  public:
    /// @throw FormatError(array.metaFile, "path") when the folder cannot be opened.
    explicit ZarrFolder(const ZarrArray& array);
    ~ZarrFolder();
    ZarrFolder(const ZarrFolder&) = delete;
    ZarrFolder& operator=(const ZarrFolder&) = delete;
    int fd() const { return mFd; }

  private:
    int mFd = -1;
};

/// Chunk indices along z, y, x (the leading axes' indices are 0).
using ZarrChunkIndex = std::array<std::uint64_t, 3>;

/// Reads and decodes the chunks of one array. One per decoding thread: it keeps the buffer of
/// compressed bytes and a zstd context from chunk to chunk. `array` and `folder` must outlive it.
class ZarrChunkReader {
  public:
    ZarrChunkReader(const ZarrArray& array, const ZarrFolder& folder);
    ~ZarrChunkReader();
    ZarrChunkReader(const ZarrChunkReader&) = delete;
    ZarrChunkReader& operator=(const ZarrChunkReader&) = delete;

    /// Decodes the chunk at `index` into `out` (array.chunkBytes bytes, the stored byte order).
    /// Returns false, `out` untouched, when the chunk has no file (it reads as the fill value).
    /// @throw FormatError(chunk file, "chunk") when the file is larger than the codec can make
    /// of a chunk, truncated, corrupt, or decodes to other than one chunk's bytes.
    bool read(const ZarrChunkIndex& index, std::span<std::byte> out);
    /// The path of a chunk's file as errors name it.
    std::string chunkPath(const ZarrChunkIndex& index) const;

  private:
    std::string chunkKey(const ZarrChunkIndex& index) const;
    int openChunk(const std::string& key, const std::string& path) const;
    void decode(std::span<const std::byte> in, std::span<std::byte> out, const std::string& path);

    const ZarrArray& mArray;
    const ZarrFolder& mFolder;
    std::vector<std::byte> mCompressed;
    ZSTD_DCtx_s* mZstd = nullptr;
};

} // namespace bc::brickstore::detail
