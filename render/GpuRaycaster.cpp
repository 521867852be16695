// The GPU raycaster's setup: its program, render targets and pool; what readies a frame (its
// level, classification and occlusion frustums). The frame's residency is in
// GpuRaycasterResidency.cpp, its passes in GpuRaycasterDraw.cpp.
#include "render/GpuRaycaster.h"

#include "brickstore/BrickStore.h"
#include "render/BrickPlan.h"
#include "render/Classification.h"
#include "render/Error.h"
#include "render/Occupancy.h"
#include "render/TransferFunction.h"
#include "render/detail/GpuRaycastState.h"
#include "render/detail/ShaderPrograms.h"

#include <algorithm>

namespace bc::render {

void GpuRaycaster::Gpu::ensureTargets(std::uint32_t w, std::uint32_t h) {
    if (w == width && h == height) return;
    for (int i = 0; i < 2; ++i) {
        accum[i] = gl::createTexture(GL_TEXTURE_2D);
        glTextureStorage2D(accum[i].get(), 1, GL_RGBA32F, GLsizei(w), GLsizei(h));
        glTextureParameteri(accum[i].get(), GL_TEXTURE_MIN_FILTER, GL_NEAREST);
        glTextureParameteri(accum[i].get(), GL_TEXTURE_MAG_FILTER, GL_NEAREST);
        GLuint f = 0;
        glCreateFramebuffers(1, &f);
        fbo[i] = gl::Framebuffer(f);
        glNamedFramebufferTexture(f, GL_COLOR_ATTACHMENT0, accum[i].get(), 0);
        if (glCheckNamedFramebufferStatus(f, GL_FRAMEBUFFER) != GL_FRAMEBUFFER_COMPLETE)
            throw RenderError("raycaster render target " + std::to_string(w) + "x" +
                              std::to_string(h) + " is incomplete");
    }
    resumeAt = gl::createTexture(GL_TEXTURE_2D);
    glTextureStorage2D(resumeAt.get(), 1, GL_R32I, GLsizei(w), GLsizei(h));
    width = w;
    height = h;
    gl::glCheck("allocating raycaster render targets");
}

void GpuRaycaster::Gpu::uploadTable(const TransferFunctionTable& table) {
    if (!tf) {
        tf = gl::createTexture(GL_TEXTURE_1D);
        glTextureStorage1D(tf.get(), 1, GL_RGBA32F, GLsizei(kClassificationTableEntries));
        glTextureParameteri(tf.get(), GL_TEXTURE_MIN_FILTER, GL_LINEAR);
        glTextureParameteri(tf.get(), GL_TEXTURE_MAG_FILTER, GL_LINEAR);
        glTextureParameteri(tf.get(), GL_TEXTURE_WRAP_S, GL_CLAMP_TO_EDGE);
    }
    glTextureSubImage1D(tf.get(), 0, 0, GLsizei(table.entries), GL_RGBA, GL_FLOAT,
                        table.rgba.data());
    gl::glCheck("uploading the transfer function");
}

GpuRaycaster::GpuRaycaster(const GpuRaycasterConfig& config)
    : mConfig(config), mGpu(std::make_unique<Gpu>()) {
    mGpu->plainProgram = detail::buildShaderProgram(detail::ShaderProgram::Raycast);
    mGpu->modesProgram = detail::buildShaderProgram(detail::ShaderProgram::RaycastModes);
    mGpu->program = mGpu->plainProgram.get();
    GLuint vao = 0;
    glCreateVertexArrays(1, &vao);
    mGpu->vao = gl::VertexArray(vao);
    mGpu->pages = gl::createBuffer();
    mGpu->counters = gl::createBuffer();
    glNamedBufferStorage(mGpu->counters.get(), 3 * sizeof(std::uint32_t), nullptr,
                         GL_DYNAMIC_STORAGE_BIT | GL_MAP_READ_BIT);
    gl::glCheck("creating the raycaster");
}

GpuRaycaster::~GpuRaycaster() = default;

void GpuRaycaster::setGpuBudgetBytes(std::uint64_t budgetBytes) {
    if (budgetBytes == mConfig.gpuBudgetBytes) return;
    mConfig.gpuBudgetBytes = budgetBytes;
    mPool.reset();
}

void GpuRaycaster::setSharedPool(std::shared_ptr<BrickPool> pool) {
    if (pool == mSharedPool) return;
    mSharedPool = std::move(pool);
    mPool.reset();
}

void GpuRaycaster::ensurePool(const brickstore::BrickStore& store) {
    const auto type = store.info().volume.type;
    const std::uint32_t edge = store.layout().storedEdge();
    if (mSharedPool) {
        if (mSharedPool->type() != type || mSharedPool->edge() != edge)
            throw RenderError("shared brick pool holds " + std::to_string(mSharedPool->edge()) +
                              "^3 slots of another type than " + store.path() + " needs");
        mPool = mSharedPool;
        mPoolStore = &store;
        mPoolStorePath = store.path();
        return;
    }
    // Every brick of every level and one spare slot (a ray-guided frame keeps one free for a
    // request) at most: a pool sized by the budget alone is cleared whole for a store a
    // fraction of its size.
    std::uint64_t bricks = 1;
    for (const auto& level : store.layout().levels())
        bricks += level.brickCount();
    const std::uint64_t bytes = BrickPool::bytesFor(bricks, type, edge, mConfig.gpuBudgetBytes);
    if (mPool && mPool->type() == type && mPool->edge() == edge && mPoolBytes == bytes) {
        if (mPoolStore != &store || mPoolStorePath != store.path()) mPool->clear();
    } else {
        mPool.reset(); // free the old texture before allocating the new one
        mPool = std::make_shared<BrickPool>(type, edge, BrickPoolConfig{bytes});
        mPoolBytes = bytes;
    }
    mPoolStore = &store;
    mPoolStorePath = store.path();
}

BrickPlan GpuRaycaster::planFor(const brickstore::BrickStore& store, const Prepared& p,
                                const View& view, const PixelRect& region,
                                const RenderOptions& options) {
    const LevelGeometry g = LevelGeometry::of(store, p.level);
    BrickPlan plan = planBricks(store, g, *p.classified.skipTable, view, region, options.skip,
                                p.classified.occupancy);
    if (options.parts > 1) // only this part's bricks: the others' samples are theirs
        keepOwned(plan, mPartitions.get(store, p.level, options.parts).region(options.part));
    if (options.clip.any()) keepInside(plan, g, options.clip); // neither uploaded nor drawn
    return plan;
}

std::uint32_t GpuRaycaster::chooseLevel(const brickstore::BrickStore& store,
                                        const TransferFunctionTable& table, const ViewBasis& view,
                                        const RenderOptions& options) {
    const auto levels = std::uint32_t(store.layout().levels().size());
    std::uint32_t level = std::min<std::uint32_t>(std::uint32_t(options.level), levels - 1);
    if (!options.interactive) return level;
    for (; level + 1 < levels; ++level) {
        const BrickPlan plan =
            planBricks(store, LevelGeometry::of(store, level), table, view, options.skip);
        if (plan.sampled <= mPool->capacity()) break;
    }
    return level;
}

GpuRaycaster::Prepared GpuRaycaster::prepare(const Scene& scene, const View& view,
                                             const RenderOptions& options, FrameStats& stats) {
    options.validate();
    checkView(view, options, true, true);
    refusePreintegration(options, "GPU raycaster");
    mGpu->program =
        detail::compositeUncut(options) ? mGpu->plainProgram.get() : mGpu->modesProgram.get();
    ensurePool(scene.store);
    Prepared p;
    const auto levels = std::uint32_t(scene.store.layout().levels().size());
    const auto asked = std::min<std::uint32_t>(std::uint32_t(options.level), levels - 1);
    if (options.interactive && options.parts == 1) { // parts: every rank draws one level
        const auto tablesOnly = scene.classifications.get(scene.store, asked, scene.tf, nullptr,
                                                          nullptr, SkipRule::of(options));
        p.level = chooseLevel(scene.store, *tablesOnly->skipTable(), view.basis, options);
    } else {
        p.level = asked;
    }
    p.classified = classifyFrame(scene, p.level, options, options.stepVoxels, stats);
    uploadOccupancy(p.classified);
    return p;
}

std::uint64_t GpuRaycaster::sceneKey(const brickstore::BrickStore& store, std::uint32_t level,
                                     const TransferFunctionTable& table,
                                     const RenderOptions& options) const {
    // What the first hits depend on: the volume, the level, which values are visible, the
    // skipping that decides "occupied", and the sample lattice.
    detail::KeyHash key;
    key.mix(store.instance());
    key.mix(level);
    for (std::uint32_t i = 0; i < table.entries; ++i)
        key.mix(table.rgba[4 * std::size_t(i) + 3] > 0.0f); // visible
    key.mix(options.skip);
    key.mix(options.parts); // a part's rays enter only its bricks
    key.mix(options.part);
    key.mix(options.octree.ratioThreshold);
    key.mix(options.octree.levelLimit);
    key.mix(options.stepVoxels);
    // What a ray samples and where it stops: its mode, and what the clip leaves.
    key.mix(options.mode);
    key.mix(options.isoValue);
    key.mix(options.clip.cropped);
    key.mix(options.clip.cropMin);
    key.mix(options.clip.cropMax);
    key.mix(options.clip.planeCount);
    for (std::uint32_t i = 0; i < options.clip.planeCount; ++i) {
        key.mix(options.clip.planes[i].normal);
        key.mix(options.clip.planes[i].offset);
    }
    return key.h;
}

bool GpuRaycaster::prepareOcclusion(const LevelGeometry& g, const ViewBasis& view,
                                    std::uint64_t scene, const RenderOptions& options,
                                    const OccupancyTrees* octree, FrameStats& stats) {
    if (!options.occlusionFrustums || !detail::compositeUncut(options)) {
        if (mGpu->occlusion) mGpu->occlusion->invalidate();
        stats.occlusionReason = options.occlusionFrustums ? "composite, uncut frames only" : "off";
        return false;
    }
    if (!mGpu->occlusion) mGpu->occlusion = std::make_unique<detail::OcclusionFrustums>();
    const double voxels = options.skip == SkipMode::None ? 0.0
                          : octree                       ? double(octree->leafVoxels())
                                                         : double(g.brickVoxels);
    const double cellMm = voxels * std::min({g.spacing.x, g.spacing.y, g.spacing.z});
    bool used = false;
    if (options.skip == SkipMode::None) {
        stats.occlusionReason = "no occupancy to find first hits with (skip none)";
    } else {
        used =
            mGpu->occlusion->prepare(view, options.width, options.height, g.box, scene, cellMm,
                                     options.stepVoxels * g.minSpacing(), options.occlusion, stats);
    }
    mGpu->occlusion->beginFrame(options.width, options.height);
    return used;
}

} // namespace bc::render
