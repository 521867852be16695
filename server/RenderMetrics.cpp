#include "server/RenderMetrics.h"

#include "render/RendererRegistry.h"
#include "server/FrameCluster.h"

namespace bc::server {

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

} // namespace

void RenderCounters::recordFrame(const FrameRecord& f, double bytes, const std::string& volume,
                                 const render::BrickPool* pool) {
    RenderCounters& c = *this;
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

void RenderCounters::recordCached(const protocol::FrameHeader& h, double bytes, double latencyMs) {
    RenderCounters& c = *this;
    c.encodeMs += h.encodeMs;
    c.bytes += bytes;
    c.latencyMs.observe(latencyMs);
    c.encodeMsHist.observe(h.encodeMs);
    c.frameBytes.observe(bytes);
}

void RenderCounters::retirePool(const std::string& volume) {
    RenderCounters& c = *this;
    if (auto it = c.poolLive.find(volume); it != c.poolLive.end()) {
        c.poolRetired[volume] += it->second;
        c.poolLive.erase(it);
    }
}

void RenderCounters::exportTo(MetricSet& m, const RenderMetricsContext& context) const {
    const RenderCounters& c = *this;
    for (const std::string& r : render::RendererRegistry::builtin().names()) {
        const auto it = c.frames.find(r);
        m.counter("frames_total", "Frames drawn and encoded, by renderer",
                  it == c.frames.end() ? 0.0 : it->second, {{"renderer", r}});
    }
    m.counter("frames_refined_total", "Full-quality frames after the camera came to rest",
              c.refined);
    m.counter("render_errors_total", "Frames that failed (sent as RenderFailed)", c.errors);
    m.counter("frames_refused_total",
              "Frames over the cost cap (frames.max_frame_gsamples), answered OutOfRange",
              c.refused);
    m.counter("frames_cancelled_total",
              "Frames dropped before they were complete: their session had gone or asked for "
              "something newer",
              c.cancelled);
    m.counter("frame_slices_total", "Slices drawn of frames too long to draw in one turn",
              c.slices);
    m.counter("refinement_checks_total",
              "First refinement passes at rest checked against a sparse frame at twice their step",
              c.checks);
    m.counter("render_ms_total", "Milliseconds spent drawing frames", c.renderMs);
    m.counter("encode_ms_total", "Milliseconds spent encoding frames", c.encodeMs);
    m.counter("frame_bytes_total", "Encoded frame message bytes", c.bytes);
    m.counter("samples_total", "Volume samples (voxels for the splatter) taken", c.samples);
    if (context.cluster) {
        m.gauge("cluster_ranks", "MPI ranks drawing the raycasters' frames",
                double(context.cluster->ranks()));
        m.counter("cluster_slices_total", "Frames or slices drawn across the ranks",
                  c.clusterSlices);
        m.counter("cluster_failures_total",
                  "Cluster frames failed because a rank did not answer (the cluster is then out "
                  "of service)",
                  c.clusterFailures);
        m.counter("cluster_composited_bytes_total",
                  "Bytes the ranks sent each other compositing (pieces and bands)", c.clusterBytes);
        m.histogram("cluster_composite_ms", "Sort-last compositing per slice, at rank 0",
                    c.clusterCompositeMs);
        m.histogram("cluster_imbalance", "Per slice: the slowest rank's render ms over the mean",
                    c.clusterImbalance);
        m.gauge("cluster_imbalance_last", "The last slice's slowest rank's render ms over the mean",
                c.lastImbalance);
        for (std::size_t r = 0; r < c.rankRenderMs.size(); ++r) {
            m.counter("cluster_rank_render_ms_total", "Milliseconds each rank spent on its parts",
                      c.rankRenderMs[r], {{"rank", std::to_string(r)}});
            m.counter("cluster_rank_samples_total", "Samples each rank took of its parts",
                      c.rankSamples[r], {{"rank", std::to_string(r)}});
        }
    }
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
    const FrameCacheStats& fc = context.frameCache;
    m.counter("frame_cache_hits_total",
              "Frames answered from the frame cache: drawn before for an identical request",
              double(fc.hits));
    m.counter("frame_cache_misses_total", "Frames looked up in the frame cache and drawn",
              double(fc.misses));
    m.counter("frame_cache_evictions_total", "Frames the frame cache dropped for its budget (LRU)",
              double(fc.evictions));
    m.counter("frame_cache_dropped_total",
              "Frames the frame cache dropped because their volume was reopened, removed or "
              "taken out of service",
              double(fc.dropped));
    m.counter("frame_cache_too_large_total",
              "Frames not kept: over a quarter of the frame cache's budget", double(fc.tooLarge));
    m.gauge("frame_cache_bytes", "Bytes of frames the frame cache holds", double(fc.bytes));
    m.gauge("frame_cache_entries", "Frames the frame cache holds", double(fc.entries));
    m.gauge("frame_cache_budget_bytes", "The frame cache's budget (frames.cache_mb; 0: off)",
            double(fc.budgetBytes));
    const render::ClassificationStats& cs = context.classifications;
    m.counter("classification_builds_total",
              "Transfer functions committed for a store and level: octrees built or brought up "
              "to date, once per key however many sessions ask",
              double(cs.builds));
    m.counter("classification_shared_total",
              "Of those, classifications that took the octrees and distance maps of one with the "
              "same visible values (an edit of colours or non-zero opacities): nothing rebuilt",
              double(cs.shared));
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
    m.gauge("render_slots_waiting", "Sessions with a frame due and not yet drawn",
            double(context.slotsWaiting));
    m.gauge("render_frames_in_progress", "Frames drawn in slices, begun and not finished",
            double(context.framesInProgress));
    m.gauge("render_idle",
            "1 while the render thread has nothing to do: no frame in progress and none owed to "
            "any session, now or when its camera rests",
            context.idle ? 1.0 : 0.0);
    m.gauge("gpu_context",
            "The render thread's OpenGL context: 0 not made (no GPU frame asked for yet), 1 "
            "made, -1 unavailable (GPU frames are refused)",
            context.gpuUnavailable ? -1.0 : c.gpuContext);
    if (context.autoChoice)
        m.gauge("auto_renderer",
                "1 for the renderer the sessions asking for auto draw with, and why (decided at "
                "the first such frame, from the OpenGL context: GL_RENDERER, GL_VENDOR)",
                1.0,
                {{"renderer", context.autoChoice->name}, {"reason", context.autoChoice->reason}});
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

} // namespace bc::server
