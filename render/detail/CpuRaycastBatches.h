#pragma once
// What each batch of the CPU raycaster loads (render/CpuRaycaster.cpp): its pins and its
// bricks' distance maps, and under ray guidance (RenderOptions::rayGuided) which of its bricks
// no ray still marching can reach, so that they are not loaded.
#include "brickstore/BrickCache.h"
#include "brickstore/VoxelType.h"
#include "render/BrickPlan.h"
#include "render/RenderTypes.h"
#include "render/View.h"
#include "render/detail/CpuRay.h"
#include "render/detail/CpuRaycastRays.h"

#include <cstddef>
#include <cstdint>
#include <vector>

#include <glm/vec3.hpp>

namespace bc::render {
class FineOccupancy;
} // namespace bc::render

namespace bc::render::detail {

/// Ray guidance's batches: plan.drawn's sampled bricks that are not resident now.
std::vector<std::uint8_t> missingBricks(const BrickPlan& plan, const brickstore::BrickCache& cache,
                                        std::uint64_t& count);

/// Pins plan.drawn[first, end) but those `unreached` marks (decompressing misses on every
/// core) and points their refs at the voxels; the pins are the batch's and go when it is
/// drawn.
std::vector<brickstore::BrickPin> pinBatch(const BrickPlan& plan, std::size_t first,
                                           std::size_t end,
                                           const std::vector<std::uint8_t>& unreached,
                                           brickstore::BrickCache& cache,
                                           std::vector<BrickRef>& bricks);

/// The distance maps (FineOccupancy) of the batch's sampled bricks, built from their pinned
/// voxels where a frame has not yet; their offsets into the pool go to their refs.
void cellsOfBatch(const BrickPlan& plan, std::size_t first, std::size_t end,
                  const std::vector<std::uint8_t>& unreached, FineOccupancy& fine,
                  brickstore::VoxelType type, const Frame& f, std::vector<BrickRef>& bricks,
                  FrameStats& stats);

/// The rays still marching (waiting for a later batch) after a pass, for ray guidance: a
/// summed-area table of them over `marched` (rays, as marchPass numbers them), so that whether
/// a rectangle holds any takes four reads, and then which of them meet a box.
class MarchingRays {
  public:
    MarchingRays(const RayStates& rays, PixelLattice lattice, const PixelRect& region,
                 const PixelRect& marched);

    /// Whether a ray still marching, of a pixel of `r` (image pixels), passes within a voxel
    /// of the box [lo, hi] (voxels of the level): the ray as RayWalk::begin sets it up, the
    /// voxel of margin for the floats of its walk.
    bool anyMeets(const Frame& f, const PixelRect& r, glm::vec3 lo, glm::vec3 hi) const;

  private:
    bool marching(std::uint32_t x, std::uint32_t y) const;
    /// `in` lies within mRect.
    bool any(const PixelRect& in) const;
    /// Whether the ray o + t dv, t >= 0, meets the box [lo, hi] (slabs).
    static bool meets(glm::vec3 o, glm::vec3 dv, glm::vec3 lo, glm::vec3 hi);

    const RayStates& mRays;
    PixelLattice mLattice;
    PixelRect mRegion, mRect;
    std::size_t mStride;
    std::vector<std::uint32_t> mSum;
};

/// Ray guidance (RenderOptions::rayGuided): marks in `unreached` the sampled bricks of
/// plan.drawn[first, end) that no ray still marching meets (every ray of their footprint has
/// terminated early, left the volume or misses the brick). A ray meets the bricks of later
/// batches only after those it waits for, so no ray would sample them: they are not loaded.
/// Returns how many it marked.
std::uint64_t markUnreached(const LevelGeometry& g, const BrickPlan& plan, std::size_t first,
                            std::size_t end, const View& view, const Frame& f,
                            const MarchingRays& marching, std::vector<std::uint8_t>& unreached);

} // namespace bc::render::detail
