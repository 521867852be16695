#include "server/RendererCache.h"

#include "brickstore/BrickStore.h"
#include "render/BrickPool.h"
#include "render/RefinementEstimate.h"
#include "render/RendererRegistry.h"
#include "server/Catalog.h"

namespace bc::server {

bool poolOutgrown(std::uint64_t poolBytes, std::uint64_t shareBytes) {
    return shareBytes < poolBytes - poolBytes / 8 || shareBytes > poolBytes + poolBytes / 8;
}

const std::shared_ptr<render::BrickPool>& fitPool(std::shared_ptr<render::BrickPool>& pool,
                                                  std::uint64_t& poolBytes, const Volume& volume,
                                                  std::uint64_t shareBytes) {
    if (!pool || poolOutgrown(poolBytes, shareBytes)) {
        pool.reset(); // the old texture goes before the new one is allocated
        pool = std::make_shared<render::BrickPool>(volume.store->info().volume.type,
                                                   volume.store->layout().storedEdge(),
                                                   render::BrickPoolConfig{shareBytes});
        poolBytes = shareBytes;
    }
    return pool;
}

std::uint64_t slotBytesOf(const brickstore::BrickStore& store) {
    const std::uint64_t e = store.layout().storedEdge();
    return e * e * e * brickstore::voxelBytes(store.info().volume.type);
}

std::uint32_t afterPass(SessionRenderers& session, FrameDrawing& d, double boundDb) {
    // Each pass after the first is estimated against the one before, and another follows at
    // half the step until the estimate meets the bound.
    const double gainDb =
        d.options.mode == render::BlendMode::Isosurface ? 0.0 : render::kHalvingGainDb;
    if (!d.check.empty())
        d.estimatedPsnrDb = render::estimatedPsnrDb(
            render::latticeOf(d.rgba8, d.options.width, d.options.height, d.checkStride), d.check,
            gainDb);
    else if (d.job.pass > 0 && session.lastPassIndex + 1 == d.job.pass &&
             session.lastPass.size() == d.rgba8.size())
        d.estimatedPsnrDb = render::estimatedPsnrDb(d.rgba8, session.lastPass, gainDb);
    session.lastPass = d.rgba8;
    session.lastPassIndex = d.job.pass;
    return render::refineFurther(d.estimatedPsnrDb, boundDb, d.options.stepVoxels) ? d.job.pass + 1
                                                                                   : 0;
}

RendererCache::RendererCache(const Catalog& catalog, std::uint64_t gpuBudgetBytes, Retired retired)
    : mCatalog(catalog), mGpuBudgetBytes(gpuBudgetBytes), mRetired(std::move(retired)) {}

std::uint32_t RendererCache::prune() {
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
        if (e.second.pool) mRetired(e.first->name);
        return true;
    });
    return dropped;
}

SessionRenderers& RendererCache::of(const std::shared_ptr<RenderSlot>& slot) {
    auto& s = sessions[slot.get()];
    if (s.slot.lock() != slot) { // a reused address
        s = SessionRenderers{};
        s.slot = slot;
    }
    return s;
}

bool RendererCache::drawing(const RenderSlot* slot) const {
    const auto it = sessions.find(slot);
    return it != sessions.end() && it->second.drawing && it->second.slot.lock().get() == slot;
}

std::size_t RendererCache::framesInProgress() const {
    std::size_t n = 0;
    for (const auto& [key, s] : sessions)
        n += s.drawing != nullptr;
    return n;
}

std::uint32_t RendererCache::interactiveSessions(Clock::time_point now, Clock::duration within,
                                                 const RenderSlot* except) const {
    std::uint32_t n = 0;
    // A frame still being drawn counts however long ago it started: a cold start's first
    // frames load the view's bricks for seconds, and the sessions drawing them share the
    // machine all the while.
    for (const auto& [key, other] : sessions)
        n += key != except && !other.slot.expired() &&
             ((other.lastInteractive && now - *other.lastInteractive < within) ||
              (other.drawing && !other.drawing->job.refined));
    return n;
}

RendererCache::Drawer RendererCache::rendererFor(const std::shared_ptr<RenderSlot>& slot,
                                                 const render::RendererKind& kind,
                                                 const std::shared_ptr<Volume>& volume) {
    auto& v = volumes[volume.get()];
    v.volume = volume;
    auto& mine = of(slot);
    RendererMap& owner = kind.sharedPerVolume ? v.shared : mine.own;
    auto it = owner.find(kind.name);
    if (it == owner.end()) it = owner.emplace(kind.name, kind.create()).first;
    render::Renderer& renderer = *it->second;
    render::GpuResidency* gpu = renderer.gpuResidency();
    if (!gpu) return {renderer, nullptr};
    // the volume's bricks on the GPU are shared by its sessions
    const render::BrickPool* before = v.pool.get();
    const auto& shared =
        fitPool(v.pool, v.poolBudgetBytes, *volume, mCatalog.shareOf(*volume, mGpuBudgetBytes));
    if (before && shared.get() != before) mRetired(volume->name);
    gpu->setSharedPool(shared);
    return {renderer, shared.get()};
}

} // namespace bc::server
