#pragma once
// Leaps below the octree's leaves: per brick, a chessboard distance map over cells
// of 1, 2 or 4 voxels, so that a ray in a non-empty 8-voxel leaf still leaps the empty space
// around thin structures (vessels, roots, bone surfaces) instead of sampling it step by step,
// and leaps it far in one go: a cell at distance d lies at the centre of a cube of 2d - 1
// cells on a side that holds no sample with opacity, so the ray goes on from the cube's exit.
//
// The store's summaries stop at the leaves, so the maps come from the voxels of the bricks as
// they are drawn: a cache of the classification (render/Classification.h), built per brick
// the first time a frame draws it under this transfer function and kept until the
// classification goes. The cells sit on the sampler's voxel lattice (half a voxel off the
// leaves'), so a cell of s voxels holds the samples that read exactly its (s + 1)^3 voxels; it
// is empty when the function is transparent over their whole value range (the same range
// test as the leaves': a prefix count of the visible table entries, one entry of margin on
// each side, which also covers a position rounded across a face). A leap skips only
// transparent samples and sample positions never move: images are those without maps, bit for
// bit (tests/render/FineOccupancyTest.cpp).
//
// Layout: one byte per cell, x fastest, cellsPerAxis()^3 of them: 0 where samples are taken,
// else the chessboard distance in cells to the nearest such cell (255 at most). Every brick's
// map is one slot of one pool, so the CPU raycaster's gathers address them by 32-bit offsets;
// slot 0 is no brick's (a brick without a map walks the octree). The GPU raycaster keeps a
// copy of the pool in a storage buffer, copying each slot once a frame draws its brick.
//
// Memory: the pool holds at most `budgetBytes` (default 64 MiB: 1,800 bricks of 2-voxel cells
// at 35 KiB, 240 of 1-voxel cells at 269 KiB, for 64-voxel bricks); past it further bricks get
// no map (and walk the octree, as before). A brick whose sampled leaves hold few empty cells
// (dense tissue) gets none either: its map would cost a lookup per sample and leap little.
// Maps are used only under the exact octree (ratio threshold 1, no level limit): a node drawn
// whole must keep its samples. Both raycasters leap by them (render/OCCUPANCY.md).
#include "brickstore/VoxelType.h"

#include <atomic>
#include <cstdint>
#include <memory>
#include <mutex>
#include <vector>

namespace bc::render {

class OccupancyTrees;
struct FrameStats;
struct TransferFunctionTable;

/// What building cells has cost so far.
struct FineOccupancyStats {
    std::uint64_t bricksBuilt = 0; ///< bricks whose voxels were read
    std::uint64_t bricksKept = 0;  ///< of those, the ones given a slot
    std::uint64_t bytes = 0;       ///< pool bytes in use
    double buildMs = 0;            ///< summed over the building threads
};

class FineOccupancy {
  public:
    static constexpr std::uint64_t kDefaultBudgetBytes = 64ull << 20;
    /// A brick keeps its cells only when at least this share of the cells of its sampled
    /// leaves is empty.
    static constexpr double kMinEmptyShare = 0.25;

    /// Maps over cells of `cellVoxels` (a power of two below the leaf) under `trees` (updated
    /// for `table`, the step-1 table they were built from). @throw std::invalid_argument when
    /// the cell is not a power of two below a power-of-two leaf.
    FineOccupancy(const OccupancyTrees& trees, const TransferFunctionTable& table,
                  std::uint32_t cellVoxels, std::uint64_t budgetBytes = kDefaultBudgetBytes);
    ~FineOccupancy();
    FineOccupancy(const FineOccupancy&) = delete;
    FineOccupancy& operator=(const FineOccupancy&) = delete;

    std::uint32_t cellVoxels() const { return mCell; }
    /// log2(leaf / cell).
    std::uint32_t levels() const { return mLevels; }
    /// Cells per brick axis: leaves per axis times leaf / cell, and one more (the lattice is
    /// half a voxel off the leaves').
    std::uint32_t cellsPerAxis() const { return mCellsPerAxis; }
    std::uint32_t wordsPerBrick() const { return mWordsPerBrick; }
    /// The pool: slot s is words [s * wordsPerBrick(), (s + 1) * wordsPerBrick()).
    const std::uint32_t* pool() const { return mPool.get(); }

    /// The word offset in pool() of brick `brick`'s map (an index within the level), building
    /// it from `voxels` (its stored voxels: edge^3 of `type`, x fastest, edge = brick + 2
    /// apron) the first time; 0 when it gets none. Thread-safe: a brick asked for by two
    /// threads at once is built by one, the other waits.
    std::uint32_t offsetOf(std::uint64_t brick, const void* voxels, brickstore::VoxelType type,
                           int brickVoxels, int apronVoxels);

    /// Brick `brick`'s offset as offsetOf() returned it, or -1 while it is not built. A slot
    /// whose offset has been handed out is written (a copy, the GPU's, may read it then).
    std::int64_t builtOffset(std::uint64_t brick) const;
    /// Words the pool may come to use (its budget).
    std::uint64_t capacityWords() const { return mSlots * mWordsPerBrick; }

    FineOccupancyStats stats() const;
    /// Adds to a frame's stats what building maps has cost since `before` (stats() when the
    /// frame began asking for them) and the `withMaps` bricks it draws by a map.
    void addFrameCost(const FineOccupancyStats& before, std::uint64_t withMaps,
                      FrameStats& stats) const;
    /// Host bytes held: the pool's used slots and the per-brick table.
    std::uint64_t bytes() const;

  private:
    /// The per-value range tests of integer voxels (mLowPrefix, mHighPrefix), once; every
    /// brick's voxels are of the first one's type.
    void prepareType(brickstore::VoxelType type);
    /// Marks a brick's cells in `grid` (the distance passes' padded grid: cellsPerAxis() + 2 a
    /// side, its padding 255): every cell, 0 where samples are taken, 255 where none are; false
    /// when the map would gain too little. S: the cell's voxels when fixed at compile time (1, 2),
    /// else 0 (cellVoxels()).
    template <int S, class T>
    bool build(std::uint64_t brick, const T* voxels, int brickVoxels, int apron,
               std::uint8_t* grid) const;
    /// Whether a cell whose reads range over [lo, hi] holds a sample with opacity: the
    /// octree leaves' test (entrySpan() and the visible-entry prefix count).
    template <class T> bool takes(T lo, T hi) const;

    const OccupancyTrees& mTrees;
    std::uint32_t mCell = 1, mLevels = 0, mCellsPerAxis = 1, mWordsPerBrick = 0;
    std::uint64_t mSlots = 0; ///< the pool's capacity, slot 0 included
    std::unique_ptr<std::uint32_t[]> mPool;
    std::atomic<std::uint64_t> mNextSlot{1};
    /// Per brick: kUnbuilt, kBuilding, or its word offset (0: none).
    std::unique_ptr<std::atomic<std::int64_t>[]> mOffsets;
    std::uint64_t mBricks = 0;
    std::vector<std::uint32_t> mPrefix; ///< visible table entries before entry i
    /// Integer voxels, per value v (i16: v + 32768): mPrefix at the first and one past the last
    /// entry of entrySpan(v, v), so a range [lo, hi] takes samples when they differ.
    std::vector<std::uint32_t> mLowPrefix, mHighPrefix;
    std::once_flag mTypeOnce;
    brickstore::VoxelType mType = brickstore::VoxelType::U8;
    double mDomainMin = 0, mDomainMax = 1;
    std::uint32_t mEntries = 2;
    std::atomic<std::uint64_t> mBuilt{0}, mKept{0}, mBuildNs{0};
};

} // namespace bc::render
