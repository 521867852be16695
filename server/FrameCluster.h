#pragma once
// The daemon's side of scale-out (render/SCALEOUT.md): the render thread of rank 0
// hands each frame (or slice of one) of a raycaster that draws parts to a FrameCluster, which
// has every rank draw its part of the volume and composites the parts. The interface knows
// nothing of MPI: server/cluster/ implements it over MPI ranks, and a daemon without one is
// today's single process.
#include "render/Image.h"
#include "render/RenderTypes.h"
#include "server/ClusterOrder.h"

#include <algorithm>
#include <cstdint>
#include <functional>
#include <stdexcept>
#include <string>
#include <vector>

namespace bc::brickstore {
class BrickStore;
}
namespace bc::render {
struct View;
}

namespace bc::server {

/// One rank's share of a frame (or slice).
struct RankFrameStats {
    double renderMs = 0;
    std::uint64_t samples = 0;
    std::uint64_t bytesSent = 0; ///< compositing, pieces and band
};

/// What a cluster frame cost, rank by rank.
struct ClusterFrameStats {
    std::vector<RankFrameStats> ranks; ///< ranks[r] is rank r's
    double compositeMs = 0;            ///< at rank 0, from its part drawn to the slice composited

    double renderMsMax() const {
        double m = 0;
        for (const auto& r : ranks)
            m = std::max(m, r.renderMs);
        return m;
    }
    double renderMsMean() const {
        double sum = 0;
        for (const auto& r : ranks)
            sum += r.renderMs;
        return ranks.empty() ? 0.0 : sum / double(ranks.size());
    }
    /// max / mean render ms (1 when nothing was drawn).
    double imbalance() const {
        const double mean = renderMsMean();
        return mean > 0 ? renderMsMax() / mean : 1.0;
    }
    std::uint64_t bytesComposited() const {
        std::uint64_t sum = 0;
        for (const auto& r : ranks)
            sum += r.bytesSent;
        return sum;
    }
    std::uint64_t samples() const {
        std::uint64_t sum = 0;
        for (const auto& r : ranks)
            sum += r.samples;
        return sum;
    }
};

class FrameCluster {
  public:
    virtual ~FrameCluster() = default;
    virtual std::uint32_t ranks() const = 0;

    /// Draws rank 0's part with these options (parts, part and region set): the renderer of
    /// the session's frame, on the render thread.
    using DrawPart = std::function<render::Image(const render::RenderOptions& options,
                                                 render::FrameStats& stats)>;

    /// Has every rank draw its part of `order` and composites the parts front to back.
    /// `options` and `view` are the order's (options.region is the slice). Returns the slice
    /// (order.region's size), clamped premultiplied RGBA, as a one-process renderer draws it;
    /// `stats` gets rank 0's part stats in `mine` and every rank's in `cluster`. Render thread
    /// only.
    /// @throw ClusterFailed when a rank did not answer within the timeout or MPI failed (the
    /// cluster is out of service from then on: every later call throws at once, saying why);
    /// what `drawMine` throws (the other ranks' parts are still composited and dropped).
    virtual render::Image draw(const ClusterOrder& order, const brickstore::BrickStore& store,
                               const render::View& view, const render::RenderOptions& options,
                               const DrawPart& drawMine, render::FrameStats& mine,
                               ClusterFrameStats& cluster) = 0;

    /// The render thread calls this at least every second while idle (it keeps workers sure
    /// that rank 0 lives). Never throws.
    virtual void idle() = 0;
};

/// A cluster frame failed: a rank did not answer, or MPI failed.
class ClusterFailed : public std::runtime_error {
  public:
    using std::runtime_error::runtime_error;
};

} // namespace bc::server
