#include "server/RenderService.h"

#include "render/BrickPool.h"
#include "render/Classification.h"
#include "render/EglContext.h"
#include "render/RendererRegistry.h"
#include "render/View.h"
#include "server/Catalog.h"
#include "server/Log.h"
#include "server/Metrics.h"
#include "server/ViewRequest.h"

#include <cmath>
#include <map>

namespace bc::server {

namespace {

double msSince(Clock::time_point t) {
    return std::chrono::duration<double, std::milli>(Clock::now() - t).count();
}

} // namespace

// ---- RenderSlot: the network side ----------------------------------------------------------

RenderSlot::RenderSlot(RenderService& service, Deliver deliver, std::uint32_t queueFrames)
    : mService(service), mDeliver(std::move(deliver)), mQueueFrames(queueFrames) {}

void RenderSlot::setVolume(std::shared_ptr<Volume> volume) {
    {
        std::lock_guard lock(mMutex);
        markChanged();
        mState.volume = std::move(volume);
        mState.camera.reset(); // a camera for the old volume means nothing for the new one
        mDirty = true;
        mResetDelta = true;
    }
    changed();
}

void RenderSlot::setCamera(const protocol::SetCamera& camera) {
    {
        std::lock_guard lock(mMutex);
        markChanged();
        mState.camera = camera; // latest wins: an undrawn camera is simply replaced
        mLastCamera = Clock::now();
        mDirty = true;
    }
    changed();
}

void RenderSlot::setTransferFunction(std::shared_ptr<const render::TransferFunction> tf,
                                     const protocol::SetTransferFunction& message) {
    {
        std::lock_guard lock(mMutex);
        markChanged();
        mState.tf = std::move(tf);
        mState.tfMessage = message;
        mDirty = true;
    }
    changed();
}

void RenderSlot::setOptions(const protocol::RenderOptions& options) {
    {
        std::lock_guard lock(mMutex);
        markChanged();
        mState.options = options;
        mDirty = true;
        mResetDelta = true;
    }
    changed();
}

void RenderSlot::request(protocol::FrameMode mode, std::uint32_t requestId) {
    {
        std::lock_guard lock(mMutex);
        markChanged();
        if (mode == protocol::FrameMode::Once) {
            mOnce = true;
            mOnceRequest = requestId;
        } else {
            mContinuous = mode == protocol::FrameMode::ContinuousOn;
            mDirty = mContinuous;
            if (!mContinuous) mNeedsRefine = false;
        }
    }
    changed();
}

void RenderSlot::frameDone() {
    {
        std::lock_guard lock(mMutex);
        if (mInFlight > 0) --mInFlight;
    }
    changed();
}

void RenderSlot::close() {
    {
        std::lock_guard lock(mMutex);
        mClosed = true;
        mDeliver = nullptr;
    }
    changed();
}

void RenderSlot::changed() {
    mService.notify();
}

void RenderSlot::markChanged() {
    if (!mDirty && !mOnce) mChangedAt = Clock::now(); // the oldest undrawn change
}

// ---- RenderSlot: the render side -----------------------------------------------------------

std::optional<Clock::time_point> RenderSlot::readyAt(std::uint32_t restMs) const {
    std::lock_guard lock(mMutex);
    if (mClosed || !mState.volume || !mState.camera || !mState.tf) return std::nullopt;
    if (mInFlight >= mQueueFrames) return std::nullopt; // frameDone() wakes us
    if (mOnce || (mContinuous && mDirty)) return Clock::time_point::min();
    if (mContinuous && mNeedsRefine) return mLastCamera + std::chrono::milliseconds(restMs);
    return std::nullopt;
}

RenderSlot::Job RenderSlot::take(Clock::time_point now, std::uint32_t restMs) {
    std::lock_guard lock(mMutex);
    Job job;
    job.state = mState;
    const auto quality = mState.options.quality;
    const bool resting = now - mLastCamera >= std::chrono::milliseconds(restMs);
    job.refined = quality == protocol::Quality::Refined ||
                  (quality == protocol::Quality::Adaptive && (resting || !mContinuous));
    job.requestId = mOnce ? mOnceRequest : 0;
    job.queuedAt = mChangedAt;
    mNeedsRefine = !job.refined && quality == protocol::Quality::Adaptive;
    mDirty = mOnce = false;
    ++mInFlight;
    if (mResetDelta) mEncoder.resetDelta();
    mResetDelta = false;
    return job;
}

// ---- RenderService -------------------------------------------------------------------------

using RendererMap = std::map<std::string, std::unique_ptr<render::Renderer>, std::less<>>;

/// What the sessions of one volume share (render thread only): the bricks resident on the GPU
/// and the renderers that hold nothing of one viewer (RendererKind::sharedPerVolume).
struct VolumeRenderers {
    std::shared_ptr<render::BrickPool> pool;
    std::uint64_t poolBudgetBytes = 0;
    RendererMap shared;
};

/// A session's own renderers, by name: each keeps what is the session's (its previous frame's
/// occlusion frustums and ray feedback); bricks come from the volume's shared pool and
/// classifications from the service's cache.
struct SessionRenderers {
    std::weak_ptr<RenderSlot> slot;
    RendererMap own;
    /// The GPU renderer's last two views and what to prefetch for the next (see runPrefetch).
    std::optional<render::Camera> lastCamera, previousCamera;
    struct Prefetch {
        render::Renderer* renderer = nullptr; ///< one of `own`, with gpuResidency()
        std::shared_ptr<Volume> volume;
        std::shared_ptr<const render::TransferFunction> tf;
        render::Camera camera;
        render::RenderOptions options;
        std::uint64_t lastFrameBricks = 0;
    };
    std::optional<Prefetch> prefetch;
};

struct RenderService::Renderers {
    std::unique_ptr<render::EglContext> context;
    std::map<const Volume*, VolumeRenderers> volumes;
    std::map<const RenderSlot*, SessionRenderers> sessions;

    /// Renderers of closed sessions and pools of volumes nobody views go (GL objects, on
    /// this thread).
    /// `retired` is told the name of each volume whose pool goes.
    void prune(const std::function<void(const std::string&)>& retired) {
        std::erase_if(sessions, [](const auto& e) { return e.second.slot.expired(); });
        std::erase_if(volumes, [&](const auto& e) {
            if (e.first->sessions.load() != 0) return false;
            if (e.second.pool) retired(e.first->name);
            return true;
        });
    }
    SessionRenderers& of(const std::shared_ptr<RenderSlot>& slot) {
        auto& s = sessions[slot.get()];
        if (s.slot.lock() != slot) s = SessionRenderers{slot, {}, {}, {}, {}}; // a reused address
        return s;
    }
};

/// Bricks a frame held resident: those it drew, less constant ones (no texture) and those
/// ray-guided residency left unloaded.
std::uint64_t residentBricks(const render::FrameStats& s) {
    return s.bricksVisited - s.bricksConstant - s.bricksDeferred + s.bricksRequested;
}

/// Bytes of one stored brick (apron included), as the pool and the host cache hold it.
std::uint64_t slotBytesOf(const brickstore::BrickStore& store) {
    const std::uint64_t e = store.layout().storedEdge();
    return e * e * e * brickstore::voxelBytes(store.info().volume.type);
}

/// The volume's pool at its fair share of the budget; a new pool only when the share moved by
/// more than an eighth, so sessions coming and going do not make every brick upload again.
std::shared_ptr<render::BrickPool>& sharedPool(VolumeRenderers& v, const Volume& volume,
                                               std::uint64_t shareBytes) {
    const bool far = shareBytes < v.poolBudgetBytes - v.poolBudgetBytes / 8 ||
                     shareBytes > v.poolBudgetBytes + v.poolBudgetBytes / 8;
    if (!v.pool || far) {
        v.pool.reset(); // the old texture goes before the new one is allocated
        v.pool = std::make_shared<render::BrickPool>(volume.store->info().volume.type,
                                                     volume.store->layout().storedEdge(),
                                                     render::BrickPoolConfig{shareBytes});
        v.poolBudgetBytes = shareBytes;
    }
    return v.pool;
}

struct RenderService::Counters {
    std::map<std::string, double> frames; ///< per renderer
    double refined = 0, errors = 0, renderMs = 0, encodeMs = 0, bytes = 0, samples = 0;
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
};

namespace {

render::BrickPoolStats& operator+=(render::BrickPoolStats& a, const render::BrickPoolStats& b) {
    a.hits += b.hits;
    a.uploads += b.uploads;
    a.bytesUploaded += b.bytesUploaded;
    a.evictions += b.evictions;
    a.refetches += b.refetches;
    a.bytesRefetched += b.bytesRefetched;
    a.uploadMs += b.uploadMs;
    return a;
}

/// The protocol's renderer numbers, by their names in the registry.
const char* rendererName(protocol::Renderer r) {
    switch (r) {
    case protocol::Renderer::GpuRaycaster:
        return "gpu";
    case protocol::Renderer::CpuRaycaster:
        return "cpu";
    case protocol::Renderer::Reference:
        return "reference";
    case protocol::Renderer::Splatter:
        return "splat";
    case protocol::Renderer::GpuSplatter:
        return "splat-gpu";
    }
    return "unknown";
}

} // namespace

RenderService::RenderService(const RenderServiceConfig& config, Catalog& catalog, Log& log)
    : mConfig(config), mCatalog(catalog), mLog(log),
      mClassifications(std::make_unique<render::ClassificationCache>(
          render::ClassificationCacheConfig{config.classificationBudgetBytes})),
      mCounters(std::make_unique<Counters>()), mThread([this] { run(); }) {}

RenderService::~RenderService() {
    {
        std::lock_guard lock(mMutex);
        mStop = true;
    }
    mWake.notify_all();
    mThread.join();
}

std::shared_ptr<RenderSlot> RenderService::open(RenderSlot::Deliver deliver,
                                                std::uint32_t queueFrames) {
    auto slot = std::make_shared<RenderSlot>(*this, std::move(deliver), queueFrames);
    std::lock_guard lock(mMutex);
    mSlots.push_back(slot);
    return slot;
}

bool RenderService::gpuAvailable() {
    std::unique_lock lock(mMutex);
    mStartedCv.wait(lock, [&] { return mStarted; });
    return mGpu;
}

void RenderService::collect(MetricSet& m) {
    std::lock_guard lock(mMutex); // then each slot's: the order nextReady() takes them in
    std::size_t waiting = 0;
    const auto now = Clock::now();
    for (const auto& w : mSlots)
        if (auto slot = w.lock()) {
            const auto at = slot->readyAt(mConfig.restMs);
            waiting += at && *at <= now;
        }
    const Counters& c = *mCounters;
    for (const char* r : {"gpu", "cpu", "splat", "splat-gpu", "reference"}) {
        const auto it = c.frames.find(r);
        m.counter("frames_total", "Frames drawn and encoded, by renderer",
                  it == c.frames.end() ? 0.0 : it->second, {{"renderer", r}});
    }
    m.counter("frames_refined_total", "Full-quality frames after the camera came to rest",
              c.refined);
    m.counter("render_errors_total", "Frames that failed (sent as RenderFailed)", c.errors);
    m.counter("render_ms_total", "Milliseconds spent drawing frames", c.renderMs);
    m.counter("encode_ms_total", "Milliseconds spent encoding frames", c.encodeMs);
    m.counter("frame_bytes_total", "Encoded frame message bytes", c.bytes);
    m.counter("samples_total", "Volume samples (voxels for the splatter) taken", c.samples);
    m.histogram(
        "frame_latency_ms",
        "From the oldest change a frame answers to the frame encoded (queue + render + encode)",
        c.latencyMs);
    m.histogram("frame_render_ms", "Drawing one frame (bricks, octrees, rays or splats)",
                c.renderMsHist);
    m.histogram("frame_upload_ms",
                "Host -> GPU uploads (CPU renderers: brick preparation) of one frame", c.uploadMs);
    m.histogram("frame_encode_ms", "Encoding one frame", c.encodeMsHist);
    m.histogram(
        "frame_working_set_bytes",
        "Bytes of the bricks one frame held on the GPU (drawn, less constant and deferred ones)",
        c.workingSet);
    m.histogram("frame_encoded_bytes", "Encoded bytes of one frame message", c.frameBytes);
    m.counter("prefetch_ms_total", "Milliseconds the render thread spent prefetching",
              c.prefetchMs);
    const render::ClassificationStats cs = mClassifications->stats();
    m.counter("classification_builds_total",
              "Transfer functions committed for a store and level: octrees built or brought up "
              "to date, once per key however many sessions ask",
              double(cs.builds));
    m.counter("classification_hits_total", "Frames that found their classification built",
              double(cs.hits));
    m.counter("classification_evictions_total",
              "Classifications dropped by the budget (LRU, none in use)", double(cs.evictions));
    m.counter("classification_bricks_rebuilt_total", "Per-brick octrees rebuilt over all builds",
              double(cs.bricksRebuilt));
    m.counter("classification_build_ms_total", "Milliseconds spent building classifications",
              cs.buildMs);
    m.gauge("classification_bytes", "Host bytes of classifications held (octrees and tables)",
            double(cs.residentBytes));
    m.gauge("classifications", "Classifications held", double(cs.entries));
    m.gauge("render_slots_waiting", "Sessions with a frame due and not yet drawn", double(waiting));
    std::map<std::string, render::BrickPoolStats> pools = c.poolRetired;
    for (const auto& [name, live] : c.poolLive)
        pools[name] += live;
    for (const auto& [name, p] : pools) {
        const std::vector<std::pair<std::string, std::string>> l{{"volume", name}};
        m.counter("gpu_pool_hits_total", "Bricks a frame found resident on the GPU", double(p.hits),
                  l);
        m.counter("gpu_pool_uploads_total", "Bricks uploaded host -> GPU", double(p.uploads), l);
        m.counter("gpu_pool_bytes_uploaded_total", "Bytes uploaded host -> GPU",
                  double(p.bytesUploaded), l);
        m.counter("gpu_pool_evictions_total", "Bricks evicted from the GPU pool (LRU)",
                  double(p.evictions), l);
        m.counter("gpu_pool_refetches_total", "Uploads of bricks the pool held before and evicted",
                  double(p.refetches), l);
        m.counter("gpu_pool_bytes_refetched_total", "Bytes uploaded again after their eviction",
                  double(p.bytesRefetched), l);
        m.counter("gpu_pool_upload_ms_total", "Milliseconds spent uploading bricks", p.uploadMs, l);
        auto of = [](const std::map<std::string, double>& m, const std::string& k) {
            const auto it = m.find(k);
            return it == m.end() ? 0.0 : it->second;
        };
        m.counter("gpu_frame_uploads_total", "Bricks uploaded while a frame waited for them",
                  of(c.frameUploads, name), l);
        m.counter("gpu_prefetch_uploads_total",
                  "Bricks uploaded ahead of need, for a predicted next view, while idle",
                  of(c.prefetchUploads, name), l);
        m.counter("gpu_prefetch_bytes_total", "Bytes uploaded by prefetch",
                  of(c.prefetchBytes, name), l);
        m.counter("gpu_deferred_bricks_total",
                  "Planned bricks a frame left unloaded: its last frame found them behind "
                  "saturated rays (ray-guided residency)",
                  of(c.deferred, name), l);
        m.counter("gpu_requested_bricks_total",
                  "Deferred bricks loaded after all, when rays reached them", of(c.requested, name),
                  l);
        const auto b = c.poolBudget.find(name);
        m.gauge("gpu_pool_budget_bytes", "The volume's share of the GPU budget",
                b == c.poolBudget.end() ? 0.0 : b->second, l);
    }
}

/// Bricks one prefetch step uploads at most (see runPrefetch).
constexpr std::uint32_t kPrefetchStepBricks = 32;

void RenderService::runPrefetch() {
    const auto start = Clock::now();
    for (auto& [key, mine] : mRenderers->sessions) {
        if (!mine.prefetch) continue;
        auto job = std::move(*mine.prefetch);
        mine.prefetch.reset();
        render::GpuResidency* gpu = job.renderer ? job.renderer->gpuResidency() : nullptr;
        if (!gpu || mine.slot.expired() || !gpu->pool()) continue;
        const render::BrickPool& pool = *gpu->pool();
        const std::uint64_t keep = std::min<std::uint64_t>(job.lastFrameBricks, pool.capacity());
        const auto room = std::uint32_t(pool.capacity() - keep);
        if (room == 0) continue;
        // A bounded step, so that a session whose frame falls due waits for at most this many
        // uploads; the rest of the job waits for the next idle turn.
        const std::uint32_t step = std::min(room, kPrefetchStepBricks);
        try {
            const std::uint64_t bytesBefore = pool.stats().bytesUploaded;
            const render::Scene scene{*job.volume->store, *job.volume->cache, *job.tf,
                                      *mClassifications};
            // A predicted camera came from no decoder: validated here (a bad guess throws).
            const std::uint32_t n = gpu->prefetch(
                scene, render::View::of(job.camera, job.options.width, job.options.height),
                job.options, step);
            if (n == step && step < room) { // more may be missing: continue next turn
                job.lastFrameBricks += n;   // what this step brought in stays too
                mine.prefetch = job;
            }
            std::lock_guard lock(mMutex);
            mCounters->prefetchUploads[job.volume->name] += n;
            mCounters->prefetchBytes[job.volume->name] +=
                double(pool.stats().bytesUploaded - bytesBefore);
            mCounters->poolLive[job.volume->name] = pool.stats();
        } catch (const std::exception& e) { // a guess that failed costs nothing but the log line
            mLog.error("prefetch: " + job.volume->name + ": " + e.what());
        }
    }
    std::lock_guard lock(mMutex);
    mCounters->prefetchMs += msSince(start);
}

void RenderService::record(const FrameRecord& f, double bytes, const std::string& volume,
                           const render::BrickPool* pool) {
    std::lock_guard lock(mMutex);
    Counters& c = *mCounters;
    c.frames[f.renderer] += 1;
    c.renderMs += f.renderMs;
    c.encodeMs += f.encodeMs;
    c.bytes += bytes;
    c.latencyMs.observe(f.latencyMs);
    c.renderMsHist.observe(f.renderMs);
    c.uploadMs.observe(f.uploadMs);
    c.encodeMsHist.observe(f.encodeMs);
    c.workingSet.observe(f.workingSetBytes);
    c.frameBytes.observe(bytes);
    if (pool) {
        c.frameUploads[volume] += f.bricksUploaded;
        c.deferred[volume] += f.bricksDeferred;
        c.requested[volume] += f.bricksRequested;
        c.poolLive[volume] = pool->stats();
        c.poolBudget[volume] = double(pool->capacity()) * double(pool->slotBytes());
    }
}

void RenderService::retirePool(const std::string& volume) {
    std::lock_guard lock(mMutex);
    Counters& c = *mCounters;
    if (auto it = c.poolLive.find(volume); it != c.poolLive.end()) {
        c.poolRetired[volume] += it->second;
        c.poolLive.erase(it);
    }
}

void RenderService::notify() {
    { std::lock_guard lock(mMutex); } // orders this wake-up after the thread's last check
    mWake.notify_all();
}

void RenderService::run() {
    mRenderers = std::make_unique<Renderers>();
    try {
        mRenderers->context = std::make_unique<render::EglContext>();
        mLog.info("render: " + mRenderers->context->renderer() + " (" +
                  mRenderers->context->platform() + ")");
    } catch (const std::exception& e) {
        mLog.error(std::string("render: no GPU renderer: ") + e.what());
    }
    {
        std::lock_guard lock(mMutex);
        mStarted = true;
        mGpu = mRenderers->context != nullptr;
    }
    mStartedCv.notify_all();
    std::unique_lock lock(mMutex);
    while (!mStop) {
        bool prefetchDue = false;
        for (const auto& [key, s] : mRenderers->sessions)
            prefetchDue |= s.prefetch.has_value();
        auto slot = nextReady(lock, !prefetchDue);
        if (!slot) {
            if (prefetchDue) {
                lock.unlock();
                runPrefetch();
                lock.lock();
            }
            continue;
        }
        auto job = slot->take(Clock::now(), mConfig.restMs);
        lock.unlock();
        mRenderers->prune([this](const std::string& volume) { retirePool(volume); });
        draw(slot, std::move(job));
        lock.lock();
    }
    lock.unlock();
    mRenderers.reset(); // GL objects go before the context, on this thread
}

std::shared_ptr<RenderSlot> RenderService::nextReady(std::unique_lock<std::mutex>& lock,
                                                     bool mayWait) {
    std::erase_if(mSlots, [](const auto& w) { return w.expired(); });
    const auto now = Clock::now();
    std::optional<Clock::time_point> wakeAt;
    for (std::size_t i = 0; i < mSlots.size(); ++i) { // round robin: fair between sessions
        const std::size_t k = (mNextSlot + i) % mSlots.size();
        auto slot = mSlots[k].lock();
        if (!slot) continue;
        const auto at = slot->readyAt(mConfig.restMs);
        if (at && *at <= now) {
            mNextSlot = k + 1;
            return slot;
        }
        if (at && (!wakeAt || *at < *wakeAt)) wakeAt = at;
    }
    if (!mayWait) return nullptr;
    if (wakeAt)
        mWake.wait_until(lock, *wakeAt);
    else
        mWake.wait(lock);
    return nullptr;
}

void RenderService::draw(const std::shared_ptr<RenderSlot>& slotPtr, RenderSlot::Job job) {
    RenderSlot& slot = *slotPtr;
    std::vector<std::uint8_t> bytes;
    try {
        FrameRecord rec;
        const render::BrickPool* pool = nullptr;
        const protocol::Frame frame = render(slotPtr, job, *mRenderers, rec, pool);
        protocol::encode(frame, job.requestId, bytes);
        record(rec, double(bytes.size()), job.state.volume->name, pool);
        std::lock_guard lock(mMutex);
        mCounters->refined += frame.header.refined;
        mCounters->samples += double(frame.header.samples);
    } catch (const std::exception& e) {
        protocol::Error error{protocol::ErrorCode::RenderFailed, false,
                              std::uint8_t(protocol::MessageType::RequestFrame),
                              protocol::fitText(e.what(), protocol::kMaxErrorMessageBytes)};
        bytes.clear();
        protocol::encode(error, job.requestId, bytes);
        mLog.error("render: " + job.state.volume->name + ": " + e.what());
        std::lock_guard lock(mMutex);
        mCounters->errors += 1;
    }
    std::unique_lock lock(slot.mMutex);
    auto deliver = slot.mDeliver;
    lock.unlock();
    if (deliver)
        deliver(std::move(bytes));
    else
        slot.frameDone();
}

protocol::Frame RenderService::render(const std::shared_ptr<RenderSlot>& slotPtr,
                                      RenderSlot::Job& job, Renderers& r, FrameRecord& rec,
                                      const render::BrickPool*& pool) {
    RenderSlot& slot = *slotPtr;
    const auto& s = job.state;
    const auto start = Clock::now();
    const auto& o = s.options;
    render::RenderOptions options = toRenderOptions(o, !job.refined);
    options.shading = shadingFor(o, s.tfMessage, *s.tf);
    // The decoder validated the camera (the same rules as Camera::validate).
    const render::View view =
        render::View::ofDecoded(toCamera(*s.camera), options.width, options.height);
    const render::Scene scene{*s.volume->store, *s.volume->cache, *s.tf, *mClassifications};
    const std::string_view name = rendererName(o.renderer);
    const render::RendererKind* kind = render::RendererRegistry::builtin().find(name);
    if (!kind) throw std::runtime_error("no renderer " + std::string(name));
    if (kind->needsGl && !r.context)
        throw std::runtime_error("this server has no OpenGL 4.5 context");
    auto& v = r.volumes[s.volume.get()];
    auto& mine = r.of(slotPtr);
    RendererMap& owner = kind->sharedPerVolume ? v.shared : mine.own;
    auto it = owner.find(name);
    if (it == owner.end()) it = owner.emplace(std::string(name), kind->create()).first;
    render::Renderer& renderer = *it->second;
    render::GpuResidency* gpu = renderer.gpuResidency();
    if (gpu) { // the volume's bricks on the GPU are shared by its sessions
        const render::BrickPool* before = v.pool.get();
        auto& shared =
            sharedPool(v, *s.volume, mCatalog.shareOf(*s.volume, mConfig.gpuBudgetBytes));
        if (before && shared.get() != before) retirePool(s.volume->name);
        gpu->setSharedPool(shared);
        pool = shared.get();
    }
    render::FrameStats stats;
    render::Image image = renderer.render(scene, view, options, stats);
    if (gpu) {
        mine.previousCamera = mine.lastCamera;
        mine.lastCamera = view.camera;
        mine.prefetch.reset();
        if (mConfig.prefetch && mine.previousCamera)
            mine.prefetch = SessionRenderers::Prefetch{
                &renderer, s.volume,
                s.tf,      render::predictNext(*mine.previousCamera, view.camera),
                options,   residentBricks(stats)};
    }
    if (!job.refined) image = interactiveUpscale(image, o.width, o.height);
    const auto rgba8 = render::toRgba8(image);
    protocol::Frame frame;
    frame.header.renderMs = float(msSince(start));
    auto encoded = slot.mEncoder.encode(rgba8, o.width, o.height, o.codec, o.codecQuality);
    auto& h = frame.header;
    h.frameId = slot.mNextFrameId++;
    h.cameraId = s.camera->cameraId;
    h.width = o.width;
    h.height = o.height;
    h.codec = o.codec;
    h.level = std::uint8_t(stats.level);
    h.refined = job.refined;
    h.keyframe = encoded.keyframe;
    h.queueMs = float(std::chrono::duration<double, std::milli>(start - job.queuedAt).count());
    h.encodeMs = float(encoded.encodeMs);
    h.samples = stats.samples;
    h.bricksDrawn = std::uint32_t(stats.bricksVisited);
    h.bricksSkipped = std::uint32_t(stats.bricksSkipped);
    h.bytesUploaded = stats.bytesUploaded;
    h.occlusionUsed = stats.occlusionUsed;
    frame.image = std::move(encoded.bytes);
    rec.renderer = rendererName(o.renderer);
    rec.renderMs = h.renderMs;
    rec.encodeMs = h.encodeMs;
    rec.uploadMs = stats.uploadMs;
    rec.latencyMs = msSince(job.queuedAt);
    rec.bricks = double(residentBricks(stats));
    rec.bricksDeferred = double(stats.bricksDeferred);
    rec.bricksRequested = double(stats.bricksRequested);
    rec.workingSetBytes = rec.bricks * double(slotBytesOf(*s.volume->store));
    rec.bricksUploaded = double(stats.bricksUploaded);
    return frame;
}

} // namespace bc::server
