#include "server/RenderService.h"

#include "brickstore/Error.h"
#include "render/BrickPool.h"
#include "render/Classification.h"
#include "render/Composite.h"
#include "render/EglContext.h"
#include "render/RefinementEstimate.h"
#include "render/RendererChoice.h"
#include "render/RendererRegistry.h"
#include "render/View.h"
#include "server/Catalog.h"
#include "server/FrameCache.h"
#include "server/FrameCluster.h"
#include "server/InteractiveBudget.h"
#include "server/Log.h"
#include "server/Metrics.h"
#include "server/Prefetch.h"
#include "server/RenderMetrics.h"
#include "server/RendererCache.h"
#include "server/ViewRequest.h"

#include <algorithm>
#include <cmath>

namespace bc::server {

// The highest bound a client may ask for at rest is the highest estimate a pass can carry: the
// protocol cannot see the estimator (the module rules), so the two are checked here.
static_assert(double(protocol::kMaxRestPsnrDb) == render::kMaxEstimateDb);

namespace {

double msSince(Clock::time_point t) {
    return std::chrono::duration<double, std::milli>(Clock::now() - t).count();
}

/// A frame of a volume out of service: answered RenderFailed at once, not logged again.
struct VolumeOutOfService : std::runtime_error {
    using std::runtime_error::runtime_error;
};

/// The shortest slice of a refined frame beside moving sessions (sliceMsBeside): shorter, the
/// fixed cost of a slice (planning the frame's bricks: about 2 ms for the 2.36 GiB mosaic on
/// the dev VM) would be a large part of it.
constexpr double kMinSliceBesideMs = 10.0;

} // namespace

RenderService::RenderService(const RenderServiceConfig& config, Catalog& catalog, Log& log,
                             VolumeFailed volumeFailed)
    : mConfig(config), mCatalog(catalog), mLog(log), mVolumeFailed(std::move(volumeFailed)),
      mBudget(std::make_unique<InteractiveBudget>(
          double(std::max<std::uint32_t>(config.interactiveMs, 1)))),
      mClassifications(std::make_unique<render::ClassificationCache>(
          render::ClassificationCacheConfig{config.classificationBudgetBytes})),
      mFrames(std::make_unique<FrameCache>(FrameCacheConfig{config.frameCacheBytes})),
      mCounters(std::make_unique<RenderCounters>()), mThread([this] { run(); }) {}

RenderService::~RenderService() {
    {
        std::lock_guard lock(mMutex);
        mStop = true;
    }
    mWake.notify_all();
    mThread.join();
}

std::shared_ptr<RenderSlot> RenderService::open(RenderSlot::Deliver deliver,
                                                std::uint32_t queueFrames,
                                                std::uint64_t queueBytes) {
    auto slot = std::make_shared<RenderSlot>(*this, std::move(deliver), queueFrames, queueBytes);
    std::lock_guard lock(mMutex);
    mSlots.push_back(slot);
    return slot;
}

std::optional<std::string> RenderService::gpuUnavailable() {
    std::lock_guard lock(mMutex);
    return mGpuUnavailable;
}

void RenderService::makeContext(const char* forWhat) {
    if (mRenderers->context) return;
    if (auto why = gpuUnavailable()) throw std::runtime_error(*why);
    try {
        mRenderers->context = std::make_unique<render::EglContext>();
    } catch (const std::exception& e) {
        const std::string why = std::string("this server has no OpenGL 4.5 context: ") + e.what();
        mLog.error("render: no GPU renderer (GPU frames are refused, the CPU renderers serve): " +
                   std::string(e.what()));
        std::lock_guard lock(mMutex);
        mGpuUnavailable = why;
        throw std::runtime_error(why);
    }
    mLog.info("render: " + mRenderers->context->renderer() + " (" +
              mRenderers->context->platform() + "), made for " + forWhat);
    withCounters([](RenderCounters& c) { c.gpuContext = 1; });
}

const render::RendererChoice& RenderService::autoChoice() {
    auto& choice = mRenderers->autoChoice;
    if (choice) return *choice;
    try {
        makeContext("the first frame asking for auto, to choose its renderer");
        choice = render::chooseAuto(mRenderers->context->renderer(), mRenderers->context->vendor());
    } catch (const std::exception& e) { // makeContext has logged why
        choice = render::chooseAutoWithoutGl(e.what());
    }
    mLog.info("render: " + choice->reason + ", for every session that asks for auto");
    std::lock_guard lock(mMutex);
    mAutoChoice = *choice;
    return *choice;
}

void RenderService::collect(MetricSet& m) {
    std::lock_guard lock(mMutex); // then each slot's: the order nextReady() takes them in
    std::size_t waiting = 0;
    bool owed = false;
    const auto now = Clock::now();
    for (const auto& w : mSlots)
        if (auto slot = w.lock()) {
            const auto at = slot->readyAt(mConfig.restMs);
            waiting += at && *at <= now;
            owed |= slot->owesFrame();
        }
    RenderMetricsContext context;
    context.slotsWaiting = waiting;
    context.framesInProgress = mFramesInProgress;
    context.idle = mWaiting && !owed && mFramesInProgress == 0;
    context.cluster = mConfig.cluster;
    context.frameCache = mFrames->stats();
    context.classifications = mClassifications->stats();
    context.gpuUnavailable = mGpuUnavailable.has_value();
    context.autoChoice = mAutoChoice;
    mCounters->exportTo(m, context);
}

void RenderService::runPrefetch() {
    const auto start = Clock::now();
    PrefetchReports reports;
    reports.uploaded = [this](const std::string& volume, std::uint32_t bricks, std::uint64_t bytes,
                              const render::BrickPoolStats& pool) {
        std::lock_guard lock(mMutex);
        mCounters->prefetchUploads[volume] += bricks;
        mCounters->prefetchBytes[volume] += double(bytes);
        mCounters->poolLive[volume] = pool;
    };
    reports.failed = [this](const std::shared_ptr<Volume>& volume, const std::exception& e) {
        mLog.error("prefetch: " + volume->name + ": " + e.what());
        checkStore(volume, e);
    };
    bc::server::runPrefetch(*mRenderers, *mClassifications, reports);
    std::lock_guard lock(mMutex);
    mCounters->prefetchMs += msSince(start);
}

void RenderService::withCounters(const std::function<void(RenderCounters& counters)>& f) {
    std::lock_guard lock(mMutex);
    f(*mCounters);
}

void RenderService::checkStore(const std::shared_ptr<Volume>& volume, const std::exception& e) {
    const bool storeError = dynamic_cast<const brickstore::StoreCorrupt*>(&e) != nullptr ||
                            dynamic_cast<const brickstore::StoreIoError*>(&e) != nullptr;
    // A bad brick in an unchanged file is that brick's error only: the rest keeps serving.
    if (!storeError || volume->failure() || !volume->store->fileChange()) return;
    if (mCatalog.markFailed(*volume, e.what(), mLog) && mVolumeFailed) mVolumeFailed(volume);
}

void RenderService::notify() {
    { std::lock_guard lock(mMutex); } // orders this wake-up after the thread's last check
    mWake.notify_all();
}

void RenderService::run() {
    mRenderers = std::make_unique<RendererCache>(
        mCatalog, mConfig.gpuBudgetBytes, [this](const std::string& volume) {
            withCounters([&](RenderCounters& c) { c.retirePool(volume); });
        });
    std::unique_lock lock(mMutex);
    while (!mStop) {
        // Sessions gone go first (their frames in progress with them), before any wait.
        lock.unlock();
        const std::uint32_t dropped = mRenderers->prune();
        lock.lock();
        mCounters->cancelled += dropped;
        mFramesInProgress = mRenderers->framesInProgress();
        if (mConfig.cluster) { // the workers hear from rank 0 at least every kHeartbeat
            lock.unlock();
            mConfig.cluster->idle();
            lock.lock();
        }
        bool prefetchDue = false;
        for (const auto& [key, s] : mRenderers->sessions)
            prefetchDue |= s.prefetch.job.has_value();
        auto slot = nextReady(lock, !prefetchDue);
        if (!slot) {
            if (prefetchDue) {
                lock.unlock();
                runPrefetch();
                lock.lock();
            }
            continue;
        }
        std::optional<RenderSlot::Job> job;
        if (!drawing(slot.get())) job = slot->take(Clock::now(), mConfig.restMs);
        lock.unlock();
        turn(slot, std::move(job));
        lock.lock();
        mFramesInProgress = mRenderers->framesInProgress();
    }
    lock.unlock();
    mRenderers.reset(); // GL objects go before the context, on this thread
}

bool RenderService::drawing(const RenderSlot* slot) const {
    return mRenderers->drawing(slot);
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
        // A frame in progress is always due: its next slice is this session's turn.
        const auto at = drawing(slot.get()) ? std::optional(now) : slot->readyAt(mConfig.restMs);
        if (at && *at <= now) {
            mNextSlot = k + 1;
            return slot;
        }
        if (at && (!wakeAt || *at < *wakeAt)) wakeAt = at;
    }
    if (!mayWait || mStop) return nullptr; // a stop set while the lock was let go is seen here
    if (mConfig.cluster) { // wake at least every second: the cluster's heartbeat (run())
        const auto beat = now + std::chrono::seconds(1);
        if (!wakeAt || beat < *wakeAt) wakeAt = beat;
    }
    mWaiting = true;
    if (wakeAt)
        mWake.wait_until(lock, *wakeAt);
    else
        mWake.wait(lock);
    mWaiting = false;
    return nullptr;
}

void RenderService::prepare(FrameDrawing& d) {
    const auto& s = d.job.state;
    const auto& o = s.options;
    d.start = Clock::now();
    if (const auto why = s.volume->failure())
        throw VolumeOutOfService("volume '" + s.volume->name + "' is out of service: " + *why);
    std::string_view name = protocol::rendererName(o.renderer);
    d.rendererChoice = "asked for " + std::string(name);

    if (o.renderer == protocol::Renderer::Auto) {
        const render::RendererChoice& choice = autoChoice();
        name = choice.name;
        d.rendererChoice = choice.reason;
    }
    d.kind = render::RendererRegistry::builtin().find(name);
    if (!d.kind) throw std::runtime_error("no renderer " + std::string(name));
    if (d.kind->needsGl) makeContext();
    // An interactive frame: drawn smaller, and at the level, its budget allows (half size at
    // the level asked for without one).
    // The session's target (SetFrameBudget), else the server's (frames.interactive_ms).
    std::optional<InteractiveChoice> budgeted;
    // The budget learns a rate per mode (a maximum's ray costs what a composite one does not).
    d.drawing = std::string(d.kind->name);
    if (s.modeAndClip.mode != protocol::BlendMode::Composite)
        d.drawing += std::string(" ") + render::toString(render::BlendMode(s.modeAndClip.mode));
    const double targetMs =
        s.budget.interactiveMs > 0 ? double(s.budget.interactiveMs) : double(mConfig.interactiveMs);
    if (!d.job.refined && targetMs > 0)
        budgeted = mBudget->choose(s.volume->name, d.drawing, o.width, o.height,
                                   interactiveLevels(*s.volume, o), d.sharers, targetMs);
    d.budgeted = budgeted.has_value();
    if (!d.job.refined) d.divisor = budgeted ? budgeted->divisor : InteractiveBudget::kFirstDivisor;
    d.options = toRenderOptions(o, d.divisor);
    applyModeAndClip(d.options, s.modeAndClip);
    if (budgeted) d.options.level = std::int32_t(budgeted->level);
    // The first pass at rest under an error bound, where the renderer draws a stride and the
    // frame is large enough: at half the session's step, checked against a sparse frame at the
    // step, so that its estimate comes with it (render/RefinementEstimate.h). Only where the
    // level's bricks fit the volume's host share: otherwise the sparse frame's rays would load
    // most of the view's bricks, and the pass load them again. Not across ranks: the sparse
    // frame is drawn here, and rank 0 holds only its part's bricks. Nor where half the step is
    // finer than any pass may be (refineFurther: no pass would follow the first).
    if (d.refinement() && s.budget.restPsnrDb > 0 && d.job.pass == 0 && d.kind->strided &&
        render::refineFurther(-1, s.budget.restPsnrDb, d.options.stepVoxels) &&
        levelFits(*s.volume, std::uint32_t(d.options.level)) &&
        !(mConfig.cluster && mConfig.cluster->ranks() > 1)) {
        d.checkStride = render::checkStride(o.width, o.height);
        if (d.checkStride > 1) d.job.pass = 1;
    }
    // A refinement pass at rest under an error bound: the session's step over 2^pass.
    if (d.job.pass > 0)
        d.options.stepVoxels = float(render::refinementStep(d.options.stepVoxels, d.job.pass));
    d.options.shading = shadingFor(o, s.tfMessage, *s.tf);
    // The decoder validated the camera (the same rules as Camera::validate).
    d.view = render::View::ofDecoded(*s.camera, d.options.width, d.options.height);
    planSlices(d, *s.volume->store, mConfig, mFrameSpeeds);
}

double RenderService::sliceMsBeside(const std::shared_ptr<RenderSlot>& slot,
                                    const FrameDrawing& d) const {
    const double sliceMs = double(mConfig.sliceMs);
    if (!d.job.refined || mConfig.interactiveMs == 0) return sliceMs;
    // Other sessions moving now: an interactive frame started within the rest interval and a
    // slice.
    const std::uint32_t moving = mRenderers->interactiveSessions(
        Clock::now(), std::chrono::milliseconds(mConfig.restMs + mConfig.sliceMs), slot.get());
    if (moving == 0) return sliceMs;
    return std::clamp(double(mConfig.interactiveMs) / double(moving + 1), kMinSliceBesideMs,
                      sliceMs);
}

bool RenderService::drawSlice(const std::shared_ptr<RenderSlot>& slot, FrameDrawing& d) {
    const RendererCache::Drawer drawer = mRenderers->rendererFor(slot, *d.kind, d.job.state.volume);
    render::Renderer& renderer = drawer.renderer;
    if (drawer.pool) d.pool = drawer.pool;
    SliceHooks hooks;
    hooks.draw = [&](const render::RenderOptions& options, render::FrameStats& stats) {
        return drawRegion(renderer, d, options, stats);
    };
    hooks.sliceMs = [&] { return sliceMsBeside(slot, d); };
    hooks.now = [] { return Clock::now(); };
    hooks.sliceDrawn = [this] { withCounters([](RenderCounters& c) { c.slices += 1; }); };
    hooks.checkDrawn = [this] { withCounters([](RenderCounters& c) { c.checks += 1; }); };
    hooks.frameSpeeds = &mFrameSpeeds;
    hooks.sliceSpeeds = &mSliceSpeeds;
    if (!drawNext(d, hooks)) return false; // more slices: the other sessions' turn
    planPrefetch(mRenderers->of(slot).prefetch, d, renderer, mConfig.prefetch);
    return true;
}

render::Image RenderService::drawRegion(render::Renderer& renderer, const FrameDrawing& d,
                                        const render::RenderOptions& options,
                                        render::FrameStats& stats) {
    const auto& s = d.job.state;
    const render::Scene scene{*s.volume->store, *s.volume->cache, *s.tf, *mClassifications};
    FrameCluster* cluster = mConfig.cluster;
    // The raycasters' frames go across the ranks; the other renderers (the reference and the
    // splatters, which do not draw parts) draw here, from the whole volume (rank 0 reads the
    // same store).
    if (!cluster || cluster->ranks() < 2 || !d.kind->parts || options.stride > 1)
        return renderer.render(scene, d.view, options, stats);
    // Every rank draws with rank 0's options as they stand (the level the frame-time budget
    // chose, a refinement pass's step, shading) and its camera.
    ClusterOrder order{s.volume->name, d.kind->name, d.view.camera, s.tfMessage, options};
    if (order.options.region.whole()) order.options.region = {0, 0, options.width, options.height};
    // Rank 0's host cache keeps what its own earlier slices loaded; the workers keep their own.
    order.options.hostKeptBefore = 0;
    render::RenderOptions whole = options;
    whole.region = order.options.region;
    ClusterFrameStats ranks;
    const auto start = Clock::now();
    render::Image image;
    try {
        image = cluster->draw(
            order, *s.volume->store, d.view, whole,
            [&](const render::RenderOptions& o, render::FrameStats& mine) {
                return renderer.render(scene, d.view, o, mine);
            },
            stats, ranks);
    } catch (const ClusterFailed&) {
        withCounters([](RenderCounters& c) { c.clusterFailures += 1; });
        throw;
    }
    if (const auto combine = render::combineFor(options.mode);
        combine != render::PartsCombine::Over) { // a projection's combined values, as colours
        const auto levels = std::uint32_t(s.volume->store->layout().levels().size());
        const auto level = std::min<std::uint32_t>(std::uint32_t(options.level), levels - 1);
        render::resolveProjections(image, options.mode,
                                   *mClassifications
                                        ->get(*s.volume->store, level, *s.tf, nullptr, nullptr,
                                              render::SkipRule::of(options))
                                        ->table(1.0));
    }
    // The frame's work is every rank's; its time is rank 0's wall time.
    stats.samples = ranks.samples();
    stats.totalMs = msSince(start);
    std::lock_guard lock(mMutex);
    RenderCounters& c = *mCounters;
    c.clusterSlices += 1;
    c.clusterBytes += double(ranks.bytesComposited());
    c.clusterCompositeMs.observe(ranks.compositeMs);
    c.clusterImbalance.observe(ranks.imbalance());
    c.lastImbalance = ranks.imbalance();
    c.rankRenderMs.resize(ranks.ranks.size());
    c.rankSamples.resize(ranks.ranks.size());
    for (std::size_t r = 0; r < ranks.ranks.size(); ++r) {
        c.rankRenderMs[r] += ranks.ranks[r].renderMs;
        c.rankSamples[r] += double(ranks.ranks[r].samples);
    }
    return image;
}

void RenderService::turn(const std::shared_ptr<RenderSlot>& slotPtr,
                         std::optional<RenderSlot::Job> job) {
    RenderSlot& slot = *slotPtr;
    auto& mine = mRenderers->of(slotPtr);
    if (job) {
        mine.drawing = std::make_unique<FrameDrawing>();
        mine.drawing->job = std::move(*job);
        if (!mine.drawing->job.refined) {
            // Sessions that started an interactive frame within the last second, or are drawing
            // one, share the frame-time budget.
            mine.lastInteractive = Clock::now();
            mine.drawing->sharers = std::max<std::uint32_t>(
                mRenderers->interactiveSessions(Clock::now(), std::chrono::seconds(1)), 1);
        }
    } else if (slot.closed() || (mine.drawing->refinement() && slot.superseded())) {
        // Nobody waits for it, or it refines a view the camera has left (interactive frames
        // follow). Other frames complete: a client that keeps moving its camera while its
        // frames take longer than its camera updates still sees every other view drawn, and a
        // requested frame is owed its answer.
        mine.drawing.reset();
        slot.frameDone(0);
        withCounters([](RenderCounters& c) { c.cancelled += 1; });
        return;
    }
    FrameDrawing& d = *mine.drawing;
    const std::string volume = d.job.state.volume->name;
    const std::uint32_t requestId = d.job.requestId;
    std::vector<std::uint8_t> bytes;
    std::uint32_t nextPass = 0; ///< > 0: the refinement pass to draw after this frame
    try {
        std::optional<protocol::Frame> cached;
        if (job) {
            prepare(d);
            cached = fromCache(slot, d);
        }
        if (!cached && !drawSlice(slotPtr, d)) return; // more slices: the other sessions' turn
        // At rest under an error bound: the pass's estimate decides whether another follows.
        const double boundDb = d.job.state.budget.restPsnrDb;
        if (!cached && d.refinement() && boundDb > 0)
            nextPass = afterPass(mine, d, boundDb);
        else
            mine.lastPass.clear();
        FrameRecord rec;
        const protocol::Frame frame = cached ? std::move(*cached) : finish(slot, d, rec);
        protocol::encode(frame, requestId, bytes);
        const double latencyMs = cached ? msSince(d.job.queuedAt) : 0;
        withCounters([&](RenderCounters& c) {
            if (cached)
                c.recordCached(frame.header, double(bytes.size()), latencyMs);
            else
                c.recordFrame(rec, double(bytes.size()), volume, d.pool);
        });
        withCounters([&](RenderCounters& c) {
            c.refined += frame.header.refined;
            c.samples += double(frame.header.samples);
        });
    } catch (const std::exception& e) {
        const bool refused = dynamic_cast<const FrameRefused*>(&e) != nullptr;
        protocol::Error error{refused ? protocol::ErrorCode::OutOfRange
                                      : protocol::ErrorCode::RenderFailed,
                              false, std::uint8_t(protocol::MessageType::RequestFrame),
                              protocol::fitText(e.what(), protocol::kMaxErrorMessageBytes)};
        bytes.clear();
        protocol::encode(error, requestId, bytes);
        if (!dynamic_cast<const VolumeOutOfService*>(&e)) {
            mLog.error("render: " + volume + ": " + e.what());
            checkStore(d.job.state.volume, e);
        }
        withCounters([&](RenderCounters& c) { (refused ? c.refused : c.errors) += 1; });
    }
    mine.drawing.reset();
    slot.delivering(bytes.size());
    std::unique_lock lock(slot.mMutex);
    auto deliver = slot.mDeliver;
    lock.unlock();
    if (deliver)
        deliver(std::move(bytes));
    else
        slot.frameDone(bytes.size());
    if (nextPass > 0) slot.continueRefinement(nextPass);
}

protocol::Frame RenderService::finish(RenderSlot& slot, FrameDrawing& d, FrameRecord& rec) {
    const auto& s = d.job.state;
    const auto& o = s.options;
    d.stats.renderer = d.kind->name;
    d.stats.rendererChoice = d.rendererChoice;
    const render::FrameStats& stats = d.stats;
    std::vector<std::uint8_t> rgba8 = std::move(d.rgba8);
    // An interactive frame is scaled up here, or sent as drawn for the client to scale.
    const bool asDrawn = !d.job.refined && (o.flags & protocol::kFlagUnscaledInteractive);
    const auto width = std::uint16_t(asDrawn ? d.options.width : o.width);
    const auto height = std::uint16_t(asDrawn ? d.options.height : o.height);
    if (!d.job.refined && !asDrawn)
        rgba8 = upscaleBy(rgba8, d.options.width, d.options.height, o.width, o.height, d.divisor);
    protocol::Frame frame;
    frame.header.renderMs = float(msSince(d.start));
    if (d.budgeted)
        mBudget->record(s.volume->name, d.drawing, stats.level,
                        std::uint64_t(d.options.width) * d.options.height, d.drawMs,
                        stats.uploadMs + stats.octreeRebuildMs + stats.cellBuildMs);
    // A refined frame may have its own codec (lossless at rest, JPEG while moving), at that
    // codec's default quality: codecQuality is `codec`'s.
    const bool ownCodec = d.job.refined && o.refinedCodec;
    const protocol::Codec codec = ownCodec ? *o.refinedCodec : o.codec;
    const std::uint8_t quality = ownCodec ? 0 : o.codecQuality;
    auto encoded = slot.mEncoder.encode(rgba8, width, height, codec, quality);
    auto& h = frame.header;
    h.frameId = slot.mNextFrameId++;
    h.cameraId = s.cameraId;
    h.width = width;
    h.height = height;
    h.codec = codec;
    h.level = std::uint8_t(stats.level);
    h.refined = d.job.refined;
    h.keyframe = encoded.keyframe;
    h.queueMs = float(std::chrono::duration<double, std::milli>(d.start - d.job.queuedAt).count());
    h.encodeMs = float(encoded.encodeMs);
    h.samples = stats.samples;
    h.bricksDrawn = std::uint32_t(stats.bricksVisited);
    h.bricksSkipped = std::uint32_t(stats.bricksSkipped);
    h.bytesUploaded = stats.bytesUploaded;
    h.occlusionUsed = stats.occlusionUsed;
    h.scale = std::uint8_t(d.divisor);
    if (d.estimatedPsnrDb >= 0)
        h.estimatedPsnrDb = std::uint8_t(
            std::clamp(std::floor(d.estimatedPsnrDb), 0.0, double(protocol::kMaxRestPsnrDb)));
    // A frame drawn at a coarser level than asked for (level 0 over the GPU pool's share,
    // which changes with the sessions) depends on more than its key: not kept.
    if (d.cacheKey && stats.level == std::uint32_t(d.options.level)) {
        CachedFrame kept{width, height, codec, h.level, quality, {}};
        kept.bytes = kept.pixels() ? std::move(rgba8) : encoded.bytes;
        mFrames->insert(std::move(*d.cacheKey), std::move(kept), s.volume);
    }
    frame.image = std::move(encoded.bytes);
    rec.renderer = d.kind->name;
    rec.renderMs = h.renderMs;
    rec.encodeMs = h.encodeMs;
    rec.uploadMs = stats.uploadMs;
    rec.latencyMs = msSince(d.job.queuedAt);
    rec.bricks = double(residentBricks(stats));
    rec.bricksDeferred = double(stats.bricksDeferred);
    rec.bricksRequested = double(stats.bricksRequested);
    rec.workingSetBytes = rec.bricks * double(slotBytesOf(*s.volume->store));
    rec.bricksUploaded = double(stats.bricksUploaded);
    return frame;
}

std::optional<protocol::Frame> RenderService::fromCache(RenderSlot& slot, FrameDrawing& d) {
    // Under a time budget an interactive frame's size follows the machine's speed as well as
    // its request: neither served from the cache nor kept in it.
    // Nor is a refined frame under an error bound: its passes are estimated from each other's
    // pixels, and passes after the first have a step of their own.
    if (!mFrames->enabled() || d.budgeted || (d.job.refined && d.job.state.budget.restPsnrDb > 0))
        return std::nullopt;
    const auto& s = d.job.state;
    FrameKey key = frameKeyOf(s.volume->store->instance(), d.kind->name, d.job.refined,
                              d.options.shading, d.view.camera, s.options, s.tf, s.modeAndClip);
    const std::shared_ptr<const CachedFrame> kept = mFrames->find(key);
    if (!kept) {
        d.cacheKey = std::move(key);
        return std::nullopt;
    }
    protocol::Frame frame = frameFrom(*kept, slot.mEncoder);
    auto& h = frame.header;
    h.frameId = slot.mNextFrameId++;
    h.cameraId = d.job.state.cameraId;
    h.refined = d.job.refined;
    h.queueMs = float(std::chrono::duration<double, std::milli>(d.start - d.job.queuedAt).count());
    h.renderMs = float(msSince(d.start));
    return frame;
}

} // namespace bc::server
