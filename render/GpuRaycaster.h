#pragma once
// The GPU raycaster: bricks of one pyramid level, drawn front to back in batches that fit
// the GPU brick pool, each batch one full-screen pass that marches every ray through the
// brick grid (DDA), sampling only the batch's bricks and compositing onto the previous
// pass's result. With a pool large enough for the view there is one pass. A region of the
// image (a slice of a frame the daemon draws in slices) is drawn under a scissor. Needs a current
// EglContext on the calling thread; render thread only.
#include "render/BrickPlan.h"
#include "render/BrickPool.h"
#include "render/Partition.h"
#include "render/Renderer.h"

#include <cstdint>
#include <memory>
#include <vector>

namespace bc::brickstore {
class BrickStore;
class BrickCache;
} // namespace bc::brickstore

namespace bc::render {

class TransferFunction;
class OccupancyTrees;
struct LevelGeometry;
struct BrickPlan;
struct TransferFunctionTable;

struct GpuRaycasterConfig {
    std::uint64_t gpuBudgetBytes = 512ull << 20; ///< brick pool bytes (of a pool of its own)
};

class GpuRaycaster final : public Renderer, public GpuResidency {
  public:
    /// @throw RenderError if the shaders do not build on this context.
    explicit GpuRaycaster(const GpuRaycasterConfig& config = {});
    ~GpuRaycaster() override;
    GpuRaycaster(const GpuRaycaster&) = delete;
    GpuRaycaster& operator=(const GpuRaycaster&) = delete;

    std::string_view name() const override { return "gpu"; }
    /// Renders one frame of the scene (bricks come through its cache). Fills `stats`.
    /// @throw std::invalid_argument on bad options or view; StoreCorrupt naming a brick
    /// that fails its checksum; RenderError on a GL failure.
    Image render(const Scene& scene, const View& view, const RenderOptions& options,
                 FrameStats& stats) override;
    using Renderer::render;

    /// A new pool budget (a daemon's fair share changed): the next frame allocates a pool of
    /// that size, and what the old pool held is uploaded again as needed.
    void setGpuBudgetBytes(std::uint64_t budgetBytes);

    /// Draws from `pool` instead of a pool of its own (nullptr: back to its own): raycasters of
    /// one store share the bricks resident on the GPU, each keeping its own octrees and
    /// occlusion frustums (a daemon's sessions). They must render on one thread, one frame at
    /// a time; the pool must hold this store's bricks only. @throw RenderError at the next
    /// frame when the pool's voxel type or slot edge does not fit the store.
    void setSharedPool(std::shared_ptr<BrickPool> pool) override;

    /// Uploads into the pool, nearest first, up to `maxUploads` bricks of the view `camera`
    /// would sample that the pool lacks (the level render() would choose; constant and
    /// transparent bricks need none), drawing nothing. LRU evicts the least recently used
    /// slots, so a caller that passes at most capacity - (bricks of the last frame) keeps
    /// every brick of the last frame resident. Returns the bricks uploaded.
    /// @throw what render() throws for its inputs.
    std::uint32_t prefetch(const Scene& scene, const View& view, const RenderOptions& options,
                           std::uint32_t maxUploads) override;

    /// The pool of the last frame (nullptr before the first); its counters span all frames.
    const BrickPool* pool() const override { return mPool.get(); }
    GpuResidency* gpuResidency() override { return this; }

  private:
    struct Gpu;
    struct Prepared;
    PartitionCache mPartitions; ///< RenderOptions::parts
    /// Validates, readies the pool, chooses the level and classifies (octrees uploaded).
    Prepared prepare(const Scene& scene, const View& view, const RenderOptions& options,
                     FrameStats& stats);
    void ensurePool(const brickstore::BrickStore& store);
    /// The bricks of level p.level the rays of `region` of `view` draw: planned by the mode's
    /// skip table, only this part's (RenderOptions::parts), none wholly outside the clip.
    BrickPlan planFor(const brickstore::BrickStore& store, const Prepared& p, const View& view,
                      const PixelRect& region, const RenderOptions& options);
    /// Pins the next bricks of `plan` into pool slots and marks them in `pages`; returns their
    /// indices.
    std::vector<std::uint64_t> fillBatch(const BrickPlan& plan, std::size_t& next,
                                         std::uint64_t levelFirst, brickstore::BrickCache& cache,
                                         std::vector<std::int32_t>& pages);
    /// Binds the frame's buffers and targets; `feedback`: rays record the bricks they enter.
    void bindFrame(std::size_t pageInts, std::uint64_t brickCount, bool feedback);
    /// Draws `plan` in front-to-back batches that fit the pool; `pass` counts the passes.
    void drawBatches(const BrickPlan& plan, std::uint64_t levelFirst, brickstore::BrickCache& cache,
                     std::vector<std::int32_t>& pages, int& pass, FrameStats& stats);
    /// Draws `plan` in one batch without its `deferred` bricks (indices into plan.drawn), then
    /// loads those that stopped rays ask for and continues them, until none asks. False, with
    /// the image unfinished, when the rest of the plan or a request does not fit the pool.
    bool drawGuided(const BrickPlan& plan, const std::vector<std::size_t>& deferred,
                    std::uint64_t levelFirst, brickstore::BrickCache& cache,
                    std::vector<std::int32_t>& pages, int& pass, FrameStats& stats);
    /// The frame's octrees (if any) on the GPU: uploaded when they are another
    /// classification's than the buffer holds (only the changed bricks' words when the buffer
    /// holds the classification they were updated from).
    void uploadOccupancy(const FrameClassification& classified);
    /// Under a running skip (runsSkip()), the bounds it compares on the GPU: per brick of
    /// `level` its stored range's, then per octree leaf of each its own, widened as the CPU
    /// raycaster's and mapped to pool texels; the shader's uRunning off otherwise.
    void uploadRunningBounds(const brickstore::BrickStore& store, std::uint32_t level,
                             const FrameClassification& classified, const RenderOptions& options);
    /// The distance maps (FineOccupancy) of the plan's sampled bricks but `deferred` (indices
    /// into plan.drawn), built from their voxels (pinned one by one) where not yet; the pool's
    /// new slots appended to the GPU's copy, each brick's offset in the per-brick table.
    /// Without maps (none for these options) the shader walks the octree alone.
    void uploadCells(const Scene& scene, const FrameClassification& classified,
                     const RenderOptions& options, const BrickPlan& plan,
                     const std::vector<std::size_t>& deferred, std::uint64_t brickCount,
                     FrameStats& stats);
    void drawPass(int pass);
    std::uint64_t sceneKey(const brickstore::BrickStore& store, std::uint32_t level,
                           const TransferFunctionTable& table, const RenderOptions& options) const;
    /// Builds this frame's ray starts from the last frame's occlusion frustums when allowed
    /// (returns whether the raycaster uses them) and readies the first-hit image.
    bool prepareOcclusion(const LevelGeometry& g, const ViewBasis& view, std::uint64_t scene,
                          const RenderOptions& options, const OccupancyTrees* octree,
                          FrameStats& stats);
    /// The pixels of `region` (of an image `imageHeight` rows high) after `passes` passes:
    /// clamped to [0, 1] (to [0, inf) when not `clamp`), or as the passes left them when `raw`
    /// (a projection's value, count and flag).
    Image readBack(int passes, const PixelRect& region, std::uint32_t imageHeight, bool clamp,
                   bool raw, FrameStats& stats);
    std::uint32_t chooseLevel(const brickstore::BrickStore& store,
                              const TransferFunctionTable& table, const ViewBasis& view,
                              const RenderOptions& options);

    GpuRaycasterConfig mConfig;
    std::unique_ptr<Gpu> mGpu;
    std::shared_ptr<BrickPool> mPool;
    std::shared_ptr<BrickPool> mSharedPool;
    const brickstore::BrickStore* mPoolStore = nullptr;
    std::string mPoolStorePath;
    std::uint64_t mPoolBytes = 0; ///< the budget mPool was made with, when it is our own
};

} // namespace bc::render
