#pragma once
// The one interface every renderer implements (the GPU and CPU raycasters, the CPU reference
// and both splatters): draw a frame of a scene seen from a view into an image, with stats.
// The daemon picks an implementation by name from RendererRegistry, never by a switch.
#include "render/Classification.h"
#include "render/Image.h"
#include "render/RenderTypes.h"
#include "render/View.h"

#include <memory>
#include <string_view>

namespace bc::brickstore {
class BrickStore;
class BrickCache;
} // namespace bc::brickstore

namespace bc::render {

class TransferFunction;
class BrickPool;

/// What a frame draws: a store (bricks through its host cache) under a transfer function,
/// classified through `classifications` (shared by every renderer that is handed it).
struct Scene {
    const brickstore::BrickStore& store;
    brickstore::BrickCache& cache;
    const TransferFunction& tf;
    ClassificationCache& classifications;
};

/// What a frame classifies through: the shared classification, its table at the frame's step
/// and its octrees when the frame leaps inside bricks.
struct FrameClassification {
    std::shared_ptr<const Classification> classification;
    /// What samples classify through: the table at the frame's step for composite, the
    /// function as authored (step 1) for the other modes, which map one value per ray.
    std::shared_ptr<const TransferFunctionTable> table;
    /// What the brick plan decides transparency by: `table` for composite, else the mode's
    /// Classification::skipTable().
    std::shared_ptr<const TransferFunctionTable> skipTable;
    const OccupancyTrees* occupancy = nullptr; ///< null: no second-stage skipping this frame
    /// With RenderOptions::preintegrate: the classification's pre-integration table.
    std::shared_ptr<const PreintegratedTable> preintegrated;
};

/// The one place a frame gets its classification, for its mode (SkipRule): octrees when
/// options.skip is All (and the store has an apron; never for BlendMode::Average, which skips
/// nothing), the table at `stepVoxels`. Records the octree build in `stats` when this frame
/// made it (0 bricks rebuilt when another frame or session already had).
/// @throw std::invalid_argument when an isosurface's value lies outside the volume's values.
FrameClassification classifyFrame(const Scene& scene, std::uint32_t level,
                                  const RenderOptions& options, double stepVoxels,
                                  FrameStats& stats);

class Renderer;

/// What a renderer that keeps bricks resident on the GPU (the GPU raycaster) lets its owner
/// do: share one pool among the renderers of a store, and upload a predicted view's bricks
/// while idle.
class GpuResidency {
  public:
    virtual ~GpuResidency() = default;
    /// Draw from `pool` instead of a pool of its own (nullptr: back to its own).
    virtual void setSharedPool(std::shared_ptr<BrickPool> pool) = 0;
    /// The pool of the last frame (nullptr before the first).
    virtual const BrickPool* pool() const = 0;
    /// Uploads up to `maxUploads` bricks `view` would sample that the pool lacks; returns how
    /// many. @throw what Renderer::render throws for its inputs.
    virtual std::uint32_t prefetch(const Scene& scene, const View& view,
                                   const RenderOptions& options, std::uint32_t maxUploads) = 0;
};

/// Not thread-safe: one frame at a time per instance. GL renderers need a current EglContext
/// on the calling thread.
class Renderer {
  public:
    virtual ~Renderer();

    /// Its name in the registry ("gpu", "cpu", "reference", "splat", "splat-gpu").
    virtual std::string_view name() const = 0;
    /// Draws one frame; `view` must be `options.width` x `options.height`. Fills `stats`.
    /// @throw std::invalid_argument on bad options or a view of another size; StoreCorrupt
    /// naming a brick; RenderError on a GL failure.
    virtual Image render(const Scene& scene, const View& view, const RenderOptions& options,
                         FrameStats& stats) = 0;

    /// For programs and tests: the camera validated here, classifications in a cache of this
    /// renderer's own.
    Image render(const brickstore::BrickStore& store, brickstore::BrickCache& cache,
                 const TransferFunction& tf, const Camera& camera, const RenderOptions& options,
                 FrameStats& stats);

    /// Its GPU residency, for renderers that keep bricks on the GPU; nullptr otherwise.
    virtual GpuResidency* gpuResidency() { return nullptr; }

    /// @throw std::invalid_argument when `view` is not the options' size, or when the options
    /// ask for a region of the image from a renderer that draws whole images only, for a part
    /// of the volume (RenderOptions::parts) from one that draws whole volumes only, or for a
    /// stride (RenderOptions::stride) from one that draws every pixel.
    static void checkView(const View& view, const RenderOptions& options, bool drawsRegions = false,
                          bool drawsParts = false, bool drawsStrided = false);
    /// @throw std::invalid_argument naming `renderer` when the options ask for
    /// pre-integration (RenderOptions::preintegrate), which it does not do.
    static void refusePreintegration(const RenderOptions& options, const char* renderer);
    /// @throw std::invalid_argument naming the field and `renderer` when the options ask for a
    /// mode other than composite, or for a crop box or clip planes, which it does not draw.
    static void refuseModesAndClips(const RenderOptions& options, const char* renderer);

  private:
    std::unique_ptr<ClassificationCache> mOwnClassifications;
};

} // namespace bc::render
