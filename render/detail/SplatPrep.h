#pragma once
// What the CPU and GPU hybrid splatters share, so both draw one model: the frame's
// constants, the visible voxels of each brick (classified, shaded, sorted front to back)
// prepared on every core, and the per-voxel decisions (point or splat, a point's filter
// weights). The drawing itself (the CPU canvas, the GPU primitive list) stays with each
// splatter.
#include "brickstore/BrickCache.h"
#include "brickstore/VoxelType.h"
#include "render/BrickPlan.h"
#include "render/Camera.h"
#include "render/RenderTypes.h"
#include "render/Renderer.h"
#include "render/SplatConfig.h"
#include "render/SplatGeometry.h"
#include "render/TransferFunction.h"

#include <array>
#include <cstddef>
#include <cstdint>
#include <memory>
#include <string>
#include <vector>

#include <glm/vec2.hpp>
#include <glm/vec3.hpp>

namespace bc::brickstore {
class BrickStore;
} // namespace bc::brickstore

namespace bc::render {
class OccupancyTrees;
class SplatFootprint;
} // namespace bc::render

namespace bc::render::detail {

constexpr double kMaxOpacity = 1.0 - 1e-6; // keeps -log(1 - a) finite

/// Everything a voxel needs to be drawn.
struct Frame {
    SplatView view;
    LevelGeometry g;
    const TransferFunctionTable* table = nullptr;
    double radiusMm = 1.0;
    double depthScale = 1.0; ///< V / (r^2 minSpacing): footprint -> steps of one voxel
    double slabMm = 1.0;
    double voxelSteps = 1.0;   ///< cube root of the voxel volume, in steps of minSpacing
    double voxelAreaMm2 = 1.0; ///< the voxel volume to the power 2/3
    double pointThreshold = 0.5, pointFilter = 1.0;
    bool shading = true, cull = true;
    glm::dvec3 gradScale{1.0};
};

/// The frame constants; `cull` is config.occlusionCulling with early termination on.
Frame frameOf(const HybridSplatterConfig& config, const LevelGeometry& g, const ViewBasis& basis,
              const RenderOptions& o, const TransferFunctionTable& table);

/// What a splatter settles before drawing: the level, and the classification (its table at
/// step 1, opacity per unit step, since the footprint gives the path; octrees under
/// SkipMode::All with an apron). Records an octree build in `stats`.
/// @throw std::invalid_argument on bad options or a view of another size.
struct SplatScene {
    std::uint32_t level;
    LevelGeometry g;
    FrameClassification classified;
    const TransferFunctionTable& table() const { return *classified.table; }
    const OccupancyTrees* occupancy() const { return classified.occupancy; }
};
SplatScene sceneOf(const Scene& scene, const View& view, const RenderOptions& options,
                   FrameStats& stats);

/// Pixel rectangle of image-plane box [lo, hi], clipped; false when empty.
bool pixelRect(const glm::dvec2& lo, const glm::dvec2& hi, std::uint32_t w, std::uint32_t h,
               std::uint32_t r[4]);

/// True when the pixel rectangle r (first and last column, first and last row) meets `region`.
bool meetsRegion(const std::uint32_t r[4], const PixelRect& region);

/// Where a planned brick can draw: its world box grown by the sphere radius (and a point's
/// filter) on the screen; Nowhere off the image, Unbounded when it reaches behind the eye.
struct BrickReach {
    enum class Kind : std::uint8_t { Nowhere, Unbounded, Rect };
    Kind kind = Kind::Unbounded;
    std::uint32_t rect[4] = {};
    /// True when no voxel of the brick can touch a pixel of `region`.
    bool misses(const PixelRect& region) const {
        return kind == Kind::Nowhere || (kind == Kind::Rect && !meetsRegion(rect, region));
    }
};
BrickReach brickReach(const Frame& f, const PlannedBrick& b, std::uint32_t width,
                      std::uint32_t height);

/// A slice of a frame (RenderOptions::region, not whole): drops from `plan` the bricks whose
/// reach misses `region` of the `width` x `height` image, counted as culled. Exact: they touch
/// none of its pixels, and the bricks left keep their order, so each pixel of the region sees
/// the operations of the whole frame; a slice prepares only the bricks it can show.
void cullOutsideRegion(const Frame& f, const PixelRect& region, std::uint32_t width,
                       std::uint32_t height, BrickPlan& plan);

/// One visible voxel of a brick, waiting for its turn.
struct Visible {
    double depth;
    std::uint32_t stored; ///< index in the stored brick (apron included); voxel for constants
    glm::dvec3 centre;
    float value;
    std::array<float, 4> rgba{}; ///< classified and shaded: straight colour, opacity per step
};

/// A brick made ready on a worker: pinned, its visible voxels sorted and shaded.
struct PreparedBrick {
    brickstore::BrickPin pin;
    std::vector<Visible> voxels;
    std::uint64_t leavesSkipped = 0;
    bool culled = false;
};

/// Bricks prepared in parallel per chunk, drawn in order: enough bricks to keep the workers
/// busy, few enough that the CPU culling test before a chunk is still sharp.
constexpr std::size_t kChunkBricks = 16;

/// The end of the chunk that starts at plan.drawn[first]: at most kChunkBricks bricks, and
/// no more sampled ones (`brickBytes` each once pinned) than `budgetBytes` holds (at least
/// one), so that a frame never pins more than the host budget.
std::size_t chunkEnd(const BrickPlan& plan, std::size_t first, std::uint64_t brickBytes,
                     std::uint64_t budgetBytes);

/// Pins, classifies, shades and sorts bricks plan.drawn[first + i] into chunk[i] on every core
/// (TBB); entries marked culled are left alone. `occupancy` (second stage, or nullptr) is
/// used for sampled bricks. @throw StoreCorrupt naming a brick.
void prepareChunk(const Frame& f, const BrickPlan& plan, std::size_t first,
                  brickstore::BrickCache& cache, brickstore::VoxelType type,
                  const OccupancyTrees* occupancy, std::vector<PreparedBrick>& chunk);

/// How one classified voxel is drawn.
struct VoxelDraw {
    enum class Kind { None, Point, Splat };
    Kind kind = Kind::None; ///< None: the sphere touches the eye plane
    glm::dvec2 image{0.0};  ///< where the centre projects (image units)
    double scale = 1.0;     ///< image units per world unit at the voxel's depth
    double lnT = 0.0;       ///< -ln(1 - a): optical depth per unit step
};
/// Point below the projected radius pointThreshold, splat above.
VoxelDraw classifyDraw(const Frame& f, const glm::dvec3& centre, float a);

/// A point's filter on the pixel lattice: centre (pixel columns and rows, row 0 at the top),
/// the coverage it deposits and the sum of its weights over the unclipped lattice. When the
/// sum is 0 (no pixel centre within the filter) the whole coverage goes to the nearest pixel.
struct PointFilter {
    double fx = 0.0, fy = 0.0;
    double total = 0.0; ///< the voxel's projected area (pixels^2) times its one-voxel opacity
    double sum = 0.0;
};
PointFilter pointFilterOf(const Frame& f, const SplatFootprint& fp, const VoxelDraw& d,
                          std::uint32_t width, std::uint32_t height);
/// The unnormalised weight of pixel (x, y).
double pointWeight(const Frame& f, const SplatFootprint& fp, const PointFilter& pf, int x, int y);

} // namespace bc::render::detail
