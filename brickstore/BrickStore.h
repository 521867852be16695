#pragma once
// Read side of a brick store (layout in FORMAT.md): opens and validates the file, reads and
// verifies bricks and their leaf summaries. Thread-safe for concurrent reads.
#include "brickstore/StoreLayout.h"
#include "brickstore/VolumeSource.h"

#include <cstdint>
#include <memory>
#include <optional>
#include <span>
#include <string>
#include <vector>

namespace bc::brickstore {

/// Value range of the voxels a brick's or leaf's samples can read (payload and apron).
struct ValueRange {
    float min = 0.0f;
    float max = 0.0f;
};

/// One index entry (FORMAT.md "Brick record").
struct BrickRecord {
    std::uint64_t offset = 0; ///< file offset of the zstd frame (0 if not stored)
    std::uint32_t compressedBytes = 0;
    std::uint32_t leafBytes = 0;       ///< leaf table that follows the frame
    std::uint32_t flags = 0;           ///< kBrickStored
    ValueRange range;                  ///< min == max == value for a brick not stored
    std::uint64_t payloadChecksum = 0; ///< XXH3-64 of the compressed frame
    std::uint64_t leafChecksum = 0;    ///< XXH3-64 of the leaf table
    bool stored() const { return (flags & 1u) != 0; }
};
constexpr std::uint32_t kBrickStored = 1u;

/// Everything the header and index say about the volume.
struct StoreInfo {
    std::uint32_t formatVersion = 0; ///< FORMAT.md; 1 and 2 are read, 2 is written
    VolumeInfo volume;
    BrickGeometry geometry;
    double valueMin = 0.0;
    double valueMax = 0.0;
    std::uint64_t fileBytes = 0;
    std::uint64_t storedBricks = 0;
    std::uint64_t storedBytes = 0; ///< compressed payloads plus leaf tables
    std::vector<std::uint64_t>
        histogram; ///< level-0 voxels in equal bins over [valueMin, valueMax]
};

namespace detail {
class StoreReadFile;
}

class BrickStore {
  public:
    /// Opens and validates header and index (offsets inside the file, no overlaps, sizes
    /// within limits, checksums of header and index). Brick payloads are checked on read.
    /// @throw StoreCorrupt naming the store and what is wrong; StoreIoError if unreadable.
    static std::unique_ptr<BrickStore> open(const std::string& path);
    ~BrickStore();

    const std::string& path() const { return mPath; }
    /// Unique among the stores this process opened, never reused: what derived state (octrees,
    /// classifications) is keyed by, where an address or a path could name another store.
    std::uint64_t instance() const { return mInstance; }
    const StoreInfo& info() const { return mInfo; }
    const StoreLayout& layout() const { return *mLayout; }
    const BrickRecord& record(const BrickKey& key) const;
    /// Bricks of `level` stored in the file (those not stored are of one value: a cache never
    /// holds them); 0 past the last level.
    std::uint64_t storedBricks(std::uint32_t level) const;
    /// What changed between the file opened and the one at path() now ("replaced by another
    /// file", "size A -> B bytes", "modified", "rewritten in place..." when only the inode's
    /// change time moved, "gone: ..."); nullopt when it is the same file, unchanged. One stat;
    /// what a reload asks before reopening a store. Without `changeTime`, a moved change time
    /// alone (a chmod as well as a rewrite that kept the modification time) is no change.
    std::optional<std::string> fileChange(bool changeTime = true) const;
    /// Bytes of one decompressed brick ((B+2A)^3 voxels).
    std::uint64_t brickBytes() const;

    /// Decompresses brick `key` into `out` (brickBytes() long); a brick not stored is filled
    /// with its constant value. @throw StoreCorrupt naming the brick on a checksum or
    /// decompression failure (other bricks stay readable), or naming the store and what
    /// changed when the file changed size or was modified since open; StoreIoError on a read
    /// error or short read. Reads with pread: a store truncated while open is an error here,
    /// never a SIGBUS.
    void readBrick(const BrickKey& key, std::span<std::byte> out) const;
    /// Per-leaf value ranges (leafCount() entries, x fastest), checksum verified, without
    /// touching voxels. A version-2 store keeps only the leaves inside the volume; the others
    /// are filled from the nearest one inside (detail::expandLeafTable). @throw StoreCorrupt naming
    /// the brick, or the store when it changed since open; StoreIoError on a short read.
    std::vector<ValueRange> leafRanges(const BrickKey& key) const;

    /// Full scrub of every brick and leaf table on `threads` workers (0 = all cores).
    /// Returns one line per fault, naming the brick; empty when the store is sound.
    std::vector<std::string> verify(unsigned threads = 0) const;

  private:
    BrickStore() = default;
    std::string mPath;
    std::uint64_t mInstance = 0;
    StoreInfo mInfo;
    std::unique_ptr<StoreLayout> mLayout;
    std::vector<BrickRecord> mRecords;
    std::vector<std::uint64_t> mStoredPerLevel;
    std::unique_ptr<detail::StoreReadFile> mFile;
};

} // namespace bc::brickstore
