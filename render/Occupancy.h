#pragma once
// Second-stage empty-space skipping (Ruijters & Vilanova 2006, section 7): one octree per
// brick over its leaf blocks, rebuilt from the store's per-leaf value ranges alone whenever
// the transfer function changes; voxels are never read.
//
// A leaf is empty when the transfer function is transparent over the whole value range its
// samples can read (FORMAT.md "Leaf table": payload voxels plus the apron reach), decided by
// a prefix count of the table entries with non-zero opacity, so a peak between two voxel
// values is never missed. A node's ratio is its share of non-empty leaves. Traversal (done
// here once per rebuild, not per frame) draws a node whole when its ratio reaches the
// threshold or it sits at the level limit; what is left is a hierarchy of occupancy bits
// per brick that the raycaster walks to leap over empty nodes (see render/OCCUPANCY.md).
#include <algorithm>
#include <array>
#include <cmath>
#include <cstdint>
#include <string>
#include <vector>

namespace bc::brickstore {
class BrickStore;
}

namespace bc::render {

struct TransferFunctionTable;

/// Table entries [i, j] whose interpolation can produce a value of [lo, hi] (of a table of
/// `entries` over [domainMin, domainMax]): those TransferFunctionTable::maxOpacity reads,
/// widened by one entry on each side so that float rounding of the table position (the GPU's,
/// or a sample position rounded across a face) cannot reach an entry the test did not look
/// at. A NaN bound gives the whole table. The one range test of the octree's leaves and of
/// the distance maps' cells (FineOccupancy.h).
/// Inline: the distance maps call it for every cell of a brick.
inline std::array<std::uint32_t, 2> entrySpan(double lo, double hi, double domainMin,
                                              double domainMax, std::uint32_t entries) {
    const double last = double(entries - 1), scale = last / (domainMax - domainMin);
    const double u0 = std::clamp((lo - domainMin) * scale, 0.0, last);
    const double u1 = std::clamp((hi - domainMin) * scale, 0.0, last);
    if (!(u0 == u0) || !(u1 == u1)) return {0, entries - 1}; // NaN: the whole table
    const double i = std::max(0.0, std::floor(u0) - 1.0), j = std::min(last, std::ceil(u1) + 1.0);
    return {std::uint32_t(i), std::uint32_t(j)};
}

/// Bounds on the values trilinear interpolation in float can give from voxels of [lo, hi]
/// (detail::fetch, the SIMD march's lerps, the GPU's): the range widened for rounding. Each of
/// the three nested lerps a + t (b - a) errs by at most about 3 ulp of max(|a|, |b|); the
/// margin, 2e-6 of the largest magnitude, is over three times the sum. Voxels of one value
/// interpolate to it exactly (b - a is 0), so such a range is its own bound: a noisy scan's
/// uniform air then holds a ray's minimum without a sample. What the projections' running skip
/// compares with a ray's maximum or minimum, so that skipping stays exact. (The GPU raycaster
/// widens these again for its texels and its own lerps.)
inline float interpolatedUpper(float lo, float hi) {
    if (lo == hi) return hi;
    return hi + 2e-6f * std::max(std::abs(lo), std::abs(hi));
}
inline float interpolatedLower(float lo, float hi) {
    if (lo == hi) return lo;
    return lo - 2e-6f * std::max(std::abs(lo), std::abs(hi));
}
/// interpolatedUpper() for a maximum's running skip (`upper`), interpolatedLower() for a minimum's.
inline float interpolatedBound(bool upper, float lo, float hi) {
    return upper ? interpolatedUpper(lo, hi) : interpolatedLower(lo, hi);
}

struct OccupancyConfig {
    /// A non-empty node whose ratio of non-empty leaves reaches this is drawn whole (its
    /// empty leaves are sampled, not leapt). 1 draws only full nodes whole; 0 draws every
    /// non-empty node whole, leaving only empty nodes below the root to leap.
    double ratioThreshold = 1.0;
    /// Deepest octree level descended: 0 is the brick, depth() the leaves. A non-empty node
    /// at the limit is drawn whole.
    std::uint32_t levelLimit = 32;

    /// Throws std::invalid_argument naming the field when a value is out of range.
    void validate() const;
    bool operator==(const OccupancyConfig&) const = default;
};

/// What one update did.
struct OccupancyRebuild {
    double ms = 0.0;
    std::uint64_t bricksRebuilt = 0; ///< octrees rebuilt (stored bricks only)
    std::uint64_t bricksStored = 0;  ///< stored bricks of the level (the others are constant)
    bool full = false;               ///< every octree rebuilt (first build, new domain or config)
};

/// The leaves of one brick whose occupancy bit is set, as a box of leaf coordinates (inclusive
/// on both ends); lo > hi on every axis when no leaf is.
struct SampledBox {
    std::array<std::uint32_t, 3> lo{}, hi{};
    bool none() const { return lo[0] > hi[0]; }
    bool operator==(const SampledBox&) const = default;
};

/// The octrees of one pyramid level of one store. Not thread-safe; render thread only.
class OccupancyTrees {
  public:
    /// Reads the leaf table of every stored brick of `level` once (checksums verified). A
    /// brick whose leaf table is corrupt gets an all-occupied octree (never leapt) and is
    /// named in faults(); the others are unaffected.
    OccupancyTrees(const brickstore::BrickStore& store, std::uint32_t level);

    /// Brings every octree up to `table` and `config`. Incremental: only the bricks whose
    /// value range meets the table entries whose emptiness changed are rebuilt, in parallel.
    /// @throw std::invalid_argument on a bad config.
    OccupancyRebuild update(const TransferFunctionTable& table, const OccupancyConfig& config);

    std::uint32_t level() const { return mLevel; }
    /// Octree levels below the root: ceil(log2(leaves per axis)).
    std::uint32_t depth() const { return mDepth; }
    std::uint32_t leavesPerAxis() const { return mLeaves; }
    std::uint32_t leafVoxels() const { return mLeafVoxels; }
    /// 32-bit words per brick in words().
    std::uint32_t wordsPerBrick() const { return mWordsPerBrick; }
    /// Per brick of the level (x fastest), the occupancy bits of octree levels 1..depth():
    /// level l holds (2^l)^3 bits (x fastest), starting at bit sum_{m=1}^{l-1} 8^m. A set bit
    /// means "sample here"; a clear one, "leap over this node". Constant bricks are all set.
    const std::vector<std::uint32_t>& words() const { return mWords; }
    /// Per brick of the level, the box of its leaves whose bit is set (every leaf for a
    /// constant brick): a ray leaves out the samples outside it before it walks the octree.
    const std::vector<SampledBox>& sampledBoxes() const { return mBoxes; }
    /// Bricks whose words changed in the last update (indices within the level).
    const std::vector<std::uint64_t>& changedBricks() const { return mChanged; }

    /// Share of non-empty leaves of a node at octree level `octLevel` (0 = the brick), by its
    /// coordinates at that level; leaves outside the brick's grid do not count.
    double ratio(std::uint64_t brick, std::uint32_t octLevel,
                 const std::array<std::uint32_t, 3>& node) const;
    /// Whether the raycaster samples inside that node (its bit, or true for the root).
    bool occupied(std::uint64_t brick, std::uint32_t octLevel,
                  const std::array<std::uint32_t, 3>& node) const;
    /// Whether leaf `leaf` ((z * leavesPerAxis() + y) * leavesPerAxis() + x) of `brick` is
    /// non-empty under the last update (its value range meets a visible table entry, or its
    /// leaf table is corrupt); false for a brick that is not stored.
    bool leafNonEmpty(std::uint64_t brick, std::uint32_t leaf) const;
    /// Whether brick `brick`'s root is drawn whole under the last update: every sample of the
    /// brick is taken, its octree leaps over nothing.
    bool drawnWhole(std::uint64_t brick) const { return mWhole[brick] != 0; }
    /// Per brick and leaf (brick * leafCount + leaf, leaves numbered as leafNonEmpty's), bounds
    /// on every value a sample inside the leaf can take: from above with `upper`, else from
    /// below (interpolatedBound() of its range; a brick that is not stored, its one value's; a
    /// corrupt leaf table, no bound: +-infinity). Independent of the transfer function.
    const std::vector<float>& leafBounds(bool upper) const {
        return upper ? mLeafUpper : mLeafLower;
    }
    /// Host memory this object holds (its tables and bits).
    std::uint64_t bytes() const;
    /// Leaf tables that failed their checksum, one line each naming the brick.
    const std::vector<std::string>& faults() const { return mFaults; }

  private:
    void rebuildBrick(std::uint64_t brick, const std::vector<std::uint32_t>& prefix);

    std::uint32_t mLevel = 0, mLeaves = 0, mLeafVoxels = 0, mDepth = 0, mWordsPerBrick = 0;
    std::uint64_t mBricks = 0;
    std::vector<std::uint8_t> mStored; ///< per brick: 1 when stored (has leaves)
    std::vector<std::array<float, 2>> mBrickRange;
    std::vector<std::array<float, 2>> mLeafRange;           ///< per brick * leafCount
    std::vector<float> mLeafUpper, mLeafLower;              ///< leafBounds(true), (false)
    std::vector<std::array<std::uint32_t, 2>> mLeafEntries; ///< table entries [i, j] read
    std::vector<std::uint8_t> mLeafFull;                    ///< corrupt leaf table: always occupied
    std::vector<std::uint8_t> mNonEmpty;                    ///< per leaf, of the last update
    std::vector<std::uint8_t> mRoot;                        ///< per brick: any leaf non-empty
    std::vector<std::uint8_t> mWhole;                       ///< per brick: drawnWhole()
    std::vector<std::uint32_t> mWords;
    std::vector<SampledBox> mBoxes;
    std::vector<std::uint64_t> mChanged;
    std::vector<std::string> mFaults;

    // What the last update was made for.
    bool mBuilt = false;
    double mDomainMin = 0.0, mDomainMax = 0.0;
    std::uint32_t mEntries = 0;
    OccupancyConfig mConfig;
    std::vector<std::uint8_t> mVisible; ///< per table entry: opacity > 0
};

} // namespace bc::render
