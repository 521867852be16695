#include "server/Prefetch.h"

#include "render/BrickPool.h"
#include "render/Renderer.h"
#include "render/View.h"
#include "server/Catalog.h"
#include "server/RendererCache.h"

#include <algorithm>

namespace bc::server {

std::uint64_t residentBricks(const render::FrameStats& s) {
    // A sliced frame's counts of bricks are its largest slice's, its deferrals the sum of its
    // slices': the difference is a lower bound (and never below zero).
    const std::uint64_t drawn = s.bricksVisited - s.bricksConstant;
    const std::uint64_t unloaded =
        s.bricksDeferred > s.bricksRequested ? s.bricksDeferred - s.bricksRequested : 0;
    return drawn > unloaded ? drawn - unloaded : 0;
}

PrefetchStep prefetchStep(std::uint64_t lastFrameBricks, std::uint32_t capacity) {
    const std::uint64_t keep = std::min<std::uint64_t>(lastFrameBricks, capacity);
    PrefetchStep step;
    step.room = std::uint32_t(capacity - keep);
    step.bricks = std::min(step.room, kPrefetchStepBricks);
    return step;
}

std::optional<render::Camera> SessionPrefetch::afterFrame(const render::Camera& camera, bool plan) {
    mPrevious = mLast;
    mLast = camera;
    job.reset();
    if (!plan || !mPrevious) return std::nullopt;
    return render::predictNext(*mPrevious, camera);
}

void planPrefetch(SessionPrefetch& mine, const FrameDrawing& d, render::Renderer& renderer,
                  bool enabled) {
    render::GpuResidency* gpu = renderer.gpuResidency();
    if (!gpu) return;
    const auto& s = d.job.state;
    // A sliced frame's brick count is its largest slice's (a lower bound): prefetch may then
    // evict a few of the frame's bricks, which costs uploads later, never a wrong frame.
    const std::optional<render::Camera> next =
        mine.afterFrame(d.view.camera, enabled && gpu->pool() != nullptr);
    if (next)
        mine.job =
            PrefetchJob{&renderer, s.volume, s.tf, *next, d.options, residentBricks(d.stats)};
}

void runPrefetch(RendererCache& renderers, render::ClassificationCache& classifications,
                 const PrefetchReports& reports) {
    for (auto& [key, mine] : renderers.sessions) {
        if (!mine.prefetch.job) continue;
        auto job = std::move(*mine.prefetch.job);
        mine.prefetch.job.reset();
        render::GpuResidency* gpu = job.renderer ? job.renderer->gpuResidency() : nullptr;
        if (!gpu || mine.slot.expired() || !gpu->pool()) continue;
        const render::BrickPool& pool = *gpu->pool();
        const PrefetchStep step = prefetchStep(job.lastFrameBricks, pool.capacity());
        if (step.room == 0) continue;
        try {
            const std::uint64_t bytesBefore = pool.stats().bytesUploaded;
            const render::Scene scene{*job.volume->store, *job.volume->cache, *job.tf,
                                      classifications};
            // A predicted camera came from no decoder: validated here (a bad guess throws).
            const std::uint32_t n = gpu->prefetch(
                scene, render::View::of(job.camera, job.options.width, job.options.height),
                job.options, step.bricks);
            if (step.continues(n)) {      // more may be missing: continue next turn
                job.lastFrameBricks += n; // what this step brought in stays too
                mine.prefetch.job = job;
            }
            reports.uploaded(job.volume->name, n, pool.stats().bytesUploaded - bytesBefore,
                             pool.stats());
        } catch (const std::exception& e) {
            reports.failed(job.volume, e);
        }
    }
}

} // namespace bc::server
