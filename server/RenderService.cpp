#include "server/RenderService.h"

#include "render/CpuRaycaster.h"
#include "render/BrickPool.h"
#include "render/EglContext.h"
#include "render/HybridSplatter.h"
#include "render/Raycaster.h"
#include "render/ReferenceRenderer.h"
#include "server/Catalog.h"
#include "server/Log.h"
#include "server/ViewRequest.h"

#include <map>

namespace bc::server {

namespace {

double msSince(Clock::time_point t) {
    return std::chrono::duration<double, std::milli>(Clock::now() - t).count();
}

/// Largest volume the reference renderer is offered for (it holds every voxel as a double).
constexpr std::uint64_t kMaxReferenceVoxels = 64ull << 20;

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

void RenderSlot::changed() { mService.notify(); }

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

/// What the sessions of one volume share on the GPU (render thread only).
struct VolumeRenderers {
    std::shared_ptr<render::BrickPool> pool;
    std::uint64_t poolBudgetBytes = 0;
    std::unique_ptr<render::ReferenceVolume> reference;
};

/// A session's own renderers: its octrees (its transfer function) and its occlusion frustums
/// (its previous frame) stay its own; bricks come from the volume's shared pool.
struct SessionRenderers {
    std::weak_ptr<RenderSlot> slot;
    std::unique_ptr<render::Raycaster> gpu;
    std::unique_ptr<render::CpuRaycaster> cpu;
    std::unique_ptr<render::HybridSplatter> splat;
};

struct RenderService::Renderers {
    std::unique_ptr<render::EglContext> context;
    std::map<const Volume*, VolumeRenderers> volumes;
    std::map<const RenderSlot*, SessionRenderers> sessions;

    /// Renderers of closed sessions and pools of volumes nobody views go (GL objects, on
    /// this thread).
    void prune() {
        std::erase_if(sessions, [](const auto& e) { return e.second.slot.expired(); });
        std::erase_if(volumes, [&](const auto& e) { return e.first->sessions.load() == 0; });
    }
    SessionRenderers& of(const std::shared_ptr<RenderSlot>& slot) {
        auto& s = sessions[slot.get()];
        if (s.slot.lock() != slot) s = SessionRenderers{slot, nullptr, nullptr, nullptr}; // a reused address
        return s;
    }
};

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

RenderService::RenderService(const RenderServiceConfig& config, Catalog& catalog, Log& log)
    : mConfig(config), mCatalog(catalog), mLog(log), mThread([this] { run(); }) {}

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

std::vector<std::pair<std::string, double>> RenderService::counters() {
    std::lock_guard lock(mMutex);
    const Counters& c = mCounters;
    return {{"frames", c.frames},           {"frames_refined", c.refined},
            {"render_errors", c.errors},    {"render_ms_total", c.renderMs},
            {"encode_ms_total", c.encodeMs}, {"frame_bytes_total", c.bytes},
            {"samples_total", c.samples},   {"gpu_uploads_total", c.uploads},
            {"gpu_bytes_uploaded_total", c.bytesUploaded},
            {"sessions", double(mCatalog.sessions())}};
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
        auto slot = nextReady(lock);
        if (!slot) continue;
        auto job = slot->take(Clock::now(), mConfig.restMs);
        lock.unlock();
        mRenderers->prune();
        draw(slot, std::move(job));
        lock.lock();
    }
    lock.unlock();
    mRenderers.reset(); // GL objects go before the context, on this thread
}

std::shared_ptr<RenderSlot> RenderService::nextReady(std::unique_lock<std::mutex>& lock) {
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
        const protocol::Frame frame = render(slotPtr, job, *mRenderers);
        protocol::encode(frame, job.requestId, bytes);
        std::lock_guard lock(mMutex);
        mCounters.frames += 1;
        mCounters.refined += frame.header.refined;
        mCounters.renderMs += frame.header.renderMs;
        mCounters.encodeMs += frame.header.encodeMs;
        mCounters.bytes += double(bytes.size());
        mCounters.samples += double(frame.header.samples);
        mCounters.bytesUploaded += double(frame.header.bytesUploaded);
    } catch (const std::exception& e) {
        protocol::Error error{protocol::ErrorCode::RenderFailed, false,
                              std::uint8_t(protocol::MessageType::RequestFrame),
                              protocol::fitText(e.what(), protocol::kMaxErrorMessageBytes)};
        bytes.clear();
        protocol::encode(error, job.requestId, bytes);
        mLog.error("render: " + job.state.volume->name + ": " + e.what());
        std::lock_guard lock(mMutex);
        mCounters.errors += 1;
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
                                      RenderSlot::Job& job, Renderers& r) {
    RenderSlot& slot = *slotPtr;
    const auto& s = job.state;
    const auto start = Clock::now();
    const auto& o = s.options;
    render::RenderOptions options = toRenderOptions(o, !job.refined);
    options.shading = shadingFor(o, s.tfMessage, *s.tf);
    const render::Camera camera = toCamera(*s.camera);
    auto& v = r.volumes[s.volume.get()];
    render::FrameStats stats;
    render::Image image;
    switch (o.renderer) {
    case protocol::Renderer::GpuRaycaster: {
        if (!r.context) throw std::runtime_error("this server has no OpenGL 4.5 context");
        auto& mine = r.of(slotPtr);
        if (!mine.gpu) mine.gpu = std::make_unique<render::Raycaster>();
        mine.gpu->setSharedPool(
            sharedPool(v, *s.volume, mCatalog.shareOf(*s.volume, mConfig.gpuBudgetBytes)));
        image = mine.gpu->render(*s.volume->store, *s.volume->cache, *s.tf, camera, options, stats);
        break;
    }
    case protocol::Renderer::CpuRaycaster: {
        auto& mine = r.of(slotPtr);
        if (!mine.cpu) mine.cpu = std::make_unique<render::CpuRaycaster>();
        image = mine.cpu->render(*s.volume->store, *s.volume->cache, *s.tf, camera, options, stats);
        break;
    }
    case protocol::Renderer::Splatter: {
        auto& mine = r.of(slotPtr);
        if (!mine.splat) mine.splat = std::make_unique<render::HybridSplatter>();
        image = mine.splat->render(*s.volume->store, *s.volume->cache, *s.tf, camera, options, stats);
        break;
    }
    case protocol::Renderer::Reference: {
        const auto& dims = s.volume->store->info().volume.dims;
        if (dims[0] * dims[1] * dims[2] > kMaxReferenceVoxels)
            throw std::runtime_error("the reference renderer is not offered for volumes over " +
                                     std::to_string(kMaxReferenceVoxels >> 20) + " Mi voxels");
        if (!v.reference)
            v.reference = std::make_unique<render::ReferenceVolume>(*s.volume->store, 0);
        image = render::renderReference(*s.volume->store, *v.reference, *s.tf, camera, options, stats);
        break;
    }
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
    return frame;
}

} // namespace bc::server
