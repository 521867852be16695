// The GPU raycaster's frame: its passes (in batches that fit the pool, or ray-guided with
// resumed rays), the pixels and counters read back, and what the frame leaves for the next
// (first hits for the occlusion frustums, the bricks its rays entered).
#include "render/GpuRaycaster.h"

#include "brickstore/BrickCache.h"
#include "brickstore/BrickStore.h"
#include "render/BrickPlan.h"
#include "render/Composite.h"
#include "render/detail/GpuRaycastState.h"
#include "render/detail/GpuRaycastUniforms.h"
#include "render/detail/RaycastShader.h"

#include <algorithm>
#include <limits>
#include <optional>

namespace bc::render {
namespace {

/// A projection's pixels as the passes leave them (texel value or sum, count, flag) in the
/// volume's units: value, or the values' sum, then the count (render/Composite.h's raw pixels).
void nativeProjections(Image& image, BlendMode mode, const TexelMapping& m) {
    for (std::size_t p = 0; p + 3 < image.rgba.size(); p += 4) {
        float* px = &image.rgba[p];
        const double count = px[1];
        px[0] = count > 0.0
                    ? float(px[0] * m.scale + (mode == BlendMode::Average ? count : 1.0) * m.offset)
                    : 0.0f;
        px[2] = px[3] = 0.0f;
    }
}

using detail::Clock;
using detail::msSince;

/// Ray-guided frames: after this many passes that each loaded what rays asked for, every
/// deferred brick left is loaded at once (so a frame takes at most this many + 2 passes).
constexpr int kMaxRequestRounds = 6;

/// A slice's scissor over the frame's passes (GL's rows go bottom-up), off again at the end.
class SliceScissor {
  public:
    SliceScissor(bool slice, const PixelRect& drawn, std::uint32_t imageHeight) : mOn(slice) {
        if (!mOn) return;
        glEnable(GL_SCISSOR_TEST);
        glScissor(GLint(drawn.x), GLint(imageHeight - drawn.y - drawn.height), GLsizei(drawn.width),
                  GLsizei(drawn.height));
    }
    ~SliceScissor() {
        if (mOn) glDisable(GL_SCISSOR_TEST);
    }
    SliceScissor(const SliceScissor&) = delete;
    SliceScissor& operator=(const SliceScissor&) = delete;

  private:
    bool mOn;
};

/// The plan's bricks the last frame of `sceneId` found hidden, to be loaded only when rays ask.
std::vector<std::size_t> deferredBricks(const detail::RayGuide& guide, const BrickPlan& plan,
                                        std::uint64_t sceneId, std::uint64_t brickCount,
                                        const BrickPool& pool, std::uint64_t levelFirst) {
    // When the plan fits the pool, hidden bricks already resident are drawn as they are;
    // when it does not, every hidden brick waits to be asked for (a resident one costs no
    // upload then), so that no slot is held by a brick no ray reaches.
    const bool fits = plan.sampled <= pool.capacity();
    return guide.deferrable(plan, sceneId, brickCount,
                            [&](std::uint64_t i) { return fits && pool.resident(levelFirst + i); });
}

/// Reads which bricks the frame's unsaturated rays entered into `stats` and the guide.
void recordEntered(GLuint feedback, detail::RayGuide& guide, const BrickPlan& plan,
                   std::uint64_t sceneId, std::uint64_t brickCount, FrameStats& stats) {
    std::vector<std::uint32_t> entered(brickCount);
    glGetNamedBufferSubData(feedback, 0, GLsizeiptr(entered.size() * 4), entered.data());
    gl::glCheck("reading ray feedback");
    for (const PlannedBrick& b : plan.drawn)
        stats.bricksEntered += b.draw == BrickDraw::Sampled && entered[b.index] != 0;
    guide.record(plan, sceneId, entered);
}

/// `plan` without its `deferred` bricks (indices into plan.drawn); `sampled` counts the sampled
/// bricks it keeps.
BrickPlan withoutDeferred(const BrickPlan& plan, const std::vector<std::size_t>& deferred,
                          std::uint64_t& sampled) {
    BrickPlan now;
    now.drawn.reserve(plan.drawn.size() - deferred.size());
    sampled = 0;
    for (std::size_t i = 0, d = 0; i < plan.drawn.size(); ++i) {
        if (d < deferred.size() && deferred[d] == i) {
            ++d;
            continue;
        }
        now.drawn.push_back(plan.drawn[i]);
        sampled += plan.drawn[i].draw == BrickDraw::Sampled;
    }
    return now;
}

/// Loads the deferred bricks still absent that rays asked for (`all`: every one left) and
/// marks their slots in `pages`. How many, or nullopt when the pool has no slot left.
std::optional<std::uint64_t>
loadRequested(BrickPool& pool, brickstore::BrickCache& cache, const BrickPlan& plan,
              const std::vector<std::size_t>& deferred, const std::vector<std::uint32_t>& asked,
              bool all, std::uint64_t levelFirst, std::vector<std::int32_t>& pages) {
    std::uint64_t loaded = 0;
    for (std::size_t i : deferred) {
        const PlannedBrick& b = plan.drawn[i];
        if (pages[2 * b.index] != detail::kPageDeferred) continue;
        if (asked[b.index] == 0 && !all) continue;
        brickstore::BrickPin pin;
        const auto slot = pool.acquire(levelFirst + b.index, [&] {
            pin = cache.pin(b.key);
            return pin.data();
        });
        if (!slot) return std::nullopt;
        pages[2 * b.index] = std::int32_t(*slot);
        ++loaded;
    }
    return loaded;
}

} // namespace

Image GpuRaycaster::render(const Scene& scene, const View& view, const RenderOptions& options,
                           FrameStats& stats) {
    const auto frameStart = Clock::now();
    stats = FrameStats{};
    const Prepared p = prepare(scene, view, options, stats);
    const brickstore::BrickStore& store = scene.store;
    brickstore::BrickCache& cache = scene.cache;
    const std::uint32_t level = p.level;
    const TransferFunctionTable& table = *p.classified.table;
    const OccupancyTrees* occupancy = p.classified.occupancy;
    const LevelGeometry g = LevelGeometry::of(store, level);
    // A slice of a frame (options.region) plans the bricks its own rays reach and draws its
    // pixels alone (a scissor on the full-size passes, so each fragment is computed as in the
    // whole frame). It neither reads nor writes what belongs to whole frames: occlusion
    // frustums and ray guidance are off for it and keep the last whole frame's findings.
    const bool slice = !options.region.whole();
    const PixelRect drawn = options.drawn();
    const BrickPlan plan = planFor(store, p, view, options.region, options);
    recordPlan(plan, level, stats);

    mGpu->ensureTargets(options.width, options.height);
    mGpu->uploadTable(table);
    const std::uint64_t sceneId = sceneKey(store, level, table, options);
    const bool guided = options.rayGuided && !slice;
    const bool captures = options.occlusionFrustums && detail::compositeUncut(options) && !slice;
    bool useStarts = false;
    if (slice)
        stats.occlusionReason = "a slice of a frame";
    else
        useStarts = prepareOcclusion(g, view.basis, sceneId, options, occupancy, stats);
    const GLuint program = mGpu->program;
    detail::setFrameUniforms(program, g, view.basis, options, table, *mPool);
    detail::setOccupancyUniforms(program, occupancy);
    detail::uniform1i(program, "uUseStart", useStarts);
    detail::uniform1i(program, "uWriteFirstHit", captures);
    const std::uint64_t uploadsBefore = mPool->stats().uploads,
                        bytesBefore = mPool->stats().bytesUploaded;
    const std::uint64_t levelFirst = store.layout().levels()[level].firstBrick;
    std::vector<std::int32_t> pages(2 * std::max<std::uint64_t>(g.brickCount(), 1),
                                    detail::kPageAbsent);
    bindFrame(pages.size(), g.brickCount(), guided);
    const SliceScissor scissor(slice, drawn, options.height);
    int pass = 0;
    std::vector<std::size_t> deferred;
    if (guided)
        deferred = deferredBricks(mGpu->guide, plan, sceneId, g.brickCount(), *mPool, levelFirst);
    uploadCells(scene, p.classified, options, plan, deferred, g.brickCount(), stats);
    uploadRunningBounds(store, level, p.classified, options);
    if (!slice) mGpu->guide.reset(); // this frame's findings replace it (none if it throws)
    if (deferred.empty() || !drawGuided(plan, deferred, levelFirst, cache, pages, pass, stats)) {
        if (!deferred.empty()) { // requests overflowed the pool: draw the frame in batches
            stats.guidedFallback = true;
            std::fill(pages.begin(), pages.end(), detail::kPageAbsent);
            bindFrame(pages.size(), g.brickCount(), guided); // counters and feedback from zero
            pass = 0;
        }
        drawBatches(plan, levelFirst, cache, pages, pass, stats);
    }

    const auto readStart = Clock::now();
    const bool projection = isProjection(options.mode);
    Image image = readBack(pass, drawn, options.height, options.parts == 1, projection, stats);
    if (projection) { // parts stay raw: they combine by their mode (render/Composite.h)
        nativeProjections(image, options.mode, mPool->texelMapping());
        if (options.parts == 1) resolveProjections(image, options.mode, table);
    }
    stats.readbackMs = msSince(readStart);
    if (captures) {
        const auto captureStart = Clock::now();
        mGpu->occlusion->capture(view.basis, sceneId, msSince(frameStart), useStarts,
                                 options.occlusion);
        stats.occlusionBuildMs += msSince(captureStart);
    }
    if (guided)
        recordEntered(mGpu->feedback.get(), mGpu->guide, plan, sceneId, g.brickCount(), stats);
    stats.bricksUploaded = mPool->stats().uploads - uploadsBefore;
    stats.bytesUploaded = mPool->stats().bytesUploaded - bytesBefore;
    stats.totalMs = msSince(frameStart);
    return image;
}

void GpuRaycaster::drawBatches(const BrickPlan& plan, std::uint64_t levelFirst,
                               brickstore::BrickCache& cache, std::vector<std::int32_t>& pages,
                               int& pass, FrameStats& stats) {
    std::size_t next = 0;
    const int first = pass;
    do { // one batch: consecutive bricks of the front-to-back order while slots last
        detail::BatchPins pins{*mPool};
        const auto uploadStart = Clock::now();
        const auto batch = fillBatch(plan, next, levelFirst, cache, pages);
        glNamedBufferSubData(mGpu->pages.get(), 0, GLsizeiptr(pages.size() * 4), pages.data());
        glFinish();
        stats.uploadMs += msSince(uploadStart);
        const auto renderStart = Clock::now();
        drawPass(pass++);
        stats.renderMs += msSince(renderStart);
        for (std::uint64_t i : batch)
            pages[2 * i] = detail::kPageAbsent;
    } while (next < plan.drawn.size());
    stats.batches = std::uint32_t(pass - first);
}

bool GpuRaycaster::drawGuided(const BrickPlan& plan, const std::vector<std::size_t>& deferred,
                              std::uint64_t levelFirst, brickstore::BrickCache& cache,
                              std::vector<std::int32_t>& pages, int& pass, FrameStats& stats) {
    // One batch of everything but the deferred bricks, or nothing (the caller draws batches).
    std::uint64_t sampled = 0;
    const BrickPlan now = withoutDeferred(plan, deferred, sampled);
    if (sampled >= mPool->capacity()) return false; // no slot would be left for a request
    const GLuint program = mGpu->program;
    detail::BatchPins pins{*mPool};
    auto uploadStart = Clock::now();
    std::size_t next = 0;
    fillBatch(now, next, levelFirst, cache, pages);
    for (std::size_t i : deferred)
        pages[2 * plan.drawn[i].index] = detail::kPageDeferred;
    stats.bricksDeferred = deferred.size();
    const GLint none = -1;
    glClearTexImage(mGpu->resumeAt.get(), 0, GL_RED_INTEGER, GL_INT, &none);
    detail::uniform1i(program, "uGuided", true);
    std::vector<std::uint32_t> asked(mGpu->feedbackBricks);
    bool complete = true;
    for (int round = 0;; ++round) {
        glNamedBufferSubData(mGpu->pages.get(), 0, GLsizeiptr(pages.size() * 4), pages.data());
        glFinish();
        stats.uploadMs += msSince(uploadStart);
        const auto renderStart = Clock::now();
        detail::uniform1i(program, "uResume", round > 0);
        drawPass(pass++);
        stats.renderMs += msSince(renderStart);
        stats.resumePasses += round > 0;
        // What the stopped rays ask for; past the last round, every deferred brick left.
        glGetNamedBufferSubData(mGpu->feedback.get(), GLintptr(asked.size() * 4),
                                GLsizeiptr(asked.size() * 4), asked.data());
        uploadStart = Clock::now();
        const std::optional<std::uint64_t> loaded = loadRequested(
            *mPool, cache, plan, deferred, asked, round >= kMaxRequestRounds, levelFirst, pages);
        complete = loaded.has_value();
        if (!complete || *loaded == 0) break;
        stats.bricksRequested += *loaded;
        mGpu->clearRequests();
    }
    detail::uniform1i(program, "uGuided", false);
    detail::uniform1i(program, "uResume", false);
    stats.batches = 1;
    return complete;
}

void GpuRaycaster::drawPass(int pass) {
    const GLuint program = mGpu->program;
    glBindFramebuffer(GL_FRAMEBUFFER, mGpu->fbo[(pass + 1) % 2].get());
    glBindTextureUnit(2, mGpu->accum[pass % 2].get());
    detail::uniform1i(program, "uFirstPass", pass == 0);
    glDrawArrays(GL_TRIANGLES, 0, 3);
    glMemoryBarrier(GL_TEXTURE_FETCH_BARRIER_BIT | GL_FRAMEBUFFER_BARRIER_BIT |
                    GL_SHADER_IMAGE_ACCESS_BARRIER_BIT);
    glFinish();
    gl::glCheck("raycasting a batch");
}

Image GpuRaycaster::readBack(int passes, const PixelRect& region, std::uint32_t imageHeight,
                             bool clamp, bool raw, FrameStats& stats) {
    const std::uint32_t width = region.width, height = region.height;
    Image image(width, height);
    std::vector<float> rows(std::size_t(width) * height * 4);
    glBindFramebuffer(GL_FRAMEBUFFER, mGpu->fbo[passes % 2].get());
    glReadPixels(GLint(region.x), GLint(imageHeight - region.y - height), GLsizei(width),
                 GLsizei(height), GL_RGBA, GL_FLOAT, rows.data());
    std::uint32_t counted[3] = {0, 0, 0};
    glGetNamedBufferSubData(mGpu->counters.get(), 0, sizeof counted, counted);
    gl::glCheck("reading the frame back");
    stats.samples = counted[0];
    stats.octreeLeaps = counted[1];
    stats.samplesSavedByStart = counted[2];
    const std::size_t rowFloats = std::size_t(width) * 4;
    // A part's segments are not clamped above: the compositing clamps (render/SCALEOUT.md).
    const float top = clamp ? 1.0f : std::numeric_limits<float>::max();
    const float bottom = raw ? std::numeric_limits<float>::lowest() : 0.0f;
    for (std::uint32_t y = 0; y < height; ++y) // GL rows go bottom-up
        std::transform(rows.begin() + std::ptrdiff_t((height - 1 - y) * rowFloats),
                       rows.begin() + std::ptrdiff_t((height - y) * rowFloats), image.pixel(0, y),
                       [=](float v) { return raw ? v : std::clamp(v, bottom, top); });
    return image;
}

void GpuRaycaster::bindFrame(std::size_t pageInts, std::uint64_t brickCount, bool feedback) {
    const GLuint program = mGpu->program;
    mGpu->resetFeedback(brickCount);
    glBindImageTexture(1, mGpu->resumeAt.get(), 0, GL_FALSE, 0, GL_READ_WRITE, GL_R32I);
    detail::uniform1i(program, "uBrickCount", GLint(brickCount));
    detail::uniform1i(program, "uFeedback", feedback);
    detail::uniform1i(program, "uGuided", 0);
    detail::uniform1i(program, "uResume", 0);
    mGpu->pages = gl::createBuffer();
    glNamedBufferStorage(mGpu->pages.get(), GLsizeiptr(pageInts * 4), nullptr,
                         GL_DYNAMIC_STORAGE_BIT);
    const std::uint32_t zero[3] = {0, 0, 0};
    glNamedBufferSubData(mGpu->counters.get(), 0, sizeof zero, zero);
    mGpu->bindForDraw(mPool->texture());
}

void GpuRaycaster::Gpu::resetFeedback(std::uint64_t brickCount) {
    if (feedbackBricks != brickCount || !feedback) {
        feedback = gl::createBuffer();
        glNamedBufferStorage(feedback.get(), GLsizeiptr(2 * brickCount * 4), nullptr,
                             GL_DYNAMIC_STORAGE_BIT | GL_MAP_READ_BIT);
        feedbackBricks = brickCount;
    }
    const std::uint32_t zeroFlag = 0;
    glClearNamedBufferData(feedback.get(), GL_R32UI, GL_RED_INTEGER, GL_UNSIGNED_INT, &zeroFlag);
    glBindBufferBase(GL_SHADER_STORAGE_BUFFER, 3, feedback.get());
}

void GpuRaycaster::Gpu::clearRequests() {
    const std::uint32_t zeroFlag = 0;
    glClearNamedBufferSubData(feedback.get(), GL_R32UI, GLintptr(feedbackBricks * 4),
                              GLsizeiptr(feedbackBricks * 4), GL_RED_INTEGER, GL_UNSIGNED_INT,
                              &zeroFlag);
}

void GpuRaycaster::Gpu::bindForDraw(GLuint poolTexture) {
    glUseProgram(program);
    glBindVertexArray(vao.get());
    glBindTextureUnit(0, poolTexture);
    glBindTextureUnit(1, tf.get());
    glBindBufferBase(GL_SHADER_STORAGE_BUFFER, 0, pages.get());
    glBindBufferBase(GL_SHADER_STORAGE_BUFFER, 1, counters.get());
    if (!occupancy) { // the shader's binding 2 must name a buffer even when unused
        occupancy = gl::createBuffer();
        glNamedBufferStorage(occupancy.get(), 4, nullptr, GL_DYNAMIC_STORAGE_BIT);
        occupancyWords = 0;
        occupancyId = 0;
    }
    glBindBufferBase(GL_SHADER_STORAGE_BUFFER, 2, occupancy.get());
    if (!runningBounds) { // binding 6 too (the running skip's bounds)
        runningBounds = gl::createBuffer();
        glNamedBufferStorage(runningBounds.get(), 4, nullptr, GL_DYNAMIC_STORAGE_BIT);
        runningFloats = 1;
        runningKey = 0;
    }
    glBindBufferBase(GL_SHADER_STORAGE_BUFFER, 6, runningBounds.get());
    if (occlusion) {
        glBindImageTexture(0, occlusion->firstHitTexture(), 0, GL_FALSE, 0, GL_READ_WRITE, GL_R32F);
        glBindTextureUnit(3, occlusion->startTexture());
    }
    glViewport(0, 0, GLsizei(width), GLsizei(height));
}

} // namespace bc::render
