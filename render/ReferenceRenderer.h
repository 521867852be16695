#pragma once
// The CPU reference renderer: the raycaster's optical model (render/OPTICS.md) in double
// precision, with no skipping of any kind and no early termination, at any step size, on
// all cores. It is the yardstick every accuracy and speed claim is measured against.
#include "render/Camera.h"
#include "render/Image.h"
#include "render/RenderTypes.h"
#include "render/Renderer.h"

#include <cstdint>
#include <memory>
#include <vector>

namespace bc::brickstore {
class BrickStore;
}

namespace bc::render {

class TransferFunction;

/// One pyramid level held whole in host memory (float is exact for every stored type).
class ReferenceVolume {
  public:
    /// Reads level `level` of `store` through its extract stream. @throw StoreCorrupt.
    ReferenceVolume(const brickstore::BrickStore& store, std::uint32_t level);

    /// Trilinear value at continuous voxel position p (voxel centres at i + 0.5), clamped
    /// to the edge outside the volume, computed in double.
    double sample(double px, double py, double pz) const;
    const std::array<std::uint64_t, 3>& dims() const { return mDims; }

  private:
    std::array<std::uint64_t, 3> mDims{};
    std::vector<float> mVoxels;
};

struct ReferenceConfig {
    unsigned threads = 0; ///< 0 = all cores
};

/// Renders with options.width/height/stepVoxels/shading/level; ignores skip and early
/// termination (the reference does neither). Fills stats.samples, level and totalMs.
Image renderReference(const brickstore::BrickStore& store, const ReferenceVolume& volume,
                      const TransferFunction& tf, const Camera& camera,
                      const RenderOptions& options, FrameStats& stats,
                      const ReferenceConfig& config = {});
/// The same for a validated view and the table it classifies through (full precision: the
/// table must hold the step's opacities), and the pre-integration table when
/// options.preintegrate (std::invalid_argument without one).
Image renderReference(const brickstore::BrickStore& store, const ReferenceVolume& volume,
                      const TransferFunctionTable& table, const ViewBasis& view,
                      const RenderOptions& options, FrameStats& stats,
                      const ReferenceConfig& config = {},
                      const PreintegratedTable* preintegrated = nullptr);

struct ReferenceRendererConfig {
    /// Largest level it draws (it takes every sample of every ray, however slow).
    std::uint64_t maxVoxels = 64ull << 20;
    ReferenceConfig threads;
};

/// The reference as a Renderer. It samples the level's bricks through the host cache, in
/// front-to-back batches whose bricks fit the cache's budget, each pinned only while its pass
/// runs (no pin outlives render()); every sample reads the voxels ReferenceVolume would read,
/// so the image is renderReference's to the bit, whatever the budget (render/RESIDENCY.md).
/// A store with aprons under 2 voxels cannot be sampled brick by brick: its level is read
/// whole (ReferenceVolume) and kept while the same one is drawn.
class ReferenceRenderer final : public Renderer {
  public:
    explicit ReferenceRenderer(const ReferenceRendererConfig& config = {});
    ~ReferenceRenderer() override;
    std::string_view name() const override { return "reference"; }
    /// @throw std::invalid_argument on bad options or view, or a level over maxVoxels;
    /// StoreCorrupt.
    Image render(const Scene& scene, const View& view, const RenderOptions& options,
                 FrameStats& stats) override;
    using Renderer::render;

  private:
    Image renderWhole(const Scene& scene, const TransferFunctionTable& table,
                      const PreintegratedTable* preintegrated, const View& view,
                      const RenderOptions& options, FrameStats& stats);

    ReferenceRendererConfig mConfig;
    std::unique_ptr<ReferenceVolume> mVolume;
    std::uint64_t mStoreInstance = 0;
    std::uint32_t mLevel = 0;
};

} // namespace bc::render
