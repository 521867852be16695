#include "render/GpuRaycaster.h"

#include "brickstore/BrickCache.h"
#include "brickstore/BrickStore.h"
#include "render/BrickPlan.h"
#include "render/Classification.h"
#include "render/Error.h"
#include "render/FineOccupancy.h"
#include "render/Occupancy.h"
#include "render/TransferFunction.h"
#include "render/detail/Gl.h"
#include "render/detail/OcclusionFrustums.h"
#include "render/detail/RayGuide.h"
#include "render/detail/RaycastShader.h"
#include "render/detail/ShaderPrograms.h"

#include <algorithm>
#include <atomic>
#include <chrono>
#include <cstring>
#include <limits>

#include <tbb/blocked_range.h>
#include <tbb/parallel_for.h>

namespace bc::render {
namespace {

using Clock = std::chrono::steady_clock;
double msSince(Clock::time_point t) {
    return std::chrono::duration<double, std::milli>(Clock::now() - t).count();
}

/// Ray-guided frames: after this many passes that each loaded what rays asked for, every
/// deferred brick left is loaded at once (so a frame takes at most this many + 2 passes).
constexpr int kMaxRequestRounds = 6;

} // namespace

struct GpuRaycaster::Gpu {
    gl::Program program;
    gl::VertexArray vao;
    gl::Texture tf;
    gl::Buffer pages, counters;
    gl::Buffer occupancy; ///< OccupancyTrees::words() of classification occupancyId
    std::uint64_t occupancyWords = 0, occupancyId = 0;
    /// The distance maps: a copy of the FineOccupancy pool of (cellsId, cellsVoxels), the
    /// slots flagged in cellsUploaded copied; and per brick of the level its map's word offset.
    gl::Buffer cells, cellBase;
    std::uint64_t cellsId = 0, cellsVoxels = 0, cellsCapacity = 0;
    std::vector<std::uint8_t> cellsUploaded;
    std::uint64_t cellBaseBricks = 0;
    std::unique_ptr<detail::OcclusionFrustums> occlusion; ///< created on first use
    gl::Buffer feedback; ///< per brick of the level: entered, then asked for (2 uints)
    std::uint64_t feedbackBricks = 0;
    detail::RayGuide guide;
    gl::Texture accum[2];
    gl::Framebuffer fbo[2];
    gl::Texture resumeAt; ///< R32I: the sample a stopped ray goes on from, or -1
    std::uint32_t width = 0, height = 0;

    void ensureTargets(std::uint32_t w, std::uint32_t h) {
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

    void uploadTable(const TransferFunctionTable& table) {
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
};

GpuRaycaster::GpuRaycaster(const GpuRaycasterConfig& config)
    : mConfig(config), mGpu(std::make_unique<Gpu>()) {
    mGpu->program = detail::buildShaderProgram(detail::ShaderProgram::Raycast);
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
    if (mPool && mPool->type() == type && mPool->edge() == edge) {
        if (mPoolStore != &store || mPoolStorePath != store.path()) mPool->clear();
    } else {
        mPool.reset(); // free the old texture before allocating the new one
        mPool = std::make_shared<BrickPool>(type, edge, BrickPoolConfig{mConfig.gpuBudgetBytes});
    }
    mPoolStore = &store;
    mPoolStorePath = store.path();
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

namespace {

/// Uniforms that stay the same for every batch of a frame.
void setFrameUniforms(GLuint p, const LevelGeometry& g, const ViewBasis& v, const RenderOptions& o,
                      const TransferFunctionTable& table, const BrickPool& pool) {
    auto vec3 = [&](const char* name, const glm::dvec3& x) {
        glProgramUniform3f(p, glGetUniformLocation(p, name), float(x.x), float(x.y), float(x.z));
    };
    auto i1 = [&](const char* name, int x) {
        glProgramUniform1i(p, glGetUniformLocation(p, name), x);
    };
    auto f1 = [&](const char* name, double x) {
        glProgramUniform1f(p, glGetUniformLocation(p, name), float(x));
    };
    glProgramUniform2f(p, glGetUniformLocation(p, "uViewport"), float(o.width), float(o.height));
    vec3("uEye", v.eye);
    vec3("uForward", v.forward);
    vec3("uRight", v.right);
    vec3("uUp", v.upScaled);
    i1("uOrtho", v.orthographic);
    vec3("uInvSpacing", 1.0 / g.spacing);
    vec3("uDims", glm::dvec3(double(g.dims[0]), double(g.dims[1]), double(g.dims[2])));
    f1("uStepMm", o.stepVoxels * g.minSpacing());
    i1("uBrick", int(g.brickVoxels));
    i1("uApron", int(g.apronVoxels));
    i1("uEdge", int(pool.edge()));
    glProgramUniform3i(p, glGetUniformLocation(p, "uGrid"), int(g.bricks[0]), int(g.bricks[1]),
                       int(g.bricks[2]));
    const auto sg = pool.slotGrid();
    glProgramUniform3i(p, glGetUniformLocation(p, "uSlotGrid"), int(sg[0]), int(sg[1]), int(sg[2]));
    const auto ts = pool.textureSize();
    vec3("uInvPoolSize", glm::dvec3(1.0 / ts[0], 1.0 / ts[1], 1.0 / ts[2]));
    // texel t -> native v = t*scale + offset -> entry position (v - min)/(max - min) * (N - 1)
    const TexelMapping m = pool.texelMapping();
    const double span = table.domainMax - table.domainMin, n = table.entries;
    f1("uTfScale", m.scale / span * (n - 1.0));
    f1("uTfOffset", (m.offset - table.domainMin) / span * (n - 1.0));
    i1("uTfEntries", int(table.entries));
    f1("uErt", o.earlyTermination ? o.ertThreshold : 2.0);
    i1("uShading", o.shading);
    i1("uHardwareFilter", o.hardwareFilter);
    i1("uJitter", o.jitter);
    const double perVoxel = 0.5 * m.scale / span * g.minSpacing();
    vec3("uGradScale", perVoxel / g.spacing);
    f1("uGradFade", ShadingModel::kGradientFade);
    f1("uAmbient", ShadingModel::kAmbient);
    f1("uDiffuse", ShadingModel::kDiffuse);
    f1("uSpecular", ShadingModel::kSpecular);
    f1("uShininess", ShadingModel::kShininess);
    gl::glCheck("setting raycaster uniforms");
}

} // namespace

namespace {

void setOccupancyUniforms(GLuint p, const OccupancyTrees* occupancy) {
    auto i1 = [&](const char* name, int x) {
        glProgramUniform1i(p, glGetUniformLocation(p, name), x);
    };
    i1("uOctDepth", occupancy ? int(occupancy->depth()) : 0);
    i1("uOccWords", occupancy ? int(occupancy->wordsPerBrick()) : 0);
    i1("uLeafAxis", occupancy ? int(occupancy->leavesPerAxis()) : 1);
    glProgramUniform1f(p, glGetUniformLocation(p, "uLeaf"),
                       occupancy ? float(occupancy->leafVoxels()) : 1.0f);
    gl::glCheck("setting occupancy uniforms");
}

/// Unpins the pool's slots when a batch ends, also when a brick load throws mid-batch.
struct BatchPins {
    BrickPool& pool;
    ~BatchPins() { pool.unpinAll(); }
};

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

void GpuRaycaster::drawPass(int pass) {
    const GLuint program = mGpu->program.get();
    glBindFramebuffer(GL_FRAMEBUFFER, mGpu->fbo[(pass + 1) % 2].get());
    glBindTextureUnit(2, mGpu->accum[pass % 2].get());
    glProgramUniform1i(program, glGetUniformLocation(program, "uFirstPass"), pass == 0);
    glDrawArrays(GL_TRIANGLES, 0, 3);
    glMemoryBarrier(GL_TEXTURE_FETCH_BARRIER_BIT | GL_FRAMEBUFFER_BARRIER_BIT |
                    GL_SHADER_IMAGE_ACCESS_BARRIER_BIT);
    glFinish();
    gl::glCheck("raycasting a batch");
}

Image GpuRaycaster::readBack(int passes, const PixelRect& region, std::uint32_t imageHeight,
                             bool clamp, FrameStats& stats) {
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
    for (std::uint32_t y = 0; y < height; ++y) // GL rows go bottom-up
        std::transform(rows.begin() + std::ptrdiff_t((height - 1 - y) * rowFloats),
                       rows.begin() + std::ptrdiff_t((height - y) * rowFloats), image.pixel(0, y),
                       [top](float v) { return std::clamp(v, 0.0f, top); });
    return image;
}

void GpuRaycaster::bindFrame(std::size_t pageInts, std::uint64_t brickCount, bool feedback) {
    const GLuint program = mGpu->program.get();
    if (mGpu->feedbackBricks != brickCount || !mGpu->feedback) {
        mGpu->feedback = gl::createBuffer();
        glNamedBufferStorage(mGpu->feedback.get(), GLsizeiptr(2 * brickCount * 4), nullptr,
                             GL_DYNAMIC_STORAGE_BIT | GL_MAP_READ_BIT);
        mGpu->feedbackBricks = brickCount;
    }
    const std::uint32_t zeroFlag = 0;
    glClearNamedBufferData(mGpu->feedback.get(), GL_R32UI, GL_RED_INTEGER, GL_UNSIGNED_INT,
                           &zeroFlag);
    glBindBufferBase(GL_SHADER_STORAGE_BUFFER, 3, mGpu->feedback.get());
    glBindImageTexture(1, mGpu->resumeAt.get(), 0, GL_FALSE, 0, GL_READ_WRITE, GL_R32I);
    glProgramUniform1i(program, glGetUniformLocation(program, "uBrickCount"), GLint(brickCount));
    glProgramUniform1i(program, glGetUniformLocation(program, "uFeedback"), feedback);
    glProgramUniform1i(program, glGetUniformLocation(program, "uGuided"), 0);
    glProgramUniform1i(program, glGetUniformLocation(program, "uResume"), 0);
    mGpu->pages = gl::createBuffer();
    glNamedBufferStorage(mGpu->pages.get(), GLsizeiptr(pageInts * 4), nullptr,
                         GL_DYNAMIC_STORAGE_BIT);
    const std::uint32_t zero[3] = {0, 0, 0};
    glNamedBufferSubData(mGpu->counters.get(), 0, sizeof zero, zero);
    glUseProgram(mGpu->program.get());
    glBindVertexArray(mGpu->vao.get());
    glBindTextureUnit(0, mPool->texture());
    glBindTextureUnit(1, mGpu->tf.get());
    glBindBufferBase(GL_SHADER_STORAGE_BUFFER, 0, mGpu->pages.get());
    glBindBufferBase(GL_SHADER_STORAGE_BUFFER, 1, mGpu->counters.get());
    if (!mGpu->occupancy) { // the shader's binding 2 must name a buffer even when unused
        mGpu->occupancy = gl::createBuffer();
        glNamedBufferStorage(mGpu->occupancy.get(), 4, nullptr, GL_DYNAMIC_STORAGE_BIT);
        mGpu->occupancyWords = 0;
        mGpu->occupancyId = 0;
    }
    glBindBufferBase(GL_SHADER_STORAGE_BUFFER, 2, mGpu->occupancy.get());
    if (mGpu->occlusion) {
        glBindImageTexture(0, mGpu->occlusion->firstHitTexture(), 0, GL_FALSE, 0, GL_READ_WRITE,
                           GL_R32F);
        glBindTextureUnit(3, mGpu->occlusion->startTexture());
    }
    glViewport(0, 0, GLsizei(mGpu->width), GLsizei(mGpu->height));
}

void GpuRaycaster::uploadCells(const Scene& scene, const FrameClassification& classified,
                               const RenderOptions& options, const BrickPlan& plan,
                               const std::vector<std::size_t>& deferred, std::uint64_t brickCount,
                               FrameStats& stats) {
    const GLuint program = mGpu->program.get();
    const OccupancyTrees* occupancy = classified.occupancy;
    FineOccupancy* fine = occupancy && occupancy->depth() > 0 && classified.classification
                              ? classified.classification->fine(options.cellVoxels)
                              : nullptr;
    glProgramUniform1i(program, glGetUniformLocation(program, "uCells"), fine != nullptr);
    auto ensure = [](gl::Buffer& b) { // a binding must name a buffer: one word, unread
        if (b) return;
        b = gl::createBuffer();
        glNamedBufferStorage(b.get(), 4, nullptr, GL_DYNAMIC_STORAGE_BIT);
    };
    if (!fine) {
        ensure(mGpu->cells);
        ensure(mGpu->cellBase);
        glBindBufferBase(GL_SHADER_STORAGE_BUFFER, 4, mGpu->cells.get());
        glBindBufferBase(GL_SHADER_STORAGE_BUFFER, 5, mGpu->cellBase.get());
        return;
    }
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
    const FineOccupancyStats before = fine->stats();
    std::atomic<std::uint64_t> withCells{0};
    tbb::parallel_for(tbb::blocked_range<std::size_t>(0, plan.drawn.size(), 1),
                      [&](const tbb::blocked_range<std::size_t>& r) {
                          for (std::size_t i = r.begin(); i != r.end(); ++i) {
                              const PlannedBrick& b = plan.drawn[i];
                              if (b.draw != BrickDraw::Sampled || skip[i]) continue;
                              std::int64_t offset = fine->builtOffset(b.index);
                              if (offset < 0) {
                                  const brickstore::BrickPin pin = scene.cache.pin(b.key);
                                  offset = fine->offsetOf(b.index, pin.data().data(), type, brick,
                                                          apron);
                              }
                              base[b.index] = std::uint32_t(offset);
                              if (offset != 0) ++withCells;
                          }
                      });
    fine->addFrameCost(before, withCells, stats);
    // The pool's copy: made anew for other maps; the slots of this frame's bricks not copied
    // yet are, in runs of consecutive slots. Only slots whose offsets this frame was handed
    // (each written before its offset is published) are read, so a map another thread is
    // building meanwhile is never copied half done.
    const std::uint64_t id = classified.classification->occupancyId();
    const std::uint64_t words = fine->wordsPerBrick();
    if (mGpu->cellsId != id || mGpu->cellsVoxels != fine->cellVoxels() ||
        mGpu->cellsCapacity != fine->capacityWords() || !mGpu->cells) {
        mGpu->cells = gl::createBuffer();
        glNamedBufferStorage(mGpu->cells.get(), GLsizeiptr(fine->capacityWords() * 4), nullptr,
                             GL_DYNAMIC_STORAGE_BIT);
        mGpu->cellsId = id;
        mGpu->cellsVoxels = fine->cellVoxels();
        mGpu->cellsCapacity = fine->capacityWords();
        mGpu->cellsUploaded.assign(fine->capacityWords() / words, 0);
    }
    std::vector<std::uint64_t> slots;
    for (std::uint32_t offset : base)
        if (offset != 0 && !mGpu->cellsUploaded[offset / words]) {
            mGpu->cellsUploaded[offset / words] = 1;
            slots.push_back(offset / words);
        }
    std::sort(slots.begin(), slots.end());
    for (std::size_t i = 0; i < slots.size();) {
        std::size_t j = i + 1;
        while (j < slots.size() && slots[j] == slots[j - 1] + 1)
            ++j;
        glNamedBufferSubData(mGpu->cells.get(), GLintptr(slots[i] * words * 4),
                             GLsizeiptr((j - i) * words * 4), fine->pool() + slots[i] * words);
        i = j;
    }
    if (mGpu->cellBaseBricks != base.size() || !mGpu->cellBase) {
        mGpu->cellBase = gl::createBuffer();
        glNamedBufferStorage(mGpu->cellBase.get(), GLsizeiptr(base.size() * 4), nullptr,
                             GL_DYNAMIC_STORAGE_BIT);
        mGpu->cellBaseBricks = base.size();
    }
    glNamedBufferSubData(mGpu->cellBase.get(), 0, GLsizeiptr(base.size() * 4), base.data());
    glBindBufferBase(GL_SHADER_STORAGE_BUFFER, 4, mGpu->cells.get());
    glBindBufferBase(GL_SHADER_STORAGE_BUFFER, 5, mGpu->cellBase.get());
    glProgramUniform1f(program, glGetUniformLocation(program, "uCell"), float(fine->cellVoxels()));
    glProgramUniform1i(program, glGetUniformLocation(program, "uCellAxis"),
                       int(fine->cellsPerAxis()));
    gl::glCheck("uploading distance maps");
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

std::uint64_t GpuRaycaster::sceneKey(const brickstore::BrickStore& store, std::uint32_t level,
                                     const TransferFunctionTable& table,
                                     const RenderOptions& options) const {
    // What the first hits depend on: the volume, the level, which values are visible, the
    // skipping that decides "occupied", and the sample lattice.
    std::uint64_t h = 1469598103934665603ull;
    auto mix = [&](const void* data, std::size_t bytes) {
        for (std::size_t i = 0; i < bytes; ++i)
            h = (h ^ static_cast<const unsigned char*>(data)[i]) * 1099511628211ull;
    };
    const std::uint64_t instance = store.instance();
    mix(&instance, sizeof instance);
    mix(&level, sizeof level);
    for (std::uint32_t i = 0; i < table.entries; ++i) {
        const bool visible = table.rgba[4 * std::size_t(i) + 3] > 0.0f;
        mix(&visible, 1);
    }
    mix(&options.skip, sizeof options.skip);
    mix(&options.parts, sizeof options.parts); // a part's rays enter only its bricks
    mix(&options.part, sizeof options.part);
    mix(&options.octree.ratioThreshold, sizeof(double));
    mix(&options.octree.levelLimit, sizeof(std::uint32_t));
    mix(&options.stepVoxels, sizeof(double));
    return h;
}

bool GpuRaycaster::prepareOcclusion(const LevelGeometry& g, const ViewBasis& view,
                                    std::uint64_t scene, const RenderOptions& options,
                                    const OccupancyTrees* octree, FrameStats& stats) {
    if (!options.occlusionFrustums) {
        if (mGpu->occlusion) mGpu->occlusion->invalidate();
        stats.occlusionReason = "off";
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

/// The level a frame of `scene` draws at and what it classifies through (chooseLevel plans
/// with the table of the asked level: tables do not depend on the level).
struct GpuRaycaster::Prepared {
    std::uint32_t level = 0;
    FrameClassification classified;
};

GpuRaycaster::Prepared GpuRaycaster::prepare(const Scene& scene, const View& view,
                                             const RenderOptions& options, FrameStats& stats) {
    options.validate();
    checkView(view, options, true, true);
    refusePreintegration(options, "GPU raycaster");
    ensurePool(scene.store);
    Prepared p;
    const auto levels = std::uint32_t(scene.store.layout().levels().size());
    const auto asked = std::min<std::uint32_t>(std::uint32_t(options.level), levels - 1);
    if (options.interactive && options.parts == 1) { // parts: every rank draws one level
        const auto tablesOnly = scene.classifications.get(scene.store, asked, scene.tf, nullptr)
                                    ->table(options.stepVoxels);
        p.level = chooseLevel(scene.store, *tablesOnly, view.basis, options);
    } else {
        p.level = asked;
    }
    p.classified = classifyFrame(scene, p.level, options, options.stepVoxels, stats);
    uploadOccupancy(p.classified);
    return p;
}

std::uint32_t GpuRaycaster::prefetch(const Scene& scene, const View& view,
                                     const RenderOptions& options, std::uint32_t maxUploads) {
    FrameStats ignored;
    const Prepared p = prepare(scene, view, options, ignored);
    const brickstore::BrickStore& store = scene.store;
    const std::uint32_t level = p.level;
    const TransferFunctionTable& table = *p.classified.table;
    const LevelGeometry g = LevelGeometry::of(store, level);
    BrickPlan plan = planBricks(store, g, table, view.basis, options.skip, p.classified.occupancy);
    if (options.parts > 1)
        keepOwned(plan, mPartitions.get(store, level, options.parts).region(options.part));
    const std::uint64_t levelFirst = store.layout().levels()[level].firstBrick;
    const std::uint64_t sceneId = sceneKey(store, level, table, options);
    brickstore::BrickCache& cache = scene.cache;
    BatchPins pins{*mPool};
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
    BrickPlan plan = planBricks(store, g, table, view, options.region, options.skip, occupancy);
    if (options.parts > 1) // only this part's bricks: the others' samples are theirs
        keepOwned(plan, mPartitions.get(store, level, options.parts).region(options.part));
    recordPlan(plan, level, stats);

    mGpu->ensureTargets(options.width, options.height);
    mGpu->uploadTable(table);
    const std::uint64_t sceneId = sceneKey(store, level, table, options);
    const bool guided = options.rayGuided && !slice;
    const bool captures = options.occlusionFrustums && !slice;
    bool useStarts = false;
    if (slice)
        stats.occlusionReason = "a slice of a frame";
    else
        useStarts = prepareOcclusion(g, view.basis, sceneId, options, occupancy, stats);
    setFrameUniforms(mGpu->program.get(), g, view.basis, options, table, *mPool);
    setOccupancyUniforms(mGpu->program.get(), occupancy);
    const GLuint program = mGpu->program.get();
    glProgramUniform1i(program, glGetUniformLocation(program, "uUseStart"), useStarts);
    glProgramUniform1i(program, glGetUniformLocation(program, "uWriteFirstHit"), captures);
    const std::uint64_t uploadsBefore = mPool->stats().uploads,
                        bytesBefore = mPool->stats().bytesUploaded;
    const std::uint64_t levelFirst = store.layout().levels()[level].firstBrick;
    std::vector<std::int32_t> pages(2 * std::max<std::uint64_t>(g.brickCount(), 1),
                                    detail::kPageAbsent);
    bindFrame(pages.size(), g.brickCount(), guided);
    if (slice) { // GL's rows go bottom-up
        glEnable(GL_SCISSOR_TEST);
        glScissor(GLint(drawn.x), GLint(options.height - drawn.y - drawn.height),
                  GLsizei(drawn.width), GLsizei(drawn.height));
    }
    struct ScissorOff {
        bool on;
        ~ScissorOff() {
            if (on) glDisable(GL_SCISSOR_TEST);
        }
    } scissorOff{slice};
    int pass = 0;
    std::vector<std::size_t> deferred;
    if (guided) {
        // When the plan fits the pool, hidden bricks already resident are drawn as they are;
        // when it does not, every hidden brick waits to be asked for (a resident one costs no
        // upload then), so that no slot is held by a brick no ray reaches.
        const bool fits = plan.sampled <= mPool->capacity();
        deferred = mGpu->guide.deferrable(plan, sceneId, g.brickCount(), [&](std::uint64_t i) {
            return fits && mPool->resident(levelFirst + i);
        });
    }
    uploadCells(scene, p.classified, options, plan, deferred, g.brickCount(), stats);
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
    Image image = readBack(pass, drawn, options.height, options.parts == 1, stats);
    stats.readbackMs = msSince(readStart);
    if (captures) {
        const auto captureStart = Clock::now();
        mGpu->occlusion->capture(view.basis, sceneId, msSince(frameStart), useStarts,
                                 options.occlusion);
        stats.occlusionBuildMs += msSince(captureStart);
    }
    if (guided) {
        std::vector<std::uint32_t> entered(g.brickCount());
        glGetNamedBufferSubData(mGpu->feedback.get(), 0, GLsizeiptr(entered.size() * 4),
                                entered.data());
        gl::glCheck("reading ray feedback");
        for (const PlannedBrick& b : plan.drawn)
            stats.bricksEntered += b.draw == BrickDraw::Sampled && entered[b.index] != 0;
        mGpu->guide.record(plan, sceneId, entered);
    }
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
        BatchPins pins{*mPool};
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
    BrickPlan now;
    now.drawn.reserve(plan.drawn.size() - deferred.size());
    std::uint64_t sampled = 0;
    for (std::size_t i = 0, d = 0; i < plan.drawn.size(); ++i) {
        if (d < deferred.size() && deferred[d] == i) {
            ++d;
            continue;
        }
        now.drawn.push_back(plan.drawn[i]);
        sampled += plan.drawn[i].draw == BrickDraw::Sampled;
    }
    if (sampled >= mPool->capacity()) return false; // no slot would be left for a request
    const GLuint program = mGpu->program.get();
    auto uniform = [&](const char* name, bool on) {
        glProgramUniform1i(program, glGetUniformLocation(program, name), on);
    };
    BatchPins pins{*mPool};
    auto uploadStart = Clock::now();
    std::size_t next = 0;
    fillBatch(now, next, levelFirst, cache, pages);
    for (std::size_t i : deferred)
        pages[2 * plan.drawn[i].index] = detail::kPageDeferred;
    stats.bricksDeferred = deferred.size();
    const GLint none = -1;
    glClearTexImage(mGpu->resumeAt.get(), 0, GL_RED_INTEGER, GL_INT, &none);
    uniform("uGuided", true);
    std::vector<std::uint32_t> asked(mGpu->feedbackBricks);
    bool complete = true;
    for (int round = 0;; ++round) {
        glNamedBufferSubData(mGpu->pages.get(), 0, GLsizeiptr(pages.size() * 4), pages.data());
        glFinish();
        stats.uploadMs += msSince(uploadStart);
        const auto renderStart = Clock::now();
        uniform("uResume", round > 0);
        drawPass(pass++);
        stats.renderMs += msSince(renderStart);
        stats.resumePasses += round > 0;
        // What the stopped rays ask for; past the last round, every deferred brick left.
        glGetNamedBufferSubData(mGpu->feedback.get(), GLintptr(asked.size() * 4),
                                GLsizeiptr(asked.size() * 4), asked.data());
        uploadStart = Clock::now();
        std::uint64_t loaded = 0;
        for (std::size_t i : deferred) {
            const PlannedBrick& b = plan.drawn[i];
            if (pages[2 * b.index] != detail::kPageDeferred) continue;
            if (asked[b.index] == 0 && round < kMaxRequestRounds) continue;
            brickstore::BrickPin pin;
            const auto slot = mPool->acquire(levelFirst + b.index, [&] {
                pin = cache.pin(b.key);
                return pin.data();
            });
            if (!slot) {
                complete = false;
                break;
            }
            pages[2 * b.index] = std::int32_t(*slot);
            ++loaded;
        }
        if (!complete || loaded == 0) break;
        stats.bricksRequested += loaded;
        const std::uint32_t zeroFlag = 0;
        glClearNamedBufferSubData(mGpu->feedback.get(), GL_R32UI, GLintptr(asked.size() * 4),
                                  GLsizeiptr(asked.size() * 4), GL_RED_INTEGER, GL_UNSIGNED_INT,
                                  &zeroFlag);
    }
    uniform("uGuided", false);
    uniform("uResume", false);
    stats.batches = 1;
    return complete;
}

} // namespace bc::render
