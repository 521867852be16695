#pragma once
// Which bricks of a pyramid level a frame draws, and in which order: bricks outside the
// view frustum are culled, bricks whose value range the transfer function maps to zero
// opacity are skipped (first-stage skipping), and the rest are sorted front to back.
#include "brickstore/StoreLayout.h"
#include "render/Camera.h"
#include "render/RenderTypes.h"
#include "render/View.h"

#include <array>
#include <cstddef>
#include <cstdint>
#include <vector>

namespace bc::brickstore {
class BrickStore;
}

namespace bc::render {

struct TransferFunctionTable;
class OccupancyTrees;

/// One pyramid level in world space. Every level spans the same world box as level 0 (its
/// spacing is the box divided by its dims), so one camera frames every level alike.
struct LevelGeometry {
    std::uint32_t level = 0;
    std::array<std::uint64_t, 3> dims{};
    glm::dvec3 spacing{1.0};
    std::uint32_t brickVoxels = 64;
    std::uint32_t apronVoxels = 2;
    std::array<std::uint32_t, 3> bricks{};
    Box box;

    static LevelGeometry of(const brickstore::BrickStore& store, std::uint32_t level);
    double minSpacing() const;
    std::uint64_t brickCount() const { return std::uint64_t(bricks[0]) * bricks[1] * bricks[2]; }
    /// The world box of a brick's payload (clipped to the volume).
    Box brickBox(const std::array<std::uint32_t, 3>& pos) const;
};

enum class BrickDraw : std::uint8_t { Culled, Skipped, Constant, Sampled };

struct PlannedBrick {
    std::uint64_t index = 0; ///< within the level, x fastest
    brickstore::BrickKey key;
    BrickDraw draw = BrickDraw::Sampled;
    float constantValue = 0.0f; ///< for Constant: the brick's one value (native units)
    std::int64_t order = 0;     ///< visibility key: never decreases along any ray
};

struct BrickPlan {
    std::vector<PlannedBrick> drawn; ///< Constant and Sampled bricks, front to back
    std::uint64_t total = 0, culled = 0, skipped = 0, constant = 0, sampled = 0;
};

/// Plans one frame. Conservative: a brick any ray of the frame can sample with non-zero
/// opacity is never culled or skipped. The order is a valid front-to-back order for every
/// ray, so batches of consecutive bricks composite correctly. With `occupancy` (its octrees up
/// to date for `table`), SkipMode::All also skips bricks none of whose leaves is visible.
/// A brick that would be skipped but lies within `keepNear` bricks (per axis) of a drawn one
/// is drawn: under pre-integration a segment from a drawn brick into a transparent one reads
/// the transparent one's value (keepNear: ceil(step / brick voxels), at least 1).
BrickPlan planBricks(const brickstore::BrickStore& store, const LevelGeometry& geometry,
                     const TransferFunctionTable& table, const ViewBasis& view, SkipMode skip,
                     const OccupancyTrees* occupancy = nullptr, std::uint32_t keepNear = 0);

/// The same for the rays of one region of the view's image alone (a slice of a frame the
/// daemon draws in slices): bricks outside the region's own frustum are culled too, so a
/// slice pins and loads only what its rays can reach. A whole() region is the whole view.
BrickPlan planBricks(const brickstore::BrickStore& store, const LevelGeometry& geometry,
                     const TransferFunctionTable& table, const View& view, const PixelRect& region,
                     SkipMode skip, const OccupancyTrees* occupancy = nullptr,
                     std::uint32_t keepNear = 0);

/// Every brick of the level, front to back, nothing culled or skipped (for the reference, which
/// samples wherever a ray goes).
BrickPlan planEveryBrick(const brickstore::BrickStore& store, const LevelGeometry& geometry,
                         const ViewBasis& view);

/// Splits the front-to-back order into batches of consecutive bricks whose sampled bricks
/// (`brickBytes` each once pinned) fit `budgetBytes`, so that a renderer drawing one batch at
/// a time never pins more than the budget (one brick when the budget holds less). Constant
/// bricks cost nothing. Returns each batch's end in plan.drawn (one batch for an empty plan).
/// Batches composite in order: along any ray the visibility key rises by one per brick face,
/// so a ray meets the bricks of batch b before those of batch b + 1.
std::vector<std::size_t> planBatches(const BrickPlan& plan, std::uint64_t brickBytes,
                                     std::uint64_t budgetBytes);
/// planBatches, and a batch also ends once it holds `loadBytes` of bricks to load
/// (`missing[i]` for plan.drawn[i]; 0 = no such limit). Between two batches a renderer learns
/// which rays are still marching, and can leave out the later bricks that none of them can
/// reach (the CPU raycaster's ray guidance): the smaller the steps its loads come in, the
/// more of them it can leave out.
std::vector<std::size_t> planBatches(const BrickPlan& plan, std::uint64_t brickBytes,
                                     std::uint64_t budgetBytes,
                                     const std::vector<std::uint8_t>& missing,
                                     std::uint64_t loadBytes);

/// Drops from `plan` the bricks whose payload box lies wholly outside what `clip` keeps
/// (Clip::outside), counting them culled: no sample of theirs is taken.
void keepInside(BrickPlan& plan, const LevelGeometry& geometry, const Clip& clip);

/// The plan's brick counts and `level` into a frame's stats.
void recordPlan(const BrickPlan& plan, std::uint32_t level, FrameStats& stats);

/// True when `box` lies wholly outside the view of `view` (side planes through the image
/// corners, and behind the eye plane).
bool outsideView(const Box& box, const ViewBasis& view);
/// True when `box` lies wholly outside the rays through `region` of the view's image (side
/// planes through the region's outer pixel edges, and behind the eye plane).
bool outsideRegion(const Box& box, const View& view, const PixelRect& region);

} // namespace bc::render
