#pragma once
// Sort-last scale-out (render/SCALEOUT.md): one level's brick grid split into convex
// parts, one per rank, by a k-d tree of planes on brick faces; the parts' front-to-back order
// for a view; and the pixels a part can cover. A part draws only the samples of its own bricks
// (RenderOptions::parts), so the parts' samples are exactly one renderer's, and their images
// composite front to back (render/Composite.h) into the one-renderer frame.
#include "render/BrickPlan.h"
#include "render/RenderTypes.h"
#include "render/View.h"

#include <array>
#include <cstdint>
#include <optional>
#include <span>
#include <vector>

namespace bc::brickstore {
class BrickStore;
}

namespace bc::render {

/// A box of bricks of one level: [lo, hi) along each axis; empty when any hi <= lo.
struct BrickBox {
    std::array<std::uint32_t, 3> lo{}, hi{};

    bool empty() const { return hi[0] <= lo[0] || hi[1] <= lo[1] || hi[2] <= lo[2]; }
    std::uint64_t count() const {
        return empty()
                   ? 0
                   : std::uint64_t(hi[0] - lo[0]) * (hi[1] - lo[1]) * std::uint64_t(hi[2] - lo[2]);
    }
    bool contains(const std::array<std::uint32_t, 3>& pos) const {
        return pos[0] >= lo[0] && pos[0] < hi[0] && pos[1] >= lo[1] && pos[1] < hi[1] &&
               pos[2] >= lo[2] && pos[2] < hi[2];
    }
    bool operator==(const BrickBox&) const = default;
};

/// A level's brick grid split into `parts` boxes by a k-d tree: each node halves its parts
/// (the first floor(n/2) to the low side) with a plane on a brick face, placed where the low
/// side's share of the weight comes closest to its share of the parts, on the axis that comes
/// closest (ties: the longest axis). The boxes are disjoint and cover the grid. A box that
/// cannot be cut (one brick) gives its extra parts empty boxes; so does a grid of fewer bricks
/// than parts. Deterministic: every rank that splits the same grid and weights gets the same.
class Partition {
  public:
    static constexpr std::uint32_t kMaxParts = 4096;

    /// `weights`: one per brick of `grid`, x fastest. @throw std::invalid_argument when parts
    /// is 0 or over kMaxParts, the grid is empty or weights is not one per brick.
    static Partition split(const std::array<std::uint32_t, 3>& grid,
                           std::span<const std::uint64_t> weights, std::uint32_t parts);
    /// Level `level` of `store`, each brick weighing its decompressed bytes when it is stored
    /// and nothing when it is of one value (what a part's host cache holds of it; 0 weight
    /// everywhere splits by brick count). Reads only the index.
    static Partition ofLevel(const brickstore::BrickStore& store, std::uint32_t level,
                             std::uint32_t parts);

    std::uint32_t parts() const { return std::uint32_t(mRegions.size()); }
    const std::array<std::uint32_t, 3>& grid() const { return mGrid; }
    const BrickBox& region(std::uint32_t part) const { return mRegions.at(part); }
    /// The weight of part `part`'s bricks.
    std::uint64_t weight(std::uint32_t part) const { return mWeights.at(part); }

    /// The parts front to back for `view` of a level of geometry `g` (the grid's): along any
    /// ray, a part's samples all come before those of the parts after it. At each plane the
    /// side holding the eye (perspective) or the side the view looks from (orthographic) comes
    /// first; parts with empty boxes are left out.
    std::vector<std::uint32_t> frontToBack(const LevelGeometry& g, const ViewBasis& view) const;

  private:
    struct Node {
        int axis = -1;           ///< -1: a leaf holding `part`
        std::uint32_t plane = 0; ///< brick index of the plane: low side [lo, plane)
        std::uint32_t low = 0, high = 0;
        std::uint32_t part = 0;
    };
    std::array<std::uint32_t, 3> mGrid{};
    std::vector<Node> mNodes; ///< mNodes[0] is the root
    std::vector<BrickBox> mRegions;
    std::vector<std::uint64_t> mWeights;

    std::uint32_t build(const BrickBox& box, std::uint32_t firstPart, std::uint32_t parts,
                        std::span<const std::uint64_t> weights);
};

/// The split of the level a renderer drawing RenderOptions::parts last asked for, kept while
/// the store (its instance), the level and the part count stay.
class PartitionCache {
  public:
    /// @throw what Partition::ofLevel throws.
    const Partition& get(const brickstore::BrickStore& store, std::uint32_t level,
                         std::uint32_t parts);

  private:
    std::optional<Partition> mPartition;
    std::uint64_t mStore = 0;
    std::uint32_t mLevel = 0;
};

/// The world box of a box of bricks' payload (clipped to the volume).
Box worldBox(const LevelGeometry& g, const BrickBox& box);

/// The pixels of `view`'s image whose rays may pass through a box of bricks: the bounding
/// rectangle of its corners' projections widened by a pixel, clipped to the image; the whole
/// image when a corner lies at or behind the eye plane. `visible` is false when no pixel is
/// left (the box lies outside the view).
struct Footprint {
    PixelRect rect;
    bool visible = false;
};
Footprint footprint(const LevelGeometry& g, const BrickBox& box, const View& view);

/// Leaves in `plan` only the bricks inside `owned` (the others count as culled): what one part
/// of a Partition draws.
void keepOwned(BrickPlan& plan, const BrickBox& owned);

} // namespace bc::render
