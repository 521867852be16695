#pragma once
// Hybrid forward splatting on the CPU (Yuan et al. 2003): object order, front to
// back. Every voxel the transfer function makes visible is a sphere of radius
// radiusVoxels (1.25) * max(spacing) carrying the kernel of SplatFootprint, weighted so that
// overlapping spheres reconstruct the voxel values (a uniform region reconstructs a constant).
// A voxel whose projected radius is below pointThresholdPixels is a point: its coverage (its
// projected voxel area times its opacity over one voxel of path) is spread over the pixels by
// the same footprint with radius pointFilterPixels (weights normalised to sum to 1) and added
// into a slab buffer about one voxel (max spacing) deep; the slab is composited 'over' when
// the voxels move past it (coverage clamped to 1: an area average, as a box filter would
// give). Larger voxels are perspective splats: the exact ellipse (projectSphere), composited
// 'over' at once with the footprint of each pixel's exact ray-centre distance (a 1D table over
// d^2, in float), or with exactDistanceFootprint off the paper's exact index (coneIndex) and
// 2D table; the two agree to the 2D table's error.
//
// Optics: a voxel's opacity per unit step a (render/OPTICS.md, one voxel of the smallest
// spacing) is applied for the footprint's line integral through its sphere, in voxel units:
// alpha = 1 - (1 - a)^(F(d) * V / (r^2 * minSpacing)), V the voxel's volume. Classification is
// per voxel (pre-interpolative), unlike the raycasters. Shading is OPTICS.md's headlight
// Blinn-Phong with the gradient from central differences of the voxel grid, the light
// direction being the eye ray to the voxel centre. RenderOptions::stepVoxels does not apply.
//
// Order: bricks in the plan's visibility order, the voxels of a brick by distance from the
// eye (perspective) or depth along the view axis (orthographic). Occlusion culling: a voxel
// is skipped without being drawn when every 8x8 tile its footprint touches is opaque
// (ertThreshold, with earlyTermination on), and a planned brick is skipped unpinned when the
// tiles under its screen box are; pixels at the threshold take no more colour either way, so
// culling changes no pixel. Bricks are pinned, classified, shaded and sorted on every core
// (TBB, 16 bricks at a time, fewer when the host budget holds fewer: no frame pins more than
// the budget), then drawn in order in horizontal bands of whole tiles, one worker per band
// (parallelDraw): slab cuts are decided once for all bands, culling per band, so every pixel
// sees the serial operations and the image and counts are those of one band.
// Regions (RenderOptions::region, a slice of a frame): the plan, the records and the slab cuts
// are the whole image's; bricks whose screen reach misses the region are dropped before they
// are pinned, and the bands, tiles and pixels drawn are the region's alone, so each pixel of a
// region gets the whole frame's operations in the same order (the same value, to the bit) at
// a cost that follows the bricks reaching it. Counts are of the voxels that meet the region.
// Not thread-safe: one frame at a time per instance.
#include "render/Renderer.h"
#include "render/SplatConfig.h"
#include "render/SplatFootprint.h"

#include <cstdint>
#include <memory>
#include <string>

namespace bc::brickstore {
class BrickStore;
class BrickCache;
} // namespace bc::brickstore

namespace bc::render {

class TransferFunction;
struct TransferFunctionTable;
class OccupancyTrees;

class HybridSplatter final : public Renderer {
  public:
    /// @throw std::invalid_argument on a bad config.
    explicit HybridSplatter(const HybridSplatterConfig& config = {});
    ~HybridSplatter() override;
    HybridSplatter(const HybridSplatter&) = delete;
    HybridSplatter& operator=(const HybridSplatter&) = delete;

    /// Renders one frame of `store` at options.level. Fills `stats` (samples = voxels drawn,
    /// octreeLeaps = empty leaves skipped, uploadMs = pinning, classifying and sorting bricks,
    /// one batch, no uploads).
    /// @throw std::invalid_argument on bad options or view; StoreCorrupt naming a brick.
    Image render(const Scene& scene, const View& view, const RenderOptions& options,
                 FrameStats& stats) override;
    using Renderer::render;
    std::string_view name() const override { return "splat"; }

    /// Counts of the last render().
    const HybridSplatStats& lastFrame() const { return mLast; }

  private:
    HybridSplatterConfig mConfig;
    SplatFootprint mFootprint; ///< of mConfig.sigmaOverRadius, built once
    HybridSplatStats mLast;
};

} // namespace bc::render
