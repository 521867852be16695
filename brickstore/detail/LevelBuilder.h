#pragma once
// Streams one pyramid level: receives its z-slices in order, keeps a ring of the B + 2A
// slices a row of bricks reads, cuts each finished row into apron-padded bricks, and feeds
// 2x2x2-downsampled slices to the next level. Memory: (B + 2A) slices per level.
#include "brickstore/StoreLayout.h"
#include "brickstore/VoxelType.h"

#include <cstddef>
#include <cstdint>
#include <functional>
#include <vector>

namespace bc::brickstore::detail {

/// A cut brick on its way to compression.
struct BrickJob {
    std::uint64_t index = 0;       ///< position in the store's brick list
    std::vector<std::byte> voxels; ///< (B + 2A)^3, native type
};

class LevelBuilder {
  public:
    using Sink = std::function<void(BrickJob&&)>;
    /// A buffer for the next brick (one the sink's consumer is done with, or empty: one of
    /// the right size is allocated).
    using TakeBuffer = std::function<std::vector<std::byte>()>;

    LevelBuilder(const StoreLayout& layout, std::uint32_t level, VoxelType type, Sink sink,
                 LevelBuilder* next, TakeBuffer takeBuffer = {});
    /// Takes slice number `received()` of this level (dims.x * dims.y voxels).
    void pushSlice(const std::byte* slice);
    std::uint64_t received() const { return mReceived; }
    bool finished() const;

  private:
    const std::byte* slice(std::int64_t z) const;
    void cutRow(std::uint32_t bz);
    void cutBrick(std::uint32_t bx, std::uint32_t by, std::uint32_t bz, std::byte* out) const;

    const StoreLayout& mLayout;
    std::uint32_t mLevel;
    VoxelType mType;
    std::size_t mVoxelBytes;
    std::array<std::uint64_t, 3> mDims;
    std::uint32_t mRingSlices;
    std::vector<std::byte> mRing;
    std::vector<std::byte> mDown; ///< next level's slice under construction
    Sink mSink;
    LevelBuilder* mNext;
    TakeBuffer mTakeBuffer;
    std::uint64_t mReceived = 0;
    std::uint32_t mNextRow = 0;
};

} // namespace bc::brickstore::detail
