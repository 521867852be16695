#pragma once
// Hybrid forward splatting on the GPU (Yuan et al. 2003): the model of
// HybridSplatter (spheres of radius radiusVoxels * max spacing, the SplatFootprint kernel,
// points below pointThresholdPixels summed in slabs of one voxel's depth, splats composited
// 'over', front to back), drawn by OpenGL so that both images agree. The CPU side is the
// CPU splatter's own (render/detail/SplatPrep.h): bricks in the plan's visibility order,
// pinned (never more than the host budget at once), classified, shaded and sorted on every
// core, each voxel made a point or a splat by the same rules. From that it writes one ordered
// list of primitives into one vertex buffer, cut into batches: a run of splats, or the points
// of one slab (a slab ends where the CPU flushes it: a point deeper than its end, a splat,
// the end of a brick).
//
// GPU path. A splat is an instanced quad over the pixel rectangle of its exact ellipse
// (projectSphere); the fragment shader takes the distance from the sphere centre to the
// pixel's eye ray in radii, which is the footprint index after correctedDistance, exactly
// (the CPU gets it from coneIndex and a 2D table over (index, half angle); the GPU needs only
// the 1D line integral: a table of kFootprintTexels entries read with full-precision linear
// weights, worst error against SplatFootprint::lookup stated in its test), discards at
// distance >= 1 and blends alpha = 1 - exp(-k fp) front to back, premultiplied, into an
// RGBA32F target (GL blends in primitive order, so the sort holds). The points of a slab are
// quads over their filter's pixels, added (coverage times colour, coverage) into a second
// RGBA32F target with the weights normalised on the CPU as the CPU path does; one pass
// over the slab's pixel box then composites it 'over' (coverage clamped to 1) and clears it.
// What differs from the CPU path:
//  - Early ray termination: blending cannot stop at ertThreshold, so a pixel keeps taking
//    colour after the CPU would have stopped: the images differ by at most about
//    (1 - ertThreshold) times the brightest shaded colour (<= 1.25), plus the float
//    rounding bound of the test.
//  - No occlusion culling: the CPU's per-tile opacity test has no cheap GPU twin, so every
//    visible voxel is drawn (HybridSplatterConfig::occlusionCulling and tilePixels are
//    ignored; lastFrame().culled and bricksCulled stay 0).
//  - Float arithmetic in the shaders (the CPU works in double), and the footprint of a splat
//    from the exact ray distance instead of the CPU's (index, half angle) table.
// Regions (RenderOptions::region): the viewport, primitives and slab cuts stay the whole
// image's, so every fragment is the whole frame's; bricks whose screen reach misses the region
// are dropped before they are pinned, primitives that miss it are not uploaded, a scissor keeps
// the region's pixels and only they are read back: each the whole frame's, to the bit.
// Needs a current EglContext on the calling thread; render thread only, one frame at a time.
#include "render/Camera.h"
#include "render/Image.h"
#include "render/RenderTypes.h"
#include "render/Renderer.h"
#include "render/SplatConfig.h"
#include "render/SplatFootprint.h"

#include <cstdint>
#include <memory>
#include <string>
#include <vector>

namespace bc::brickstore {
class BrickStore;
class BrickCache;
} // namespace bc::brickstore

namespace bc::render {

class TransferFunction;
class OccupancyTrees;

class GpuSplatter final : public Renderer {
  public:
    /// Texels of the footprint texture: lineIntegral at distance k / (kFootprintTexels - 1).
    static constexpr std::uint32_t kFootprintTexels = 4096;

    /// @throw std::invalid_argument on a bad config; RenderError naming a shader that does
    /// not build on this context.
    explicit GpuSplatter(const HybridSplatterConfig& config = {});
    ~GpuSplatter() override;
    GpuSplatter(const GpuSplatter&) = delete;
    GpuSplatter& operator=(const GpuSplatter&) = delete;

    /// Renders one frame of `store` at options.level, as HybridSplatter::render. Fills `stats`
    /// (samples = voxels drawn, octreeLeaps = empty leaves skipped, batches = draw batches,
    /// uploadMs = preparing bricks and uploading the primitives, renderMs = drawing).
    /// @throw std::invalid_argument on bad options or view; StoreCorrupt naming a brick;
    /// RenderError on a GL failure.
    Image render(const Scene& scene, const View& view, const RenderOptions& options,
                 FrameStats& stats) override;
    using Renderer::render;
    std::string_view name() const override { return "splat-gpu"; }

    /// Counts of the last render() (points, splats, slabs, leaves skipped; nothing culled).
    const HybridSplatStats& lastFrame() const { return mLast; }

    /// What the footprint texture holds for `footprint` (kFootprintTexels floats).
    static std::vector<float> footprintTexels(const SplatFootprint& footprint);
    /// The shader's footprint read, on the CPU: linear between the two texels around
    /// distance d (radii), full-precision weights; 0 at d >= 1.
    static double sampleFootprint(const std::vector<float>& texels, double distanceRadii);

  private:
    struct Gpu;

    HybridSplatterConfig mConfig;
    SplatFootprint mFootprint; ///< of mConfig.sigmaOverRadius, built once
    HybridSplatStats mLast;
    std::unique_ptr<Gpu> mGpu;
};

} // namespace bc::render
