#include "render/HybridSplatter.h"

#include "brickstore/BrickCache.h"
#include "brickstore/BrickStore.h"
#include "render/BrickPlan.h"
#include "render/Occupancy.h"
#include "render/SplatFootprint.h"
#include "render/SplatGeometry.h"
#include "render/TransferFunction.h"
#include "render/detail/HybridSplatDrawer.h"
#include "render/detail/SplatPrep.h"

#include <algorithm>
#include <chrono>
#include <cmath>
#include <stdexcept>
#include <vector>

namespace bc::render {
namespace {

using detail::Canvas;
using detail::ChunkDrawer;
using detail::Frame;
using detail::PreparedBrick;
using detail::SplatScene;

using Clock = std::chrono::steady_clock;
double msSince(Clock::time_point t) {
    return std::chrono::duration<double, std::milli>(Clock::now() - t).count();
}

/// The whole view's plan, less the bricks that cannot reach the region: its own frustum
/// (planBricks for a region) would lose splats that reach into it from outside.
BrickPlan planOf(const brickstore::BrickStore& store, const SplatScene& splat, const Frame& f,
                 const View& view, const RenderOptions& options, FrameStats& stats) {
    BrickPlan plan =
        planBricks(store, splat.g, splat.table(), view.basis, options.skip, splat.occupancy());
    detail::cullOutsideRegion(f, options.region, options.width, options.height, plan);
    recordPlan(plan, splat.level, stats);
    stats.batches = 1;
    return plan;
}

/// Draws the plan in chunks: each culled against the canvas, prepared on every core (timed as
/// uploadMs), then drawn.
void drawChunks(const Scene& scene, const SplatScene& splat, const Frame& f, const BrickPlan& plan,
                ChunkDrawer& drawer, FrameStats& stats) {
    brickstore::BrickCache& cache = scene.cache;
    const auto type = scene.store.info().volume.type;
    const std::uint64_t brickBytes = scene.store.brickBytes(), budget = cache.stats().budgetBytes;
    for (std::size_t first = 0, end; first < plan.drawn.size(); first = end) {
        end = detail::chunkEnd(plan, first, brickBytes, budget);
        std::vector<PreparedBrick> chunk(end - first);
        drawer.cullBricks(plan.drawn.data() + first, chunk);
        const auto prepareStart = Clock::now();
        detail::prepareChunk(f, plan, first, cache, type, splat.occupancy(), chunk);
        stats.uploadMs += msSince(prepareStart);
        drawer.draw(chunk);
    }
}

} // namespace

void HybridSplatterConfig::validate() const {
    if (!(radiusVoxels >= 0.5 && radiusVoxels <= 8.0))
        throw std::invalid_argument("HybridSplatterConfig.radiusVoxels must be in [0.5, 8]");
    SplatFootprintConfig{sigmaOverRadius}.validate();
    if (!(pointThresholdPixels >= 0.0 && std::isfinite(pointThresholdPixels)))
        throw std::invalid_argument("HybridSplatterConfig.pointThresholdPixels must be >= 0");
    if (!(pointFilterPixels >= 0.5 && pointFilterPixels <= 16.0))
        throw std::invalid_argument("HybridSplatterConfig.pointFilterPixels must be in [0.5, 16]");
    if (tilePixels < 1 || tilePixels > 256)
        throw std::invalid_argument("HybridSplatterConfig.tilePixels must be in [1, 256]");
}

HybridSplatter::HybridSplatter(const HybridSplatterConfig& config)
    : mConfig((config.validate(), config)),
      mFootprint(SplatFootprintConfig{config.sigmaOverRadius}) {}
HybridSplatter::~HybridSplatter() = default;

Image HybridSplatter::render(const Scene& scene, const View& view, const RenderOptions& options,
                             FrameStats& stats) {
    const auto frameStart = Clock::now();
    stats = FrameStats{};
    mLast = HybridSplatStats{};
    // Opacity per unit step: the footprint supplies each voxel's own path length.
    const SplatScene splat = detail::sceneOf(scene, view, options, stats);
    const Frame f = detail::frameOf(mConfig, splat.g, view.basis, options, splat.table());
    const BrickPlan plan = planOf(scene.store, splat, f, view, options, stats);

    Canvas canvas(options.drawn(), mConfig.tilePixels,
                  options.earlyTermination ? options.ertThreshold : 2.0);
    ChunkDrawer drawer(f, mFootprint, mConfig, options.width, options.height, canvas, mLast);
    drawChunks(scene, splat, f, plan, drawer, stats);
    for (float& v : canvas.image.rgba)
        v = std::clamp(v, 0.0f, 1.0f);
    stats.samples = mLast.points + mLast.splats;
    stats.octreeLeaps = mLast.leavesSkipped;
    stats.occlusionReason = "not on the splatter";
    stats.totalMs = msSince(frameStart);
    stats.renderMs = stats.totalMs - stats.uploadMs;
    return std::move(canvas.image);
}

} // namespace bc::render
