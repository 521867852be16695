#pragma once
// Prefetch (frames.prefetch): after a GPU frame, its session's next view is predicted from its
// last two (render::predictNext), and while the render thread has no frame due, the bricks that
// view would sample and the volume's GPU pool lacks are uploaded ahead of need, a bounded step
// at a time. A wrong guess costs uploads, never a wrong frame. Render thread only.
#include "render/Camera.h"
#include "render/RenderTypes.h"

#include <cstdint>
#include <exception>
#include <functional>
#include <memory>
#include <optional>
#include <string>

namespace bc::render {
struct BrickPoolStats;
class ClassificationCache;
class Renderer;
class TransferFunction;
} // namespace bc::render

namespace bc::server {

struct FrameDrawing;
class RendererCache;
struct Volume;

/// Bricks a frame held resident: those it drew, less constant ones (no texture) and those
/// ray-guided residency left unloaded.
std::uint64_t residentBricks(const render::FrameStats& stats);

/// Bricks one prefetch step uploads at most: a session whose frame falls due waits for at most
/// this many uploads; the rest of the job waits for the next idle turn.
inline constexpr std::uint32_t kPrefetchStepBricks = 32;

/// What to upload for a session's predicted next view.
struct PrefetchJob {
    render::Renderer* renderer = nullptr; ///< the session's, with gpuResidency()
    std::shared_ptr<Volume> volume;
    std::shared_ptr<const render::TransferFunction> tf;
    render::Camera camera; ///< predicted
    render::RenderOptions options;
    /// Bricks to leave in the pool: the last frame's, and what earlier steps brought in.
    std::uint64_t lastFrameBricks = 0;
};

/// One step of a job in a pool of `capacity` slots.
struct PrefetchStep {
    std::uint32_t room = 0;   ///< slots beside the bricks to leave (0: nothing to do)
    std::uint32_t bricks = 0; ///< uploads at most: room, up to kPrefetchStepBricks
    /// Whether more may be missing after a step that uploaded `uploaded`: the job goes on at the
    /// next idle turn.
    bool continues(std::uint32_t uploaded) const { return uploaded == bricks && bricks < room; }
};

/// The next step of a job whose pool has `capacity` slots and that leaves `lastFrameBricks`.
PrefetchStep prefetchStep(std::uint64_t lastFrameBricks, std::uint32_t capacity);

/// A session's GPU views and what to prefetch for its next.
class SessionPrefetch {
  public:
    /// A GPU frame of `camera` was drawn: the job planned before is dropped. Returns the camera
    /// predicted next when `plan` and the frame before had a camera too, else nullopt.
    std::optional<render::Camera> afterFrame(const render::Camera& camera, bool plan);

    std::optional<PrefetchJob> job;

  private:
    std::optional<render::Camera> mLast, mPrevious;
};

/// After frame `d` (complete) drawn by `renderer`: when that is a GPU renderer, plans `mine`'s
/// job for the predicted next view if `enabled` and the renderer has a pool.
void planPrefetch(SessionPrefetch& mine, const FrameDrawing& d, render::Renderer& renderer,
                  bool enabled);

/// What runPrefetch tells its caller: a step's uploads (`bytes`) to `volume`'s pool, and the
/// pool's counters after it; a job that failed (a bad guess: nothing but the log line).
struct PrefetchReports {
    std::function<void(const std::string& volume, std::uint32_t bricks, std::uint64_t bytes,
                       const render::BrickPoolStats& pool)>
        uploaded;
    std::function<void(const std::shared_ptr<Volume>& volume, const std::exception& e)> failed;
};

/// One step of every session's job (render thread, when no frame is due).
void runPrefetch(RendererCache& renderers, render::ClassificationCache& classifications,
                 const PrefetchReports& reports);

} // namespace bc::server
