#include "server/RenderService.h"

#include "brickstore/Error.h"
#include "render/BrickPlan.h"
#include "render/BrickPool.h"
#include "render/Classification.h"
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
#include "server/RenderMetrics.h"
#include "server/ViewRequest.h"

#include <algorithm>
#include <cmath>
#include <cstdio>
#include <map>

#include <glm/geometric.hpp>

namespace bc::server {

// The highest bound a client may ask for at rest is the highest estimate a pass can carry: the
// protocol cannot see the estimator (the module rules), so the two are checked here.
static_assert(double(protocol::kMaxRestPsnrDb) == render::kMaxEstimateDb);

namespace {

double msSince(Clock::time_point t) {
    return std::chrono::duration<double, std::milli>(Clock::now() - t).count();
}

} // namespace

// ---- RenderService -------------------------------------------------------------------------

namespace {

using RendererMap = std::map<std::string, std::unique_ptr<render::Renderer>, std::less<>>;

/// What the sessions of one volume share (render thread only): the bricks resident on the GPU
/// and the renderers that hold nothing of one viewer (RendererKind::sharedPerVolume).
struct VolumeRenderers {
    /// Held until pruned: the map is keyed by its address, which must not be reused meanwhile.
    std::shared_ptr<Volume> volume;
    std::shared_ptr<render::BrickPool> pool;
    std::uint64_t poolBudgetBytes = 0;
    RendererMap shared;
};

} // namespace

/// A frame being drawn (render thread only): what its first turn resolved, the image so far and
/// where the next slice starts. A frame that fits one slice lives for one turn.
struct FrameDrawing {
    RenderSlot::Job job;
    const render::RendererKind* kind = nullptr;
    render::RenderOptions options; ///< the whole frame's (region: whole)
    render::View view;
    std::uint64_t costPerPixel = 0; ///< estimated samples of one ray (the longest)
    std::uint64_t cost = 0;         ///< of the whole frame
    bool sliced = false;
    /// The frame drawn, 8-bit RGBA (a sliced frame's slices are converted as they come: at
    /// 4096^2 that is 64 MiB where float pixels would take 256).
    std::vector<std::uint8_t> rgba8;
    std::uint64_t nextPixel = 0; ///< row-major cursor
    // Slices are sized by each pixel's samples: its ray's length inside the level's box over the
    // step (plus one for the ray), so rows that miss the volume are not taken for dense ones.
    render::Box box;
    double stepMm = 1;
    std::vector<double> rowCost; ///< per row, computed as the cursor reaches it (< 0: not yet)
    double sliceTargetMs = 0;    ///< the next slice's length
    std::uint32_t slices = 0;
    double slicesMs = 0; ///< drawing them
    render::FrameStats stats;
    const render::BrickPool* pool = nullptr;
    Clock::time_point start;
    std::string rendererChoice;       ///< why d.kind draws it (RendererChoice::reason)
    std::optional<FrameKey> cacheKey; ///< set when the frame cache is on and had no frame
    /// An interactive frame is drawn at the requested size over this (rounded up).
    std::uint32_t divisor = 1;
    /// Sessions drawing interactive frames now, this one included: they share the budget.
    std::uint32_t sharers = 1;
    bool budgeted = false; ///< an interactive frame whose level and scale a time budget chose
    /// A refined frame's estimated PSNR against the converged image (render/
    /// RefinementEstimate.h); negative: none.
    double estimatedPsnrDb = -1;
    /// The first refinement pass at rest under an error bound, where the renderer draws a
    /// stride: the stride of the sparse frame at twice the pass's step that it is checked
    /// against (render::checkStride; 1: no such check), that frame (8-bit RGBA, the lattice's
    /// size) and the image row its next band starts at (a sliced frame draws it in bands of
    /// rows, first).
    std::uint32_t checkStride = 1;
    std::vector<std::uint8_t> check;
    std::uint32_t checkRow = 0;
    double checkMs = 0;      ///< drawing it
    double drawMs = 0;       ///< drawing its slices, not waiting for other sessions' turns
    std::uint32_t draws = 0; ///< render calls so far (slices and bands of the check)

    bool checkDue() const { return checkStride > 1 && checkRow < options.height; }

    /// A refined frame drawn because an adaptive session's camera came to rest.
    bool refinement() const {
        return !job.requested && job.refined &&
               job.state.options.quality == protocol::Quality::Adaptive;
    }
};

namespace {

/// A session's own renderers, by name: each keeps what is the session's (its previous frame's
/// occlusion frustums and ray feedback); bricks come from the volume's shared pool and
/// classifications from the service's cache.
struct SessionRenderers {
    std::weak_ptr<RenderSlot> slot;
    std::unique_ptr<FrameDrawing> drawing; ///< the frame in progress, if any
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
    /// When its last interactive frame started (budget sharing, InteractiveBudget::choose).
    std::optional<Clock::time_point> lastInteractive;
    /// The last refinement pass drawn under an error bound (8-bit RGBA), which the next pass is
    /// estimated against; empty once any other frame is drawn.
    std::vector<std::uint8_t> lastPass;
    std::uint32_t lastPassIndex = 0;
};

} // namespace

struct RenderService::Renderers {
    std::unique_ptr<render::EglContext> context;
    /// What `auto` draws with on this server: decided at its first frame, once (autoChoice).
    std::optional<render::RendererChoice> autoChoice;
    std::map<const Volume*, VolumeRenderers> volumes;
    std::map<const RenderSlot*, SessionRenderers> sessions;

    /// Renderers of closed sessions and pools of volumes nobody views go (GL objects, on
    /// this thread). `retired` is told the name of each volume whose pool goes. Returns the
    /// frames in progress that went with their sessions.
    std::uint32_t prune(const std::function<void(const std::string&)>& retired) {
        std::uint32_t dropped = 0;
        std::erase_if(sessions, [&](const auto& e) {
            if (!e.second.slot.expired()) return false;
            dropped += e.second.drawing != nullptr;
            return true;
        });
        std::erase_if(volumes, [&](const auto& e) {
            if (e.second.volume->sessions.load() != 0) return false;
            for (const auto& [key, s] : sessions) // a frame in progress keeps its renderers
                if (s.drawing && s.drawing->job.state.volume.get() == e.first) return false;
            if (e.second.pool) retired(e.first->name);
            return true;
        });
        return dropped;
    }
    SessionRenderers& of(const std::shared_ptr<RenderSlot>& slot) {
        auto& s = sessions[slot.get()];
        if (s.slot.lock() != slot) { // a reused address
            s = SessionRenderers{};
            s.slot = slot;
        }
        return s;
    }
};

namespace {

/// Bricks a frame held resident: those it drew, less constant ones (no texture) and those
/// ray-guided residency left unloaded.
std::uint64_t residentBricks(const render::FrameStats& s) {
    // A sliced frame's counts of bricks are its largest slice's, its deferrals the sum of its
    // slices': the difference is a lower bound (and never below zero).
    const std::uint64_t drawn = s.bricksVisited - s.bricksConstant;
    const std::uint64_t unloaded =
        s.bricksDeferred > s.bricksRequested ? s.bricksDeferred - s.bricksRequested : 0;
    return drawn > unloaded ? drawn - unloaded : 0;
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

} // namespace

namespace {

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
    case protocol::Renderer::Auto:
        return "auto";
    }
    return "unknown";
}

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
    std::lock_guard lock(mMutex);
    mCounters->gpuContext = 1;
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
    const auto now = Clock::now();
    for (const auto& w : mSlots)
        if (auto slot = w.lock()) {
            const auto at = slot->readyAt(mConfig.restMs);
            waiting += at && *at <= now;
        }
    RenderMetricsContext context;
    context.slotsWaiting = waiting;
    context.cluster = mConfig.cluster;
    context.frameCache = mFrames->stats();
    context.classifications = mClassifications->stats();
    context.gpuUnavailable = mGpuUnavailable.has_value();
    context.autoChoice = mAutoChoice;
    mCounters->exportTo(m, context);
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
            checkStore(job.volume, e);
        }
    }
    std::lock_guard lock(mMutex);
    mCounters->prefetchMs += msSince(start);
}

void RenderService::record(const FrameRecord& f, double bytes, const std::string& volume,
                           const render::BrickPool* pool) {
    std::lock_guard lock(mMutex);
    mCounters->recordFrame(f, bytes, volume, pool);
}

void RenderService::recordCached(const protocol::FrameHeader& h, double bytes, double latencyMs) {
    std::lock_guard lock(mMutex);
    mCounters->recordCached(h, bytes, latencyMs);
}

void RenderService::retirePool(const std::string& volume) {
    std::lock_guard lock(mMutex);
    mCounters->retirePool(volume);
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
    mRenderers = std::make_unique<Renderers>();
    std::unique_lock lock(mMutex);
    while (!mStop) {
        // Sessions gone go first (their frames in progress with them), before any wait.
        lock.unlock();
        const std::uint32_t dropped =
            mRenderers->prune([this](const std::string& volume) { retirePool(volume); });
        lock.lock();
        mCounters->cancelled += dropped;
        if (mConfig.cluster) { // the workers hear from rank 0 at least every kHeartbeat
            lock.unlock();
            mConfig.cluster->idle();
            lock.lock();
        }
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
        std::optional<RenderSlot::Job> job;
        if (!drawing(slot.get())) job = slot->take(Clock::now(), mConfig.restMs);
        lock.unlock();
        turn(slot, std::move(job));
        lock.lock();
    }
    lock.unlock();
    mRenderers.reset(); // GL objects go before the context, on this thread
}

bool RenderService::drawing(const RenderSlot* slot) const {
    const auto it = mRenderers->sessions.find(slot);
    return it != mRenderers->sessions.end() && it->second.drawing &&
           it->second.slot.lock().get() == slot;
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
    if (wakeAt)
        mWake.wait_until(lock, *wakeAt);
    else
        mWake.wait(lock);
    return nullptr;
}

namespace {

/// A frame over its cost cap: answered OutOfRange, not RenderFailed.
struct FrameRefused : std::runtime_error {
    using std::runtime_error::runtime_error;
};

/// A frame of a volume out of service: answered RenderFailed at once, not logged again.
struct VolumeOutOfService : std::runtime_error {
    using std::runtime_error::runtime_error;
};

/// Cost units (samples) per millisecond assumed of a renderer before it has drawn anything:
/// low (2 M samples/s, the reference renderer's order on one slow core), so that a first
/// frame that turns out heavy is sliced rather than drawn whole, and its first slice is short
/// on any machine (at 20 M samples/s assumed, a first slice under ThreadSanitizer took 18 s).
/// The measured speed replaces it from the first slice on.
constexpr double kFirstCostPerMs = 2000.0;

/// The speed `rates` holds for renderer `name` (cost units per millisecond), or
/// kFirstCostPerMs before it has drawn anything.
double speedOf(const std::map<std::string, double, std::less<>>& rates, std::string_view name) {
    const auto rate = rates.find(name);
    return rate == rates.end() ? kFirstCostPerMs : rate->second;
}

/// The shortest slice of a refined frame beside moving sessions (sliceMsBeside): shorter, the
/// fixed cost of a slice (planning the frame's bricks: about 2 ms for the 2.36 GiB mosaic on
/// the dev VM) would be a large part of it.
constexpr double kMinSliceBesideMs = 10.0;

/// Estimated cost of pixel (x, y): its ray's samples inside the box, plus one for the ray.
double pixelCost(const FrameDrawing& d, std::uint32_t x, std::uint32_t y) {
    const render::Ray ray = d.view.basis.ray(x, y, d.options.width, d.options.height);
    const auto [t0, t1] = render::intersectBox(ray, d.box);
    return 1.0 + std::max(0.0, (t1 - std::max(t0, 0.0)) / d.stepMm);
}

double rowCost(FrameDrawing& d, std::uint32_t y) {
    if (d.rowCost[y] < 0) {
        double sum = 0;
        for (std::uint32_t x = 0; x < d.options.width; ++x)
            sum += pixelCost(d, x, y);
        d.rowCost[y] = sum;
    }
    return d.rowCost[y];
}

/// The next slice of about `budget` cost units (at least one pixel): whole rows from the cursor
/// when it is at a row's start and its row fits, else a run of the cursor's row. Returns the
/// slice and (in `cost`) its estimated cost.
render::PixelRect nextSlice(FrameDrawing& d, double budget, double& cost) {
    const std::uint32_t w = d.options.width, h = d.options.height;
    const auto x = std::uint32_t(d.nextPixel % w), y = std::uint32_t(d.nextPixel / w);
    cost = 0;
    if (x == 0 && rowCost(d, y) <= budget) {
        std::uint32_t rows = 0;
        while (y + rows < h && cost + rowCost(d, y + rows) <= budget)
            cost += rowCost(d, y + rows++);
        return {0, y, w, rows};
    }
    std::uint32_t n = 0;
    while (x + n < w && (n == 0 || cost + pixelCost(d, x + n, y) <= budget))
        cost += pixelCost(d, x + n++, y);
    return {x, y, n, 1};
}

void paste(std::vector<std::uint8_t>& frame, std::uint32_t frameWidth, const render::Image& part,
           const render::PixelRect& at) {
    const auto bytes = render::toRgba8(part);
    const std::size_t row = std::size_t(part.width) * 4;
    for (std::uint32_t y = 0; y < part.height; ++y)
        std::copy_n(&bytes[y * row], row, &frame[(std::size_t(at.y + y) * frameWidth + at.x) * 4]);
}

/// The frame's statistics with those of its next slice (the first is the frame's so far).
void accumulate(render::FrameStats& total, const render::FrameStats& slice, bool first) {
    if (first)
        total = slice;
    else
        render::addSlice(total, slice);
}

/// The bytes of `level` of `volume` (the last level past it) a host cache can hold: its
/// stored bricks, decompressed, aprons included (a brick of one value is never loaded).
double levelBytes(const Volume& volume, std::uint32_t level) {
    const auto last = std::uint32_t(volume.store->layout().levels().size() - 1);
    return double(volume.store->storedBricks(std::min(level, last))) *
           double(volume.store->brickBytes());
}

/// Whether those bytes fit the volume's share of the host cache.
bool levelFits(const Volume& volume, std::uint32_t level) {
    return levelBytes(volume, level) <= double(volume.cache->stats().budgetBytes);
}

/// The levels an interactive frame of `volume` may be drawn at: the one asked for, or under
/// automatic level every level, each marked by whether its stored bricks fit the volume's
/// share of the host cache whole (levelBytes) and whether it is warm.
LevelRange interactiveLevels(const Volume& volume, const protocol::RenderOptions& o) {
    const brickstore::StoreLayout& layout = volume.store->layout();
    const auto levels = std::uint32_t(layout.levels().size());
    if (o.level != protocol::kLevelAutomatic) {
        const std::uint32_t l = std::min<std::uint32_t>(o.level, levels - 1);
        return {l, l, {}, {}};
    }
    const double share = double(volume.cache->stats().budgetBytes);
    LevelRange range{0, levels - 1, {}, {}};
    for (std::uint32_t l = 0; l < levels; ++l) {
        range.fits.push_back(levelFits(volume, l));
        range.warm.push_back(double(volume.cache->residentBytes(l)) >=
                             LevelRange::kWarmShare * std::min(levelBytes(volume, l), share));
    }
    return range;
}

std::string giga(std::uint64_t samples) {
    char text[32];
    std::snprintf(text, sizeof text, "%.3g", double(samples) / double(1ull << 30));
    return text;
}

} // namespace

void RenderService::prepare(FrameDrawing& d) {
    const auto& s = d.job.state;
    const auto& o = s.options;
    d.start = Clock::now();
    if (const auto why = s.volume->failure())
        throw VolumeOutOfService("volume '" + s.volume->name + "' is out of service: " + *why);
    std::string_view name = rendererName(o.renderer);
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
    const double targetMs =
        s.budget.interactiveMs > 0 ? double(s.budget.interactiveMs) : double(mConfig.interactiveMs);
    if (!d.job.refined && targetMs > 0)
        budgeted = mBudget->choose(s.volume->name, d.kind->name, o.width, o.height,
                                   interactiveLevels(*s.volume, o), d.sharers, targetMs);
    d.budgeted = budgeted.has_value();
    if (!d.job.refined) d.divisor = budgeted ? budgeted->divisor : InteractiveBudget::kFirstDivisor;
    d.options = toRenderOptions(o, d.divisor);
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
    d.view = render::View::ofDecoded(toCamera(*s.camera), d.options.width, d.options.height);

    // Cost: an upper bound of the samples (every ray as long as the level's diagonal), or the
    // voxels a splatter projects.
    const brickstore::BrickStore& store = *s.volume->store;
    const auto levels = std::uint32_t(store.layout().levels().size());
    const auto level = std::min<std::uint32_t>(std::uint32_t(d.options.level), levels - 1);
    const render::LevelGeometry g = render::LevelGeometry::of(store, level);
    const std::uint64_t pixels = std::uint64_t(d.options.width) * d.options.height;
    const double diagonal = glm::length(g.box.size());
    d.costPerPixel = std::uint64_t(std::ceil(diagonal / (d.options.stepVoxels * g.minSpacing())));
    const double voxels = double(g.dims[0]) * double(g.dims[1]) * double(g.dims[2]);
    const double cost =
        d.kind->objectOrder ? voxels + double(pixels) : double(pixels) * double(d.costPerPixel);
    const bool sliceable = d.kind->regions;
    const std::uint64_t cap = sliceable ? mConfig.maxFrameSamples : mConfig.maxUnslicedSamples;
    if (cost > double(cap))
        throw FrameRefused(
            "frame cost " + giga(std::uint64_t(std::min(cost, 1e19))) + " Gi samples (" +
            std::to_string(d.options.width) + "x" + std::to_string(d.options.height) + " pixels, " +
            std::to_string(d.costPerPixel) + " samples per ray, " + std::string(name) +
            ") is over the server's cap of " + giga(cap) + " Gi samples (" +
            (sliceable ? "frames.max_frame_gsamples" : "frames.max_unsliced_gsamples") + ")");
    d.cost = std::uint64_t(cost);

    const double perMs = speedOf(mCostPerMs, name);
    d.sliced = sliceable && cost / perMs > 1.5 * mConfig.sliceMs;
    if (d.sliced) {
        d.rgba8.assign(std::size_t(d.options.width) * d.options.height * 4, 0);
        d.box = g.box;
        d.stepMm = d.options.stepVoxels * g.minSpacing();
        d.rowCost.assign(d.options.height, -1.0);
        d.sliceTargetMs = mConfig.sliceMs;
    }
}

render::Renderer& RenderService::rendererFor(const std::shared_ptr<RenderSlot>& slot,
                                             FrameDrawing& d) {
    const auto& s = d.job.state;
    auto& v = mRenderers->volumes[s.volume.get()];
    v.volume = s.volume;
    auto& mine = mRenderers->of(slot);
    RendererMap& owner = d.kind->sharedPerVolume ? v.shared : mine.own;
    auto it = owner.find(d.kind->name);
    if (it == owner.end()) it = owner.emplace(d.kind->name, d.kind->create()).first;
    render::Renderer& renderer = *it->second;
    if (render::GpuResidency* gpu = renderer.gpuResidency()) {
        // the volume's bricks on the GPU are shared by its sessions
        const render::BrickPool* before = v.pool.get();
        auto& shared =
            sharedPool(v, *s.volume, mCatalog.shareOf(*s.volume, mConfig.gpuBudgetBytes));
        if (before && shared.get() != before) retirePool(s.volume->name);
        gpu->setSharedPool(shared);
        d.pool = shared.get();
    }
    return renderer;
}

std::uint32_t RenderService::interactiveSessions(Clock::duration within,
                                                 const RenderSlot* except) const {
    const auto now = Clock::now();
    std::uint32_t n = 0;
    // A frame still being drawn counts however long ago it started: a cold start's first
    // frames load the view's bricks for seconds, and the sessions drawing them share the
    // machine all the while.
    for (const auto& [key, other] : mRenderers->sessions)
        n += key != except && !other.slot.expired() &&
             ((other.lastInteractive && now - *other.lastInteractive < within) ||
              (other.drawing && !other.drawing->job.refined));
    return n;
}

double RenderService::sliceMsBeside(const std::shared_ptr<RenderSlot>& slot,
                                    const FrameDrawing& d) const {
    const double sliceMs = double(mConfig.sliceMs);
    if (!d.job.refined || mConfig.interactiveMs == 0) return sliceMs;
    // Other sessions moving now: an interactive frame started within the rest interval and a
    // slice.
    const std::uint32_t moving = interactiveSessions(
        std::chrono::milliseconds(mConfig.restMs + mConfig.sliceMs), slot.get());
    if (moving == 0) return sliceMs;
    return std::clamp(double(mConfig.interactiveMs) / double(moving + 1), kMinSliceBesideMs,
                      sliceMs);
}

double RenderService::drawCheck(render::Renderer& renderer, FrameDrawing& d, double budget) {
    const auto start = Clock::now();
    const render::PixelLattice lattice{d.checkStride};
    const std::uint32_t w = d.options.width, h = d.options.height;
    if (d.check.empty()) d.check.assign(std::size_t(lattice.first(w)) * lattice.first(h) * 4, 0);
    render::RenderOptions options = d.options;
    options.stride = d.checkStride;
    options.stepVoxels = 2.0 * d.options.stepVoxels; // the session's step: a power of two apart
    options.hostKeptBefore = d.stats.hostKeptBytes;  // its bricks count as the frame's
    // Whole lattice rows from d.checkRow, about `budget` cost units, at least one: a lattice
    // row takes a stride-th of its image row's rays, at twice the step.
    std::uint32_t rows = h - d.checkRow;
    if (budget > 0) {
        double cost = 0;
        std::uint32_t j = lattice.first(d.checkRow);
        do
            cost += rowCost(d, lattice.pixel(j)) / (2.0 * d.checkStride);
        while (++j < lattice.first(h) && cost < budget);
        rows = (j < lattice.first(h) ? lattice.pixel(j) : h) - d.checkRow;
    }
    options.region = {0, d.checkRow, w, rows};
    const std::optional<render::PixelRect> at = lattice.of(options.region);
    render::FrameStats stats;
    const render::Image band = drawRegion(renderer, d, options, stats);
    paste(d.check, lattice.first(w), band, *at);
    accumulate(d.stats, stats, d.draws++ == 0);
    d.checkRow += rows;
    d.checkMs += msSince(start);
    if (!d.checkDue()) {
        std::lock_guard lock(mMutex);
        mCounters->checks += 1;
    }
    return std::min(stats.uploadMs, msSince(start));
}

bool RenderService::drawSlice(const std::shared_ptr<RenderSlot>& slot, FrameDrawing& d) {
    render::Renderer& renderer = rendererFor(slot, d);
    if (d.checkDue() && !d.sliced) {
        drawCheck(renderer, d, 0); // whole, and the pass in the same turn
    } else if (d.checkDue()) {     // a band of it is this turn's slice
        if (d.draws == 0) d.sliceTargetMs = sliceMsBeside(slot, d);
        const double loadMs =
            drawCheck(renderer, d, d.sliceTargetMs * speedOf(mSliceCostPerMs, d.kind->name));
        d.sliceTargetMs = std::max(sliceMsBeside(slot, d), 2.0 * loadMs);
        d.drawMs = d.checkMs;
        return false;
    }
    const auto start = Clock::now();
    // Speeds measured, per renderer: whole frames against their upper-bound cost (whether to
    // slice), slices against their pixels' estimated samples (how large a slice is). The
    // estimate is an upper bound whose truth varies across an image (skipping, early ray
    // termination, rays that miss): a slower speed is taken at once, so that a slice that ran
    // long is not followed by another, and a faster one is approached by halves.
    auto calibrate = [&](std::map<std::string, double, std::less<>>& rates, double cost,
                         double ms) {
        const double perMs = cost / std::max(ms, 0.01);
        auto [it, fresh] = rates.try_emplace(d.kind->name, perMs);
        if (!fresh) it->second = perMs < it->second ? perMs : 0.5 * (it->second + perMs);
    };
    if (!d.sliced) {
        render::FrameStats stats;
        d.rgba8 = render::toRgba8(drawRegion(renderer, d, d.options, stats));
        accumulate(d.stats, stats, d.draws++ == 0);
        const double ms = msSince(start);
        d.drawMs = d.checkMs + ms;
        calibrate(mCostPerMs, double(d.cost), ms);
        planPrefetch(slot, d, renderer);
        return true;
    }
    const double perMs = speedOf(mSliceCostPerMs, d.kind->name);
    double cost = 0;
    render::RenderOptions options = d.options;
    if (d.draws == 0) d.sliceTargetMs = sliceMsBeside(slot, d);
    options.region = nextSlice(d, d.sliceTargetMs * perMs, cost);
    options.hostKeptBefore = d.stats.hostKeptBytes; // the slices keep one frame's bricks
    render::FrameStats stats;
    const render::Image part = drawRegion(renderer, d, options, stats);
    paste(d.rgba8, d.options.width, part, options.region);
    accumulate(d.stats, stats, d.draws++ == 0);
    // The speed of the rays alone: loading bricks is a cost per slice, not per pixel (when the
    // frame's bricks exceed the host budget, a brick whose footprint spans several slices is
    // loaded by each). Slices are made long enough that it stays at most half of each.
    const double ms = msSince(start), loadMs = std::min(stats.uploadMs, ms);
    calibrate(mSliceCostPerMs, cost, ms - loadMs);
    d.sliceTargetMs = std::max(sliceMsBeside(slot, d), 2.0 * loadMs);
    ++d.slices;
    d.slicesMs += msSince(start);
    d.drawMs = d.checkMs + d.slicesMs;
    d.nextPixel += options.region.pixels();
    {
        std::lock_guard lock(mMutex);
        mCounters->slices += 1;
    }
    if (d.nextPixel < std::uint64_t(d.options.width) * d.options.height) return false;
    // The whole frame's speed too, so that a frame like it is sliced only when it must be.
    calibrate(mCostPerMs, double(d.cost), d.slicesMs);
    planPrefetch(slot, d, renderer);
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
        std::lock_guard lock(mMutex);
        mCounters->clusterFailures += 1;
        throw;
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

void RenderService::planPrefetch(const std::shared_ptr<RenderSlot>& slot, const FrameDrawing& d,
                                 render::Renderer& renderer) {
    render::GpuResidency* gpu = renderer.gpuResidency();
    if (!gpu) return;
    const auto& s = d.job.state;
    auto& mine = mRenderers->of(slot);
    mine.previousCamera = mine.lastCamera;
    mine.lastCamera = d.view.camera;
    mine.prefetch.reset();
    // A sliced frame's brick count is its largest slice's (a lower bound): prefetch may then
    // evict a few of the frame's bricks, which costs uploads later, never a wrong frame.
    if (mConfig.prefetch && mine.previousCamera && gpu->pool())
        mine.prefetch = SessionRenderers::Prefetch{
            &renderer, s.volume,
            s.tf,      render::predictNext(*mine.previousCamera, d.view.camera),
            d.options, residentBricks(d.stats)};
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
            mine.drawing->sharers =
                std::max<std::uint32_t>(interactiveSessions(std::chrono::seconds(1)), 1);
        }
    } else if (slot.closed() || (mine.drawing->refinement() && slot.superseded())) {
        // Nobody waits for it, or it refines a view the camera has left (interactive frames
        // follow). Other frames complete: a client that keeps moving its camera while its
        // frames take longer than its camera updates still sees every other view drawn, and a
        // requested frame is owed its answer.
        mine.drawing.reset();
        slot.frameDone(0);
        std::lock_guard lock(mMutex);
        mCounters->cancelled += 1;
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
        // At rest under an error bound: each pass after the first is estimated against the
        // one before, and another follows at half the step until the estimate meets the bound.
        const double boundDb = d.job.state.budget.restPsnrDb;
        if (!cached && d.refinement() && boundDb > 0) {
            if (!d.check.empty())
                d.estimatedPsnrDb = render::estimatedPsnrDb(
                    render::latticeOf(d.rgba8, d.options.width, d.options.height, d.checkStride),
                    d.check);
            else if (d.job.pass > 0 && mine.lastPassIndex + 1 == d.job.pass &&
                     mine.lastPass.size() == d.rgba8.size())
                d.estimatedPsnrDb = render::estimatedPsnrDb(d.rgba8, mine.lastPass);
            mine.lastPass = d.rgba8;
            mine.lastPassIndex = d.job.pass;
            if (render::refineFurther(d.estimatedPsnrDb, boundDb, d.options.stepVoxels))
                nextPass = d.job.pass + 1;
        } else {
            mine.lastPass.clear();
        }
        FrameRecord rec;
        const protocol::Frame frame = cached ? std::move(*cached) : finish(slot, d, rec);
        protocol::encode(frame, requestId, bytes);
        if (cached)
            recordCached(frame.header, double(bytes.size()), msSince(d.job.queuedAt));
        else
            record(rec, double(bytes.size()), volume, d.pool);
        std::lock_guard lock(mMutex);
        mCounters->refined += frame.header.refined;
        mCounters->samples += double(frame.header.samples);
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
        std::lock_guard lock(mMutex);
        (refused ? mCounters->refused : mCounters->errors) += 1;
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
        mBudget->record(s.volume->name, d.kind->name, stats.level,
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
    h.cameraId = s.camera->cameraId;
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

namespace {

/// What determines the frame `d` (prepared): FrameCache.h.
FrameKey keyOf(const FrameDrawing& d) {
    const auto& s = d.job.state;
    FrameKey key;
    key.storeInstance = s.volume->store->instance();
    key.renderer = d.kind->name;
    key.refined = d.job.refined;
    key.shading = d.options.shading;
    protocol::SetCamera camera = *s.camera;
    camera.cameraId = 0; // the client's name for the view, not the view
    protocol::encode(camera, 0, key.request);
    protocol::SetRenderOptions options{s.options};
    // What they decide is in the key already: who draws it (key.renderer) and whether it is
    // refined (an adaptive session's frame at rest is a refined session's frame).
    options.options.renderer = protocol::Renderer::Auto;
    options.options.quality = protocol::Quality::Adaptive;
    protocol::encode(options, 0, key.request);
    key.tf = s.tf;
    return key;
}

} // namespace

std::optional<protocol::Frame> RenderService::fromCache(RenderSlot& slot, FrameDrawing& d) {
    // Under a time budget an interactive frame's size follows the machine's speed as well as
    // its request: neither served from the cache nor kept in it.
    // Nor is a refined frame under an error bound: its passes are estimated from each other's
    // pixels, and passes after the first have a step of their own.
    if (!mFrames->enabled() || d.budgeted || (d.job.refined && d.job.state.budget.restPsnrDb > 0))
        return std::nullopt;
    FrameKey key = keyOf(d);
    const std::shared_ptr<const CachedFrame> kept = mFrames->find(key);
    if (!kept) {
        d.cacheKey = std::move(key);
        return std::nullopt;
    }
    protocol::Frame frame;
    auto& h = frame.header;
    if (kept->pixels()) { // a delta against this session's own previous frame
        auto encoded = slot.mEncoder.encode(kept->bytes, kept->width, kept->height, kept->codec,
                                            kept->quality);
        h.keyframe = encoded.keyframe;
        h.encodeMs = float(encoded.encodeMs);
        frame.image = std::move(encoded.bytes);
    } else {
        slot.mEncoder.resetDelta(); // as encoding a frame of another codec does
        frame.image = kept->bytes;
    }
    h.frameId = slot.mNextFrameId++;
    h.cameraId = d.job.state.camera->cameraId;
    h.width = kept->width;
    h.height = kept->height;
    h.codec = kept->codec;
    h.level = kept->level;
    h.refined = d.job.refined;
    h.cached = true;
    h.queueMs = float(std::chrono::duration<double, std::milli>(d.start - d.job.queuedAt).count());
    h.renderMs = float(msSince(d.start));
    return frame;
}

} // namespace bc::server
