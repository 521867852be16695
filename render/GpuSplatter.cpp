#include "render/GpuSplatter.h"

#include "brickstore/BrickCache.h"
#include "brickstore/BrickStore.h"
#include "render/BrickPlan.h"
#include "render/Error.h"
#include "render/Occupancy.h"
#include "render/SplatGeometry.h"
#include "render/TransferFunction.h"
#include "render/detail/Gl.h"
#include "render/detail/ShaderPrograms.h"
#include "render/detail/SplatPrep.h"

#include <algorithm>
#include <chrono>
#include <cmath>

namespace bc::render {
namespace {

using detail::Frame;
using detail::PointFilter;
using detail::PreparedBrick;
using detail::Visible;
using detail::VoxelDraw;

using Clock = std::chrono::steady_clock;
double msSince(Clock::time_point t) {
    return std::chrono::duration<double, std::milli>(Clock::now() - t).count();
}

/// One primitive of the frame's vertex buffer: three vec4 instance attributes.
struct Primitive {
    float rect[4];   ///< first and last pixel column and row, inclusive (row 0 at the top)
    float colour[4]; ///< straight colour; w: k = lnT * depthScale (splat) or cover scale (point)
    /// splat: centre - eye (mm), half angle (rad; the shader needs only the centre);
    /// point: filter centre (pixels), 1 / filter radius, 1 for all to the nearest pixel.
    float shape[4];
};
static_assert(sizeof(Primitive) == 12 * sizeof(float));

/// Consecutive primitives of one kind: a run of splats, or the points of one slab.
struct Batch {
    bool points = false;
    std::uint32_t first = 0, count = 0;
    std::uint32_t box[4] = {0, 0, 0, 0}; ///< pixels the batch touches (columns, rows; inclusive)
};

/// The frame as primitives: the CPU splatter's decisions (ChunkDrawer,
/// render/detail/HybridSplatDrawer.h), recorded in order instead of drawn. Slabs are cut as in the
/// whole image; only primitives that meet `region` (the pixels drawn) are kept.
class PrimitiveList {
  public:
    PrimitiveList(const Frame& f, const SplatFootprint& fp, std::uint32_t w, std::uint32_t h,
                  const PixelRect& region, HybridSplatStats& n)
        : mF(f), mFp(fp), mW(w), mH(h), mRegion(region), mN(n) {}

    std::vector<Primitive> primitives;
    std::vector<Batch> batches;

    /// Records one classified voxel (straight colour c, opacity a per unit step) at `depth`.
    void draw(const glm::dvec3& centre, double depth, const float* c, float a) {
        const VoxelDraw d = detail::classifyDraw(mF, centre, a);
        if (d.kind == VoxelDraw::Kind::Point)
            point(d, depth, c);
        else if (d.kind == VoxelDraw::Kind::Splat)
            splat(centre, c, d.lnT);
    }
    /// Ends the open slab, if any: its points become one batch.
    void flushSlab() {
        if (!mSlabOpen) return;
        mSlabOpen = false;
        mBatchClosed = true;
        ++mN.slabs;
    }

  private:
    void point(const VoxelDraw& d, double depth, const float* c) {
        const double R = mF.pointFilter;
        std::uint32_t r[4];
        if (!detail::pixelRect(d.image - R, d.image + R, mW, mH, r)) return;
        if (mSlabOpen && depth > mSlabEnd) flushSlab();
        if (!mSlabOpen) {
            mSlabOpen = true;
            mSlabEnd = depth + mF.slabMm;
        }
        if (!detail::meetsRegion(r, mRegion)) return;
        ++mN.points;
        const PointFilter pf = detail::pointFilterOf(mF, mFp, d, mW, mH);
        Primitive p{{}, {c[0], c[1], c[2], 0.0f}, {float(pf.fx), float(pf.fy), float(1.0 / R), 0}};
        if (pf.sum > 0.0) {
            p.colour[3] = float(pf.total / pf.sum);
        } else { // no pixel centre under the filter: all of it to the nearest pixel
            const long nx = std::lround(pf.fx), ny = std::lround(pf.fy);
            if (!(nx >= 0 && ny >= 0 && nx < long(mW) && ny < long(mH))) return;
            r[0] = r[2] = std::uint32_t(nx);
            r[1] = r[3] = std::uint32_t(ny);
            if (!detail::meetsRegion(r, mRegion)) return;
            p.colour[3] = float(pf.total);
            p.shape[3] = 1.0f;
        }
        push(p, true, r);
    }

    void splat(const glm::dvec3& centre, const float* c, double lnT) {
        const SplatProjection proj = projectSphere(mF.view, centre, mF.radiusMm);
        if (!proj.ok()) return;
        const SplatEllipse& e = proj.ellipse;
        const glm::dvec2 half = e.halfExtent();
        std::uint32_t r[4];
        if (!detail::pixelRect(e.centre - half, e.centre + half, mW, mH, r)) return;
        flushSlab(); // points in front go first
        if (!detail::meetsRegion(r, mRegion)) return;
        ++mN.splats;
        const glm::dvec3 rel = centre - mF.view.eye;
        push({{},
              {c[0], c[1], c[2], float(lnT * mF.depthScale)},
              {float(rel.x), float(rel.y), float(rel.z), float(e.halfAngleRad)}},
             false, r);
    }

    void push(Primitive p, bool points, const std::uint32_t r[4]) {
        for (int i = 0; i < 4; ++i)
            p.rect[i] = float(r[i]);
        if (batches.empty() || mBatchClosed || batches.back().points != points) {
            batches.push_back(
                {points, std::uint32_t(primitives.size()), 0, {r[0], r[1], r[2], r[3]}});
            mBatchClosed = false;
        }
        Batch& b = batches.back();
        ++b.count;
        b.box[0] = std::min(b.box[0], r[0]);
        b.box[1] = std::min(b.box[1], r[1]);
        b.box[2] = std::max(b.box[2], r[2]);
        b.box[3] = std::max(b.box[3], r[3]);
        primitives.push_back(p);
    }

    const Frame& mF;
    const SplatFootprint& mFp;
    std::uint32_t mW, mH;
    PixelRect mRegion;
    HybridSplatStats& mN;
    bool mSlabOpen = false, mBatchClosed = true;
    double mSlabEnd = 0.0;
};

gl::Texture floatTarget(std::uint32_t w, std::uint32_t h, gl::Framebuffer& fbo) {
    gl::Texture t = gl::createTexture(GL_TEXTURE_2D);
    glTextureStorage2D(t.get(), 1, GL_RGBA32F, GLsizei(w), GLsizei(h));
    glTextureParameteri(t.get(), GL_TEXTURE_MIN_FILTER, GL_NEAREST);
    glTextureParameteri(t.get(), GL_TEXTURE_MAG_FILTER, GL_NEAREST);
    GLuint f = 0;
    glCreateFramebuffers(1, &f);
    fbo = gl::Framebuffer(f);
    glNamedFramebufferTexture(f, GL_COLOR_ATTACHMENT0, t.get(), 0);
    if (glCheckNamedFramebufferStatus(f, GL_FRAMEBUFFER) != GL_FRAMEBUFFER_COMPLETE)
        throw RenderError("splatter render target " + std::to_string(w) + "x" + std::to_string(h) +
                          " is incomplete");
    return t;
}

/// Restricts drawing and clearing to the pixel rectangle r (first and last column and row; window
/// row = image row) within `region`; false when they do not meet.
bool scissor(const std::uint32_t r[4], const PixelRect& region) {
    const std::uint32_t x0 = std::max(r[0], region.x), y0 = std::max(r[1], region.y);
    const std::uint32_t x1 = std::min(r[2], region.x + region.width - 1),
                        y1 = std::min(r[3], region.y + region.height - 1);
    if (x0 > x1 || y0 > y1) return false;
    glScissor(GLint(x0), GLint(y0), GLsizei(x1 - x0 + 1), GLsizei(y1 - y0 + 1));
    return true;
}

/// dst += (1 - dst.a) * src, src premultiplied: front-to-back 'over'.
void blendFrontToBack() {
    glBlendFuncSeparate(GL_ONE_MINUS_DST_ALPHA, GL_ONE, GL_ONE_MINUS_DST_ALPHA, GL_ONE);
}

} // namespace

struct GpuSplatter::Gpu {
    gl::Program splat, point, composite;
    gl::VertexArray quads, empty;
    gl::Buffer primitives;
    std::size_t primitiveBytes = 0; ///< capacity of `primitives`
    gl::Texture footprint;
    gl::Texture colour, slab;
    gl::Framebuffer colourFbo, slabFbo;
    std::uint32_t width = 0, height = 0;

    void ensureTargets(std::uint32_t w, std::uint32_t h) {
        if (w == width && h == height) return;
        colour = floatTarget(w, h, colourFbo);
        slab = floatTarget(w, h, slabFbo);
        width = w;
        height = h;
        gl::glCheck("allocating splatter render targets");
    }

    void upload(const std::vector<Primitive>& list) {
        const std::size_t bytes = list.size() * sizeof(Primitive);
        if (bytes > primitiveBytes) {
            primitiveBytes = std::max(bytes, 2 * primitiveBytes);
            primitives = gl::createBuffer();
            glNamedBufferStorage(primitives.get(), GLsizeiptr(primitiveBytes), nullptr,
                                 GL_DYNAMIC_STORAGE_BIT);
            glVertexArrayVertexBuffer(quads.get(), 0, primitives.get(), 0, sizeof(Primitive));
        }
        if (bytes > 0) glNamedBufferSubData(primitives.get(), 0, GLsizeiptr(bytes), list.data());
        gl::glCheck("uploading splat primitives");
    }

    /// Scissored to `region`, as draw().
    void drawSlab(const Batch& b, const PixelRect& region) {
        glBindFramebuffer(GL_DRAW_FRAMEBUFFER, slabFbo.get());
        glUseProgram(point.get());
        glBindVertexArray(quads.get());
        glBlendFunc(GL_ONE, GL_ONE);
        glDrawArraysInstancedBaseInstance(GL_TRIANGLE_STRIP, 0, 4, GLsizei(b.count), b.first);
        // Composite and clear only the slab's pixel box (every primitive kept meets the region).
        scissor(b.box, region);
        glBindFramebuffer(GL_DRAW_FRAMEBUFFER, colourFbo.get());
        glUseProgram(composite.get());
        glBindVertexArray(empty.get());
        blendFrontToBack();
        glDrawArrays(GL_TRIANGLES, 0, 3);
        const float zero[4] = {0, 0, 0, 0};
        glClearNamedFramebufferfv(slabFbo.get(), GL_COLOR, 0, zero);
        const std::uint32_t all[4] = {region.x, region.y, region.x + region.width - 1,
                                      region.y + region.height - 1};
        scissor(all, region);
    }

    /// Draws `region` of the image (the pixels drawn): the viewport and every primitive are
    /// the whole image's, so each fragment is the whole frame's; the scissor keeps the region.
    void draw(const std::vector<Batch>& batches, const PixelRect& region) {
        const float zero[4] = {0, 0, 0, 0};
        const std::uint32_t all[4] = {region.x, region.y, region.x + region.width - 1,
                                      region.y + region.height - 1};
        glEnable(GL_SCISSOR_TEST);
        scissor(all, region);
        glClearNamedFramebufferfv(colourFbo.get(), GL_COLOR, 0, zero);
        glClearNamedFramebufferfv(slabFbo.get(), GL_COLOR, 0, zero);
        glViewport(0, 0, GLsizei(width), GLsizei(height));
        glDisable(GL_DEPTH_TEST);
        glDisable(GL_CULL_FACE);
        glEnable(GL_BLEND);
        glBlendEquation(GL_FUNC_ADD);
        glBindTextureUnit(0, footprint.get());
        glBindTextureUnit(1, slab.get());
        for (const Batch& b : batches) {
            if (b.points) {
                drawSlab(b, region);
                continue;
            }
            glBindFramebuffer(GL_DRAW_FRAMEBUFFER, colourFbo.get());
            glUseProgram(splat.get());
            glBindVertexArray(quads.get());
            blendFrontToBack();
            glDrawArraysInstancedBaseInstance(GL_TRIANGLE_STRIP, 0, 4, GLsizei(b.count), b.first);
        }
        glDisable(GL_BLEND); // other renderers of this context expect the default state
        glDisable(GL_SCISSOR_TEST);
        glBindFramebuffer(GL_DRAW_FRAMEBUFFER, 0);
        glBindVertexArray(0);
        glUseProgram(0);
        gl::glCheck("drawing splats");
    }

    /// The pixels of `region` (texture row = image row: no flip).
    Image readBack(const PixelRect& region) {
        Image image(region.width, region.height);
        glGetTextureSubImage(colour.get(), 0, GLint(region.x), GLint(region.y), 0,
                             GLsizei(region.width), GLsizei(region.height), 1, GL_RGBA, GL_FLOAT,
                             GLsizei(image.rgba.size() * 4), image.rgba.data());
        gl::glCheck("reading the splatter image back");
        for (float& v : image.rgba)
            v = std::clamp(v, 0.0f, 1.0f);
        return image;
    }
};

namespace {

void setViewUniforms(GLuint p, const Frame& f, std::uint32_t w, std::uint32_t h) {
    auto vec3 = [&](const char* name, const glm::dvec3& x) {
        glProgramUniform3f(p, glGetUniformLocation(p, name), float(x.x), float(x.y), float(x.z));
    };
    auto f1 = [&](const char* name, double x) {
        glProgramUniform1f(p, glGetUniformLocation(p, name), float(x));
    };
    glProgramUniform2f(p, glGetUniformLocation(p, "uViewport"), float(w), float(h));
    vec3("uForward", f.view.forward);
    vec3("uRight", f.view.right);
    vec3("uUp", f.view.up);
    f1("uFocal", f.view.focalLength);
    f1("uOrthoScale", f.view.orthoScale);
    f1("uInvRadius", 1.0 / f.radiusMm);
    glProgramUniform1i(p, glGetUniformLocation(p, "uOrtho"), f.view.orthographic);
}

/// The instance attributes of Primitive, from binding 0 (the buffer is attached on upload).
void describePrimitives(GLuint vao) {
    for (GLuint i = 0; i < 3; ++i) {
        glEnableVertexArrayAttrib(vao, i);
        glVertexArrayAttribFormat(vao, i, 4, GL_FLOAT, GL_FALSE, i * 4 * sizeof(float));
        glVertexArrayAttribBinding(vao, i, 0);
    }
    glVertexArrayBindingDivisor(vao, 0, 1);
}

} // namespace

std::vector<float> GpuSplatter::footprintTexels(const SplatFootprint& footprint) {
    std::vector<float> texels(kFootprintTexels);
    for (std::uint32_t k = 0; k < kFootprintTexels; ++k)
        texels[k] = float(footprint.lineIntegral(double(k) / (kFootprintTexels - 1)));
    return texels;
}

double GpuSplatter::sampleFootprint(const std::vector<float>& texels, double distanceRadii) {
    if (!(distanceRadii < 1.0)) return 0.0;
    const double u = std::clamp(distanceRadii, 0.0, 1.0) * (kFootprintTexels - 1);
    const std::uint32_t i = std::min(std::uint32_t(u), kFootprintTexels - 2);
    return texels[i] + (u - i) * (double(texels[i + 1]) - texels[i]);
}

GpuSplatter::GpuSplatter(const HybridSplatterConfig& config)
    : mConfig((config.validate(), config)),
      mFootprint(SplatFootprintConfig{config.sigmaOverRadius}), mGpu(std::make_unique<Gpu>()) {
    mGpu->splat = detail::buildShaderProgram(detail::ShaderProgram::Splat);
    mGpu->point = detail::buildShaderProgram(detail::ShaderProgram::SplatPoint);
    mGpu->composite = detail::buildShaderProgram(detail::ShaderProgram::SplatComposite);
    GLuint vao[2] = {0, 0};
    glCreateVertexArrays(2, vao);
    mGpu->quads = gl::VertexArray(vao[0]);
    mGpu->empty = gl::VertexArray(vao[1]);
    describePrimitives(vao[0]);
    mGpu->footprint = gl::createTexture(GL_TEXTURE_1D);
    glTextureStorage1D(mGpu->footprint.get(), 1, GL_R32F, GLsizei(kFootprintTexels));
    glTextureParameteri(mGpu->footprint.get(), GL_TEXTURE_MIN_FILTER, GL_NEAREST);
    glTextureParameteri(mGpu->footprint.get(), GL_TEXTURE_MAG_FILTER, GL_NEAREST);
    const std::vector<float> texels = footprintTexels(mFootprint);
    glTextureSubImage1D(mGpu->footprint.get(), 0, 0, GLsizei(kFootprintTexels), GL_RED, GL_FLOAT,
                        texels.data());
    gl::glCheck("creating the splatter");
}

GpuSplatter::~GpuSplatter() = default;

Image GpuSplatter::render(const Scene& scene, const View& view, const RenderOptions& options,
                          FrameStats& stats) {
    const auto frameStart = Clock::now();
    stats = FrameStats{};
    mLast = HybridSplatStats{};
    const detail::SplatScene splat = detail::sceneOf(scene, view, options, stats);
    const brickstore::BrickStore& store = scene.store;
    brickstore::BrickCache& cache = scene.cache;
    const OccupancyTrees* occupancy = splat.occupancy();
    const Frame f = detail::frameOf(mConfig, splat.g, view.basis, options, splat.table());
    BrickPlan plan = planBricks(store, splat.g, splat.table(), view.basis, options.skip, occupancy);
    detail::cullOutsideRegion(f, options.region, options.width, options.height, plan);
    recordPlan(plan, splat.level, stats);

    const auto prepareStart = Clock::now();
    const PixelRect region = options.drawn();
    PrimitiveList list(f, mFootprint, options.width, options.height, region, mLast);
    const auto type = store.info().volume.type;
    const std::uint64_t brickBytes = store.brickBytes(), budget = cache.stats().budgetBytes;
    for (std::size_t first = 0, end; first < plan.drawn.size(); first = end) {
        end = detail::chunkEnd(plan, first, brickBytes, budget);
        std::vector<PreparedBrick> chunk(end - first);
        detail::prepareChunk(f, plan, first, cache, type, occupancy, chunk);
        for (const PreparedBrick& p : chunk) {
            mLast.leavesSkipped += p.leavesSkipped;
            for (const Visible& vis : p.voxels)
                list.draw(vis.centre, vis.depth, vis.rgba.data(), vis.rgba[3]);
            list.flushSlab(); // the next brick may lie in front of this slab
        }
    }
    mGpu->ensureTargets(options.width, options.height);
    mGpu->upload(list.primitives);
    setViewUniforms(mGpu->splat.get(), f, options.width, options.height);
    setViewUniforms(mGpu->point.get(), f, options.width, options.height);
    gl::glCheck("setting splatter uniforms");
    stats.uploadMs = msSince(prepareStart);

    const auto renderStart = Clock::now();
    mGpu->draw(list.batches, region);
    glFinish();
    stats.renderMs = msSince(renderStart);
    const auto readStart = Clock::now();
    Image image = mGpu->readBack(region);
    stats.readbackMs = msSince(readStart);
    stats.batches = std::uint32_t(list.batches.size());
    stats.samples = mLast.points + mLast.splats;
    stats.octreeLeaps = mLast.leavesSkipped;
    stats.occlusionReason = "not on the splatter";
    stats.totalMs = msSince(frameStart);
    return image;
}

} // namespace bc::render
