#pragma once
// The render thread: it owns the GL context and every renderer, and draws for the sessions in
// turn. A session writes what it wants into its RenderSlot (camera updates coalesce: the
// latest wins) and the thread takes the newest state of a slot whose write queue has room (in
// frames and in bytes), so a slow reader never makes frames pile up: it gets the newest view
// when it catches up. Network threads never wait for it: slots are a mutex and a condition
// variable away.
//
// Fairness: every frame's cost (pixels x samples per ray, an upper bound) is checked against a
// cap before it is drawn; a frame of a renderer that draws regions (every built-in renderer)
// and would take longer than a slice is drawn in slices of about RenderServiceConfig::sliceMs
// (row bands, or runs of one row: render::RenderOptions::region), and
// the sessions take turns between slices, so a heavy frame costs every other session at most
// one slice per turn. A frame whose session has gone, or whose camera has been superseded, is
// dropped at its next slice; stopping the service stops within one slice.
//
// A frame that fails on a store error while the store's file has changed on disk takes its
// volume out of service (Catalog::markFailed): later frames of it are refused at once.
#include "protocol/FrameCodec.h"
#include "protocol/Messages.h"
#include "render/Image.h"
#include "render/RenderTypes.h"
#include "render/RendererChoice.h"
#include "render/TransferFunction.h"
#include "server/RenderSlot.h"
#include "server/SlicePlanner.h"

#include <chrono>
#include <condition_variable>
#include <cstdint>
#include <functional>
#include <map>
#include <memory>
#include <mutex>
#include <optional>
#include <string>
#include <thread>
#include <vector>

namespace bc::render {
class BrickPool;
class ClassificationCache;
class Renderer;
} // namespace bc::render

namespace bc::server {

class FrameCache;
class FrameCluster;
class RendererCache;
struct ClusterFrameStats;
struct Volume;
class Catalog;
class Log;
class RenderService;
class MetricSet;
struct RenderCounters;
struct FrameRecord;

struct RenderServiceConfig {
    std::uint64_t gpuBudgetBytes = 512ull << 20;
    std::uint32_t restMs = 150;
    bool prefetch = true; ///< DaemonConfig::prefetch
    /// Classifications (TF tables and octrees) kept once no session uses them: an eighth of
    /// the host budget by default (Daemon).
    std::uint64_t classificationBudgetBytes = 128ull << 20;
    /// Cost caps (samples: pixels x samples of the longest ray, or the splatters' voxels):
    /// a frame over its cap is refused with OutOfRange. Renderers that draw regions are sliced
    /// and take `maxFrameSamples`; a renderer that draws whole frames only (none of the
    /// built-in ones; RendererKind::regions) takes `maxUnslicedSamples`.
    std::uint64_t maxFrameSamples = 64ull << 30;
    std::uint64_t maxUnslicedSamples = 4ull << 30;
    std::uint32_t sliceMs = 50; ///< target length of one slice of a long frame
    /// DaemonConfig::interactiveMs: the time an interactive frame should take; 0: half size.
    std::uint32_t interactiveMs = 0;
    /// Encoded frames kept for identical requests of any session (FrameCache.h); 0: none.
    std::uint64_t frameCacheBytes = 64ull << 20;
    /// Under MPI: the ranks that draw the CPU and GPU raycasters' frames with this one
    /// (FrameCluster.h); null: this process draws every frame. Used on the render thread only.
    FrameCluster* cluster = nullptr;
};

struct FrameDrawing;
class InteractiveBudget;

class RenderService {
  public:
    /// Told on the render thread, once per volume, that a volume was taken out of service
    /// (Catalog::markFailed): a frame found its store changed on disk. Must not block.
    using VolumeFailed = std::function<void(std::shared_ptr<Volume> volume)>;
    /// Starts the render thread. It makes its GL context when the first frame of a GPU
    /// renderer asks for one, never before (a server that draws on the CPU only never loads
    /// the driver); when it cannot, that frame and every later GPU frame fail with RenderFailed
    /// saying why, and the CPU renderers still serve. The first frame asking for auto makes the
    /// context too, to decide between the GPU and the CPU raycaster (autoChoice).
    RenderService(const RenderServiceConfig& config, Catalog& catalog, Log& log,
                  VolumeFailed volumeFailed = {});
    /// Stops and joins the thread (within about one slice); frames not yet drawn are not drawn.
    ~RenderService();
    RenderService(const RenderService&) = delete;
    RenderService& operator=(const RenderService&) = delete;

    /// A slot for a new session.
    std::shared_ptr<RenderSlot> open(RenderSlot::Deliver deliver, std::uint32_t queueFrames,
                                     std::uint64_t queueBytes);
    /// Why the GPU renderers cannot serve (the GL context could not be made), or nullopt when
    /// nothing is known against them (the context is made, or not asked for yet). Thread-safe.
    std::optional<std::string> gpuUnavailable();
    /// Frames (per renderer), errors, time and bytes; per-frame histograms of latency
    /// (oldest change answered -> encoded), render, upload and encode ms, working set and
    /// encoded bytes; the host -> GPU tier per volume (hits, uploads, evictions, bytes,
    /// re-fetches; counters carried across pool rebuilds); render slots waiting.
    void collect(MetricSet& metrics);

  private:
    friend class RenderSlot;
    void run();
    /// Makes the GL context on the first call (render thread), logging that it was made
    /// `forWhat`; later calls return at once.
    /// @throw std::runtime_error saying why when it cannot be made (then and every time after).
    void makeContext(const char* forWhat = "the first GPU frame");
    /// What `auto` draws with (render thread): decided at the first call from the GL context
    /// (made then if need be) and logged; the same on every call after. Never throws.
    const render::RendererChoice& autoChoice();
    void notify();
    /// The next slot due, or nullptr after waiting (not at all when `mayWait` is false) for one.
    std::shared_ptr<RenderSlot> nextReady(std::unique_lock<std::mutex>& lock, bool mayWait);
    /// Uploads the predicted next view's missing bricks of every GPU session (render thread,
    /// when no frame is due).
    void runPrefetch();
    /// One turn of `slot`: starts `job` when given, else goes on with the frame in progress;
    /// draws one slice (or the whole frame) and delivers the frame once it is complete.
    void turn(const std::shared_ptr<RenderSlot>& slot, std::optional<RenderSlot::Job> job);
    /// Resolves the frame's options and view, checks its cost and decides on slices
    /// (planSlices).
    void prepare(FrameDrawing& d);
    /// Draws the next slice with the session's renderer (drawNext); true when the frame is
    /// complete, and its session's next view is then planned for prefetch.
    bool drawSlice(const std::shared_ptr<RenderSlot>& slot, FrameDrawing& d);
    /// How long a slice of `d` should be: `frames.slice_ms`, but a refined frame's, while other
    /// sessions move, their share of `frames.interactive_ms` (each of the n moving and this one
    /// gets interactive_ms / (n + 1), at least 10 ms): a moving session's frame then waits for
    /// short slices of the frames at rest, not for whole 50 ms ones.
    double sliceMsBeside(const std::shared_ptr<RenderSlot>& slot, const FrameDrawing& d) const;
    /// Draws `options.region` of the frame: with `renderer` here, or across the cluster's
    /// ranks when there is one and the frame is a raycaster's (a sparse frame, options.stride,
    /// is drawn here).
    render::Image drawRegion(render::Renderer& renderer, const FrameDrawing& d,
                             const render::RenderOptions& options, render::FrameStats& stats);
    protocol::Frame finish(RenderSlot& slot, FrameDrawing& d, FrameRecord& record);
    /// The frame `d` (prepared) from the frame cache, encoded for `slot`, or nullopt when the
    /// cache has no frame for its key (then d.cacheKey is set for finish() to keep it).
    std::optional<protocol::Frame> fromCache(RenderSlot& slot, FrameDrawing& d);
    /// Whether `slot` has a frame in progress (render thread).
    bool drawing(const RenderSlot* slot) const;
    /// Calls `f` with the counters, under mMutex (the render thread's counting).
    void withCounters(const std::function<void(RenderCounters& counters)>& f);
    /// After `e` failed a frame or prefetch of `volume`: a store error while its file has
    /// changed on disk takes the volume out of service (Catalog::markFailed) and tells
    /// mVolumeFailed.
    void checkStore(const std::shared_ptr<Volume>& volume, const std::exception& e);

    RenderServiceConfig mConfig;
    Catalog& mCatalog;
    Log& mLog;
    VolumeFailed mVolumeFailed;
    std::mutex mMutex;
    std::condition_variable mWake;
    std::vector<std::weak_ptr<RenderSlot>> mSlots;
    std::size_t mNextSlot = 0;
    bool mStop = false;
    /// What the render thread is doing, for collect(): it waits in nextReady() (having found
    /// nothing due), and the frames it has in progress (written on the render thread).
    bool mWaiting = false;
    std::size_t mFramesInProgress = 0;
    std::optional<std::string> mGpuUnavailable;        ///< set once by makeContext()
    std::optional<render::RendererChoice> mAutoChoice; ///< set once by autoChoice(), for metrics
    std::unique_ptr<RendererCache> mRenderers;         // render thread only
    /// Measured speed of each renderer in cost units (upper bounds of samples) per millisecond,
    /// from the whole frames it drew: whether a frame is sliced (render thread only).
    RendererSpeeds mFrameSpeeds;
    /// The same against each slice's pixels' estimated samples (sizes slices).
    RendererSpeeds mSliceSpeeds;
    /// The image scale of interactive frames (render thread only); null: half size.
    std::unique_ptr<InteractiveBudget> mBudget;
    /// Shared by every session and renderer (thread-safe).
    std::unique_ptr<render::ClassificationCache> mClassifications;
    std::unique_ptr<FrameCache> mFrames; ///< shared by every session (thread-safe)

    std::unique_ptr<RenderCounters> mCounters; // under mMutex
    std::thread mThread;
};

} // namespace bc::server
