// The GPU raycaster's residency: bricks pinned into pool slots and marked in the page table,
// bricks uploaded ahead of a frame, and the classification's octrees and distance maps copied
// to the GPU.
#include "render/GpuRaycaster.h"

#include "brickstore/BrickCache.h"
#include "brickstore/BrickStore.h"
#include "render/BrickPlan.h"
#include "render/Classification.h"
#include "render/Error.h"
#include "render/FineOccupancy.h"
#include "render/Occupancy.h"
#include "render/detail/GpuRaycastState.h"
#include "render/detail/GpuRaycastUniforms.h"
#include "render/detail/RaycastShader.h"

#include <algorithm>
#include <atomic>
#include <cmath>
#include <cstring>

#include <tbb/blocked_range.h>
#include <tbb/parallel_for.h>

namespace bc::render {
namespace {

/// The distance maps of the frame, or null: without octree leaves (or a classification) the
/// shader walks the octree alone.
FineOccupancy* frameCells(const FrameClassification& classified, const RenderOptions& options) {
    const OccupancyTrees* occupancy = classified.occupancy;
    return occupancy && occupancy->depth() > 0 && classified.classification
               ? classified.classification->fine(options.cellVoxels)
               : nullptr;
}

/// Per brick of the level (`brickCount`), the word offset of its map in fine's pool (0: none):
/// the plan's sampled bricks but `deferred` (indices into plan.drawn).
std::vector<std::uint32_t> cellOffsets(const Scene& scene, FineOccupancy& fine,
                                       const BrickPlan& plan,
                                       const std::vector<std::size_t>& deferred,
                                       std::uint64_t brickCount, FrameStats& stats) {
    // Maps of the bricks drawn now (a deferred one walks the octree: reading its voxels for a
    // map would load what ray guidance leaves unloaded), built in parallel where not yet.
    const brickstore::BrickStore& store = scene.store;
    const brickstore::VoxelType type = store.info().volume.type;
    const int brick = int(store.layout().geometry().brickVoxels);
    const int apron = int(store.layout().geometry().apronVoxels);
    std::vector<std::uint8_t> skip(plan.drawn.size(), 0);
    for (std::size_t i : deferred)
        skip[i] = 1;
    std::vector<std::uint32_t> base(std::max<std::uint64_t>(brickCount, 1), 0);
    const FineOccupancyStats before = fine.stats();
    std::atomic<std::uint64_t> withCells{0};
    auto brickOffset = [&](std::size_t i) {
        const PlannedBrick& b = plan.drawn[i];
        if (b.draw != BrickDraw::Sampled || skip[i]) return;
        std::int64_t offset = fine.builtOffset(b.index);
        if (offset < 0) {
            const brickstore::BrickPin pin = scene.cache.pin(b.key);
            offset = fine.offsetOf(b.index, pin.data().data(), type, brick, apron);
        }
        base[b.index] = std::uint32_t(offset);
        if (offset != 0) ++withCells;
    };
    tbb::parallel_for(tbb::blocked_range<std::size_t>(0, plan.drawn.size(), 1),
                      [&](const tbb::blocked_range<std::size_t>& r) {
                          for (std::size_t i = r.begin(); i != r.end(); ++i)
                              brickOffset(i);
                      });
    fine.addFrameCost(before, withCells, stats);
    return base;
}

} // namespace

std::vector<std::uint64_t> GpuRaycaster::fillBatch(const BrickPlan& plan, std::size_t& next,
                                                   std::uint64_t levelFirst,
                                                   brickstore::BrickCache& cache,
                                                   std::vector<std::int32_t>& pages) {
    const TexelMapping mapping = mPool->texelMapping();
    std::vector<std::uint64_t> batch;
    for (; next < plan.drawn.size(); ++next) {
        const PlannedBrick& b = plan.drawn[next];
        if (b.draw == BrickDraw::Constant) {
            const float texel = float((double(b.constantValue) - mapping.offset) / mapping.scale);
            pages[2 * b.index] = detail::kPageConstant;
            std::memcpy(&pages[2 * b.index + 1], &texel, 4);
            batch.push_back(b.index);
            continue;
        }
        brickstore::BrickPin pin;
        auto slot = mPool->acquire(levelFirst + b.index, [&] {
            pin = cache.pin(b.key);
            return pin.data();
        });
        if (!slot) break; // every slot holds a brick of this batch
        pages[2 * b.index] = std::int32_t(*slot);
        batch.push_back(b.index);
    }
    if (next < plan.drawn.size() && batch.empty())
        throw RenderError("GPU brick pool has no free slot for a batch");
    return batch;
}

std::uint32_t GpuRaycaster::prefetch(const Scene& scene, const View& view,
                                     const RenderOptions& options, std::uint32_t maxUploads) {
    FrameStats ignored;
    const Prepared p = prepare(scene, view, options, ignored);
    const brickstore::BrickStore& store = scene.store;
    const std::uint32_t level = p.level;
    const TransferFunctionTable& table = *p.classified.table;
    const BrickPlan plan = planFor(store, p, view, {}, options);
    const std::uint64_t levelFirst = store.layout().levels()[level].firstBrick;
    const std::uint64_t sceneId = sceneKey(store, level, table, options);
    brickstore::BrickCache& cache = scene.cache;
    detail::BatchPins pins{*mPool};
    std::uint32_t uploaded = 0;
    for (const PlannedBrick& b : plan.drawn) {
        if (uploaded >= maxUploads) break;
        if (b.draw == BrickDraw::Constant || mPool->resident(levelFirst + b.index)) continue;
        // Behind the last frame's saturated rays: the frame asks for it if it is needed.
        if (options.rayGuided && mGpu->guide.hidden(sceneId, b.index)) continue;
        brickstore::BrickPin pin;
        const auto slot = mPool->acquire(levelFirst + b.index, [&] {
            pin = cache.pin(b.key);
            return pin.data();
        });
        if (!slot) break;
        ++uploaded;
    }
    glFinish();
    return uploaded;
}

void GpuRaycaster::uploadOccupancy(const FrameClassification& classified) {
    const OccupancyTrees* occupancy = classified.occupancy;
    if (!occupancy || occupancy->depth() == 0) return; // brick roots only, no bits
    const Classification& c = *classified.classification;
    if (mGpu->occupancyId == c.occupancyId()) return; // these octrees (perhaps shared) are there
    const auto& words = occupancy->words();
    const std::uint32_t per = occupancy->wordsPerBrick();
    const auto& changed = occupancy->changedBricks();
    if (mGpu->occupancyWords != words.size()) {
        mGpu->occupancy = gl::createBuffer();
        glNamedBufferStorage(mGpu->occupancy.get(), GLsizeiptr(words.size() * 4), words.data(),
                             GL_DYNAMIC_STORAGE_BIT);
        mGpu->occupancyWords = words.size();
    } else if (mGpu->occupancyId != c.basedOn() || changed.size() * 4 > words.size() / per) {
        glNamedBufferSubData(mGpu->occupancy.get(), 0, GLsizeiptr(words.size() * 4), words.data());
    } else { // the buffer holds the words these were updated from: only the changed bricks
        for (std::uint64_t b : changed)
            glNamedBufferSubData(mGpu->occupancy.get(), GLintptr(b * per * 4), GLsizeiptr(per * 4),
                                 &words[b * per]);
    }
    gl::glCheck("uploading octree occupancy");
    mGpu->occupancyId = c.occupancyId();
}

void GpuRaycaster::uploadRunningBounds(const brickstore::BrickStore& store, std::uint32_t level,
                                       const FrameClassification& classified,
                                       const RenderOptions& options) {
    const GLuint program = mGpu->program;
    const bool running = runsSkip(options) && !options.hardwareFilter;
    detail::uniform1i(program, "uRunning", running);
    if (!running) return;
    const bool maximum = options.mode == BlendMode::Maximum;
    const OccupancyTrees* occupancy = classified.occupancy;
    const bool leaves = occupancy && occupancy->depth() > 0;
    const auto& layout = store.layout();
    const auto& l = layout.levels().at(level);
    const std::uint64_t bricks = l.brickCount(), leafCount = leaves ? layout.leafCount() : 0;
    detail::uniform1i(program, "uLeafBounds", leaves);
    const TexelMapping m = mPool->texelMapping();
    detail::KeyHash key; // what the bounds depend on
    key.mix(store.instance());
    key.mix(level);
    key.mix(maximum);
    key.mix(leafCount);
    key.mix(m.scale);
    key.mix(m.offset);
    if (mGpu->runningKey == key.h && mGpu->runningBounds) return;
    // A bound in stored units (widened for the CPU's float interpolation) to pool texels: the
    // texel a voxel becomes and the shader's interpolation of it round again, so widen by a
    // further 1e-5 of the magnitude (over 50 ulp; a 16-bit texel's unit is 1.5e-5).
    const auto texel = [&](float native) {
        if (!std::isfinite(native)) return native;
        const double t = (double(native) - m.offset) / m.scale;
        const double margin = 1e-5 * std::max(1.0, std::abs(t));
        return float(maximum ? t + margin : t - margin);
    };
    std::vector<float> bounds(std::max<std::uint64_t>(bricks * (1 + leafCount), 1));
    for (std::uint64_t b = 0; b < bricks; ++b) {
        const brickstore::ValueRange r = store.record(layout.keyOf(l.firstBrick + b)).range;
        bounds[b] = texel(interpolatedBound(maximum, r.min, r.max));
    }
    if (leaves) {
        const std::vector<float>& leaf = occupancy->leafBounds(maximum);
        for (std::uint64_t i = 0; i < bricks * leafCount; ++i)
            bounds[bricks + i] = texel(leaf[i]);
    }
    if (mGpu->runningFloats != bounds.size()) {
        mGpu->runningBounds = gl::createBuffer();
        glNamedBufferStorage(mGpu->runningBounds.get(), GLsizeiptr(bounds.size() * 4),
                             bounds.data(), GL_DYNAMIC_STORAGE_BIT);
        mGpu->runningFloats = bounds.size();
    } else {
        glNamedBufferSubData(mGpu->runningBounds.get(), 0, GLsizeiptr(bounds.size() * 4),
                             bounds.data());
    }
    gl::glCheck("uploading the running skip's bounds");
    mGpu->runningKey = key.h;
    glBindBufferBase(GL_SHADER_STORAGE_BUFFER, 6, mGpu->runningBounds.get());
}

void GpuRaycaster::uploadCells(const Scene& scene, const FrameClassification& classified,
                               const RenderOptions& options, const BrickPlan& plan,
                               const std::vector<std::size_t>& deferred, std::uint64_t brickCount,
                               FrameStats& stats) {
    const GLuint program = mGpu->program;
    FineOccupancy* fine = frameCells(classified, options);
    detail::uniform1i(program, "uCells", fine != nullptr);
    if (!fine) {
        mGpu->bindCellPlaceholders();
        return;
    }
    const std::vector<std::uint32_t> base =
        cellOffsets(scene, *fine, plan, deferred, brickCount, stats);
    mGpu->ensureCellCopy(*fine, classified.classification->occupancyId());
    mGpu->copyNewCellSlots(*fine, base);
    mGpu->uploadCellBase(base);
    glBindBufferBase(GL_SHADER_STORAGE_BUFFER, 4, mGpu->cells.get());
    glBindBufferBase(GL_SHADER_STORAGE_BUFFER, 5, mGpu->cellBase.get());
    glProgramUniform1f(program, glGetUniformLocation(program, "uCell"), float(fine->cellVoxels()));
    detail::uniform1i(program, "uCellAxis", int(fine->cellsPerAxis()));
    gl::glCheck("uploading distance maps");
}

void GpuRaycaster::Gpu::bindCellPlaceholders() {
    auto ensure = [](gl::Buffer& b) { // a binding must name a buffer: one word, unread
        if (b) return;
        b = gl::createBuffer();
        glNamedBufferStorage(b.get(), 4, nullptr, GL_DYNAMIC_STORAGE_BIT);
    };
    ensure(cells);
    ensure(cellBase);
    glBindBufferBase(GL_SHADER_STORAGE_BUFFER, 4, cells.get());
    glBindBufferBase(GL_SHADER_STORAGE_BUFFER, 5, cellBase.get());
}

// The pool's copy: made anew for other maps; the slots of this frame's bricks not copied
// yet are, in runs of consecutive slots. Only slots whose offsets this frame was handed
// (each written before its offset is published) are read, so a map another thread is
// building meanwhile is never copied half done.
void GpuRaycaster::Gpu::ensureCellCopy(const FineOccupancy& fine, std::uint64_t id) {
    if (cellsId != id || cellsVoxels != fine.cellVoxels() ||
        cellsCapacity != fine.capacityWords() || !cells) {
        cells = gl::createBuffer();
        glNamedBufferStorage(cells.get(), GLsizeiptr(fine.capacityWords() * 4), nullptr,
                             GL_DYNAMIC_STORAGE_BIT);
        cellsId = id;
        cellsVoxels = fine.cellVoxels();
        cellsCapacity = fine.capacityWords();
        cellsUploaded.assign(fine.capacityWords() / fine.wordsPerBrick(), 0);
    }
}

void GpuRaycaster::Gpu::copyNewCellSlots(const FineOccupancy& fine,
                                         const std::vector<std::uint32_t>& offsets) {
    const std::uint64_t words = fine.wordsPerBrick();
    std::vector<std::uint64_t> slots;
    for (std::uint32_t offset : offsets)
        if (offset != 0 && !cellsUploaded[offset / words]) {
            cellsUploaded[offset / words] = 1;
            slots.push_back(offset / words);
        }
    std::sort(slots.begin(), slots.end());
    for (std::size_t i = 0; i < slots.size();) {
        std::size_t j = i + 1;
        while (j < slots.size() && slots[j] == slots[j - 1] + 1)
            ++j;
        glNamedBufferSubData(cells.get(), GLintptr(slots[i] * words * 4),
                             GLsizeiptr((j - i) * words * 4), fine.pool() + slots[i] * words);
        i = j;
    }
}

void GpuRaycaster::Gpu::uploadCellBase(const std::vector<std::uint32_t>& offsets) {
    if (cellBaseBricks != offsets.size() || !cellBase) {
        cellBase = gl::createBuffer();
        glNamedBufferStorage(cellBase.get(), GLsizeiptr(offsets.size() * 4), nullptr,
                             GL_DYNAMIC_STORAGE_BIT);
        cellBaseBricks = offsets.size();
    }
    glNamedBufferSubData(cellBase.get(), 0, GLsizeiptr(offsets.size() * 4), offsets.data());
}

} // namespace bc::render
