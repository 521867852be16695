#pragma once
// The render thread's counters and what they export (RenderService::collect): frames by
// renderer, times and bytes, per-frame histograms, the GPU pool's tier per volume (carried across
// pool rebuilds, so that the exported counters never go down), prefetch, and under MPI each
// rank's share. Not thread-safe: RenderService calls it under its mutex.
#include "protocol/Messages.h"
#include "render/BrickPool.h"
#include "render/Classification.h"
#include "render/RendererChoice.h"
#include "server/FrameCache.h"
#include "server/Metrics.h"

#include <map>
#include <optional>
#include <string>
#include <vector>

namespace bc::server {

class FrameCluster;

/// What one frame measured.
struct FrameRecord {
    std::string renderer;
    double latencyMs = 0, renderMs = 0, uploadMs = 0, encodeMs = 0;
    double workingSetBytes = 0, bricks = 0, bricksUploaded = 0;
    double bricksDeferred = 0, bricksRequested = 0; ///< ray-guided residency
};

/// What the counters are exported beside: the render thread's state as RenderService::collect
/// found it.
struct RenderMetricsContext {
    std::size_t slotsWaiting = 0;
    std::size_t framesInProgress = 0; ///< frames drawn in slices, begun and not finished
    /// The render thread waits with nothing to do: no frame in progress, none owed to any
    /// session (now or at rest), no prefetch.
    bool idle = false;
    const FrameCluster* cluster = nullptr; ///< under MPI
    FrameCacheStats frameCache;
    render::ClassificationStats classifications;
    bool gpuUnavailable = false;
    std::optional<render::RendererChoice> autoChoice;
};

struct RenderCounters {
    std::map<std::string, double> frames; ///< per renderer
    double refined = 0, errors = 0, renderMs = 0, encodeMs = 0, bytes = 0, samples = 0;
    double refused = 0, cancelled = 0, slices = 0, checks = 0;
    Histogram latencyMs{Histogram::series125(1, 10000)};
    Histogram renderMsHist{Histogram::series125(1, 10000)};
    Histogram uploadMs{Histogram::series125(0.1, 10000)};
    Histogram encodeMsHist{Histogram::series125(0.01, 1000)};
    Histogram workingSet{Histogram::geometric(64 * 1024, 64.0 * (1ull << 30), 4)};
    Histogram frameBytes{Histogram::geometric(256, 64.0 * (1 << 20), 4)};
    /// Per volume: the live pool's counters (as of its last frame) and those of pools
    /// replaced or freed before it, so the exported counters never go down.
    std::map<std::string, render::BrickPoolStats> poolLive, poolRetired;
    std::map<std::string, double> poolBudget;
    /// Per volume: bricks uploaded while a frame waited for them, and by prefetch while idle.
    std::map<std::string, double> frameUploads, prefetchUploads, prefetchBytes;
    std::map<std::string, double> deferred, requested; ///< ray-guided residency, per volume
    double prefetchMs = 0;
    double gpuContext = 0; ///< 1 once the render thread has made its GL context
    // Under MPI: slices drawn across the ranks, their compositing and each rank's share.
    double clusterSlices = 0, clusterBytes = 0, clusterFailures = 0;
    Histogram clusterCompositeMs{Histogram::series125(0.1, 10000)};
    Histogram clusterImbalance{{1.05, 1.1, 1.25, 1.5, 2, 3, 5, 10}};
    std::vector<double> rankRenderMs, rankSamples; ///< per rank, summed over slices
    double lastImbalance = 1;

    /// A frame drawn and encoded into `bytes`; `pool` is the GPU pool it drew from, if any.
    void recordFrame(const FrameRecord& f, double bytes, const std::string& volume,
                     const render::BrickPool* pool);
    /// A frame answered from the frame cache: its bytes, latency and encoding.
    void recordCached(const protocol::FrameHeader& h, double bytes, double latencyMs);
    /// `volume`'s pool is replaced or freed: its counters carry on in the retired ones.
    void retirePool(const std::string& volume);
    void exportTo(MetricSet& m, const RenderMetricsContext& context) const;
};

} // namespace bc::server
