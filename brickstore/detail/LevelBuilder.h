#pragma once
// Streams one pyramid level: receives its z-slices in order into a ring, hands each finished
// row of bricks to the compression workers as cut jobs, and feeds 2x2x2-downsampled slices to
// the next level. The workers cut their bricks (apron-padded) straight from the ring while the
// reading thread fills the next row: the ring holds the B + 2A slices a row reads and `extra`
// more (pipelinedExtra(): B at level 0, B/2 below), so that filling a row never waits for the row
// before it, only for the one before that (pushSlice blocks until the slices it would overwrite
// have been cut; with no extra slices the reader waits for each row to be cut before it fills the
// next). Memory: min(B + 2A + extra, depth) slices per level.
#include "brickstore/StoreLayout.h"
#include "brickstore/VoxelType.h"

#include <condition_variable>
#include <cstddef>
#include <cstdint>
#include <functional>
#include <mutex>
#include <vector>

namespace bc::brickstore::detail {

class LevelBuilder;

/// A brick of a finished row, to be cut from its level's ring and compressed.
struct BrickJob {
    LevelBuilder* level = nullptr;
    std::uint64_t index = 0; ///< position in the store's brick list
    std::uint32_t bx = 0, by = 0, bz = 0;
};

class LevelBuilder {
  public:
    using Sink = std::function<void(BrickJob&&)>;

    /// The ring's slices for `layout`'s level `level` with `extra` slices past a row's.
    static std::uint64_t ringSlices(const StoreLayout& layout, std::uint32_t level,
                                    std::uint64_t extra);
    /// The extra slices that keep level `level`'s reader from waiting on the row before: B at
    /// level 0; B/2 further down, where a row's slices arrive at half the rate (two of the
    /// level above per slice) and its small row of jobs is queued ahead of the level above's
    /// next row, so it is cut by the time the reader needs its slots.
    static std::uint64_t pipelinedExtra(const StoreLayout& layout, std::uint32_t level);

    LevelBuilder(const StoreLayout& layout, std::uint32_t level, VoxelType type, Sink sink,
                 LevelBuilder* next, std::uint64_t extraSlices);
    /// Takes slice number `received()` of this level (dims.x * dims.y voxels). Blocks while
    /// the ring slot it goes to still has bricks to be cut from it; returns at once, dropping
    /// the slice, after abort().
    void pushSlice(const std::byte* slice);
    std::uint64_t received() const { return mReceived; }
    bool finished() const;

    /// Cuts `job`'s brick ((B + 2A)^3 voxels, native type) into `out`; called by any thread,
    /// once per job. Once the last brick of a row is cut its ring slots may be overwritten.
    void cut(const BrickJob& job, std::byte* out);
    /// Wakes and releases a pushSlice waiting for cuts that will not come (a worker failed).
    void abort();
    /// Seconds pushSlice has waited for ring slots to be cut free (the pushing thread's).
    double waitedSeconds() const { return 1e-9 * double(mWaitedNs); }

  private:
    const std::byte* slice(std::int64_t z) const;
    void emitRow(std::uint32_t bz);
    /// Waits until rows [0, row] are cut; false after abort().
    bool waitForRowsCut(std::uint32_t row);
    void cutBrick(std::uint32_t bx, std::uint32_t by, std::uint32_t bz, std::byte* out) const;

    const StoreLayout& mLayout;
    std::uint32_t mLevel;
    VoxelType mType;
    std::size_t mVoxelBytes;
    std::array<std::uint64_t, 3> mDims;
    std::uint64_t mRingSlices;
    std::vector<std::byte> mRing;
    std::vector<std::byte> mDown; ///< next level's slice under construction
    Sink mSink;
    LevelBuilder* mNext;
    std::uint64_t mReceived = 0;
    std::uint32_t mNextRow = 0; ///< rows handed out

    std::mutex mMutex;
    std::condition_variable mRowCut;
    static constexpr std::uint32_t kNotHandedOut = ~0u;
    std::vector<std::uint32_t> mUncut; ///< per row: bricks handed out, not yet cut
    std::uint32_t mRowsCut = 0;        ///< rows [0, mRowsCut) are cut
    bool mAborted = false;
    std::uint64_t mWaitedNs = 0;
};

} // namespace bc::brickstore::detail
