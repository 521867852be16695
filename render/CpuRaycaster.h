#pragma once
// The CPU raycaster: the GPU raycaster's twin for machines without a GPU, where llvmpipe
// runs the shader at a few million samples per second. Same brick plan, same octree leaps,
// same sample positions and the same optical model as the shader (render/OPTICS.md), in
// float, on every core (TBB over 8x8 pixel tiles). Bricks come from the host cache, under its
// budget: the front-to-back plan is drawn in batches whose bricks fit the budget (one when
// they all do), each pinned only while its pass runs, every ray carrying its colour and its
// place in the brick grid from pass to pass, so the image does not depend on the budget
// (render/RESIDENCY.md). No pin outlives render(). It draws a region (the daemon's slices), a
// part of the brick grid (MPI ranks) and a stride (RenderOptions::stride: the rays of a lattice
// of pixels, the daemon's check of a first pass at rest), each pixel as in the whole frame.
// Occlusion frustums are a GPU technique and are not used here. Not thread-safe: one frame at
// a time per instance.
#include "render/Partition.h"
#include "render/Renderer.h"

#include <memory>
#include <string>

namespace bc::brickstore {
class BrickStore;
class BrickCache;
} // namespace bc::brickstore

namespace bc::render {

class TransferFunction;
class OccupancyTrees;

class CpuRaycaster final : public Renderer {
  public:
    CpuRaycaster();
    ~CpuRaycaster() override;
    CpuRaycaster(const CpuRaycaster&) = delete;
    CpuRaycaster& operator=(const CpuRaycaster&) = delete;

    std::string_view name() const override { return "cpu"; }
    /// Renders one frame at options.level (interactive is ignored). Pins at most the host
    /// cache's budget at once (one brick when the budget holds less). Fills `stats` (no
    /// uploads; batches = passes; uploadMs = pinning).
    /// @throw std::invalid_argument on bad options; StoreCorrupt naming a brick.
    Image render(const Scene& scene, const View& view, const RenderOptions& options,
                 FrameStats& stats) override;
    using Renderer::render;

    /// The instruction set RenderOptions::simd runs on here and its lanes ("AVX3_SPR x16").
    static std::string simdTarget();

  private:
    PartitionCache mPartitions; ///< RenderOptions::parts
};

} // namespace bc::render
