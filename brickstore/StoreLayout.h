#pragma once
// How a volume is cut into bricks, level by level. Pure arithmetic shared by the writer,
// the reader and (later) the renderer; see FORMAT.md for the meaning of each number.
#include <array>
#include <cstdint>
#include <string>
#include <vector>

namespace bc::brickstore {

/// One brick of one pyramid level. Level 0 is full resolution.
struct BrickKey {
    std::uint32_t level = 0;
    std::array<std::uint32_t, 3> pos{}; ///< brick coordinates along x, y, z
    bool operator==(const BrickKey&) const = default;
    /// "L0 (3,1,2)": how errors and tools name a brick.
    std::string toString() const;
};

struct LevelLayout {
    std::array<std::uint64_t, 3> dims{};   ///< voxels of this level
    std::array<std::uint32_t, 3> bricks{}; ///< bricks along x, y, z
    std::uint64_t firstBrick = 0;          ///< index of brick (0,0,0) in the store's brick list
    std::uint64_t brickCount() const { return std::uint64_t(bricks[0]) * bricks[1] * bricks[2]; }
};

struct BrickGeometry {
    std::uint32_t brickVoxels = 64; ///< payload edge B
    std::uint32_t apronVoxels = 2;  ///< overlap A on every side; stored edge is B + 2A
    std::uint32_t leafVoxels = 8;   ///< edge of a leaf block of per-leaf min/max
};

/// Accepted ranges of BrickGeometry (checked on ingest and on open).
constexpr std::uint32_t kMinBrickVoxels = 4, kMaxBrickVoxels = 512, kMaxApronVoxels = 16;
constexpr std::uint32_t kMaxLevels = 24;

class StoreLayout {
  public:
    /// Builds level 0 from `dims` and halves (rounding up) until a level fits in one brick.
    /// @throw std::invalid_argument on a geometry outside the accepted ranges.
    StoreLayout(const std::array<std::uint64_t, 3>& dims, const BrickGeometry& geometry);

    const BrickGeometry& geometry() const { return mGeometry; }
    const std::vector<LevelLayout>& levels() const { return mLevels; }
    std::uint64_t brickCount() const { return mBrickCount; }
    std::uint32_t storedEdge() const { return mGeometry.brickVoxels + 2 * mGeometry.apronVoxels; }
    std::uint64_t storedVoxels() const {
        return std::uint64_t(storedEdge()) * storedEdge() * storedEdge();
    }
    std::uint32_t leavesPerAxis() const;
    std::uint32_t leafCount() const { return leavesPerAxis() * leavesPerAxis() * leavesPerAxis(); }
    /// Leaves along x, y, z whose payload voxels meet the volume: all leavesPerAxis() except in
    /// the partial bricks at the far borders (FORMAT.md "Leaf table", version 2).
    std::array<std::uint32_t, 3> leavesInside(const BrickKey& key) const;

    /// Position of a brick in the store's brick list (level-major, then z, y, x).
    std::uint64_t indexOf(const BrickKey& key) const;
    BrickKey keyOf(std::uint64_t index) const;
    bool contains(const BrickKey& key) const;
    /// First payload voxel of a brick, in its level's voxel coordinates.
    std::array<std::uint64_t, 3> payloadOrigin(const BrickKey& key) const;
    /// Payload voxels of a brick that lie inside the volume (border bricks are partial).
    std::array<std::uint64_t, 3> payloadExtent(const BrickKey& key) const;

  private:
    BrickGeometry mGeometry;
    std::vector<LevelLayout> mLevels;
    std::uint64_t mBrickCount = 0;
};

} // namespace bc::brickstore
