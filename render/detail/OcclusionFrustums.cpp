#include "render/detail/OcclusionFrustums.h"

#include "render/Error.h"
#include "render/detail/ShaderPrograms.h"

#include <algorithm>
#include <chrono>
#include <cmath>

#include <glm/geometric.hpp>
#include <glm/mat4x4.hpp>

namespace bc::render::detail {
namespace {

constexpr float kMiss = 3.0e38f; // no first hit / no proxy: beyond any ray

/// World -> clip for `v` (the raycaster's ray rule), clipping at `nearMm` and `farMm`.
glm::mat4 viewProjection(const ViewBasis& v, double nearMm, double farMm) {
    const glm::dvec3 r = v.right / glm::dot(v.right, v.right);
    const glm::dvec3 u = v.upScaled / glm::dot(v.upScaled, v.upScaled);
    const glm::dvec3 f = v.forward;
    auto row = [&](const glm::dvec3& a) { return glm::dvec4(a, -glm::dot(a, v.eye)); };
    glm::dvec4 rows[4] = {row(r), row(u), {}, {}};
    if (v.orthographic) {
        rows[3] = {0, 0, 0, 1};
        rows[2] = row(f) * (2.0 / farMm) - glm::dvec4(0, 0, 0, 1);
    } else {
        rows[3] = row(f);
        rows[2] = rows[3] * ((farMm + nearMm) / (farMm - nearMm)) -
                  glm::dvec4(0, 0, 0, 2.0 * farMm * nearMm / (farMm - nearMm));
    }
    glm::mat4 m(0.0f);
    for (int c = 0; c < 4; ++c)
        for (int rr = 0; rr < 4; ++rr)
            m[c][rr] = float(rows[rr][c]);
    return m;
}

struct HalfSpace {
    glm::dvec3 point, normal; ///< kept: dot(p - point, normal) <= 0
};

/// The part of `box` in `h`, as triangles (a convex polyhedron: clipped faces and the cap).
void clipBox(const Box& box, const HalfSpace& h, std::vector<float>& triangles) {
    auto corner = [&](int c) {
        return glm::dvec3((c & 1) ? box.max.x : box.min.x, (c & 2) ? box.max.y : box.min.y,
                          (c & 4) ? box.max.z : box.min.z);
    };
    static const int kFaces[6][4] = {{0, 2, 6, 4}, {1, 3, 7, 5}, {0, 1, 5, 4},
                                     {2, 3, 7, 6}, {0, 1, 3, 2}, {4, 5, 7, 6}};
    auto side = [&](const glm::dvec3& p) { return glm::dot(p - h.point, h.normal); };
    std::vector<glm::dvec3> cap;
    auto fan = [&](const std::vector<glm::dvec3>& poly) {
        for (std::size_t i = 1; i + 1 < poly.size(); ++i)
            for (const auto* p : {&poly[0], &poly[i], &poly[i + 1]})
                triangles.insert(triangles.end(), {float(p->x), float(p->y), float(p->z)});
    };
    for (const auto& face : kFaces) {
        std::vector<glm::dvec3> out;
        for (int i = 0; i < 4; ++i) {
            const glm::dvec3 a = corner(face[i]), b = corner(face[(i + 1) % 4]);
            const double sa = side(a), sb = side(b);
            if (sa <= 0) out.push_back(a);
            if ((sa <= 0) != (sb <= 0)) {
                const glm::dvec3 x = a + (b - a) * (sa / (sa - sb));
                out.push_back(x);
                cap.push_back(x);
            }
        }
        if (out.size() >= 3) fan(out);
    }
    if (cap.size() < 3) return;
    glm::dvec3 centre(0.0);
    for (const auto& p : cap)
        centre += p / double(cap.size());
    const glm::dvec3 e1 =
        glm::normalize(glm::abs(h.normal.x) < 0.9 ? glm::cross(h.normal, glm::dvec3(1, 0, 0))
                                                  : glm::cross(h.normal, glm::dvec3(0, 1, 0)));
    const glm::dvec3 e2 = glm::cross(h.normal, e1);
    std::sort(cap.begin(), cap.end(), [&](const glm::dvec3& a, const glm::dvec3& b) {
        return std::atan2(glm::dot(a - centre, e2), glm::dot(a - centre, e1)) <
               std::atan2(glm::dot(b - centre, e2), glm::dot(b - centre, e1));
    });
    fan(cap);
}

/// The outside of `v`'s view volume as half-spaces: beyond each side plane, and behind the
/// plane at `nearMm` in front of the eye. Each is widened by `slackMm` so the pieces overlap
/// the block frustums.
std::vector<HalfSpace> outsideOfView(const ViewBasis& v, double nearMm, double slackMm) {
    std::vector<HalfSpace> out;
    out.push_back({v.eye + v.forward * (nearMm + slackMm), v.forward});
    if (v.orthographic) {
        const glm::dvec3 r = glm::normalize(v.right), u = glm::normalize(v.upScaled);
        out.push_back({v.eye + v.right - r * slackMm, -r});
        out.push_back({v.eye - v.right + r * slackMm, r});
        out.push_back({v.eye + v.upScaled - u * slackMm, -u});
        out.push_back({v.eye - v.upScaled + u * slackMm, u});
        return out;
    }
    const glm::dvec3 f = v.forward, r = v.right, u = v.upScaled;
    const glm::dvec3 c[4] = {f + r + u, f - r + u, f - r - u, f + r - u};
    for (int i = 0; i < 4; ++i) {
        glm::dvec3 n = glm::normalize(glm::cross(c[i], c[(i + 1) % 4]));
        if (glm::dot(n, f) < 0.0) n = -n; // inward
        out.push_back({v.eye + n * slackMm, n});
    }
    return out;
}

bool insideBox(const glm::dvec3& p, const Box& b) {
    return p.x >= b.min.x && p.y >= b.min.y && p.z >= b.min.z && p.x <= b.max.x && p.y <= b.max.y &&
           p.z <= b.max.z;
}

void uniform3(GLuint p, const char* name, const glm::dvec3& v) {
    glProgramUniform3f(p, glGetUniformLocation(p, name), float(v.x), float(v.y), float(v.z));
}

} // namespace

OcclusionFrustums::OcclusionFrustums() {
    mReduce = buildShaderProgram(ShaderProgram::OcclusionReduce);
    mFrustum = buildShaderProgram(ShaderProgram::OcclusionFrustums);
    mPieces = buildShaderProgram(ShaderProgram::OcclusionPieces);
    GLuint vao = 0;
    glCreateVertexArrays(1, &vao);
    mVao = gl::VertexArray(vao);
    gl::glCheck("creating occlusion frustums");
}

void OcclusionFrustums::ensureTargets(std::uint32_t width, std::uint32_t height) {
    if (width == mWidth && height == mHeight) return;
    for (gl::Texture* t : {&mFirstHit, &mStart}) {
        *t = gl::createTexture(GL_TEXTURE_2D);
        glTextureStorage2D(t->get(), 1, GL_R32F, GLsizei(width), GLsizei(height));
        glTextureParameteri(t->get(), GL_TEXTURE_MIN_FILTER, GL_NEAREST);
        glTextureParameteri(t->get(), GL_TEXTURE_MAG_FILTER, GL_NEAREST);
    }
    GLuint f = 0;
    glCreateFramebuffers(1, &f);
    mStartFbo = gl::Framebuffer(f);
    glNamedFramebufferTexture(f, GL_COLOR_ATTACHMENT0, mStart.get(), 0);
    if (glCheckNamedFramebufferStatus(f, GL_FRAMEBUFFER) != GL_FRAMEBUFFER_COMPLETE)
        throw RenderError("occlusion ray-start target is incomplete");
    mWidth = width;
    mHeight = height;
    mValid = false;
    gl::glCheck("allocating occlusion targets");
}

void OcclusionFrustums::beginFrame(std::uint32_t width, std::uint32_t height) {
    ensureTargets(width, height);
    glClearTexImage(mFirstHit.get(), 0, GL_RED, GL_FLOAT, &kMiss);
    gl::glCheck("clearing the first-hit image");
}

bool OcclusionFrustums::prepare(const ViewBasis& view, std::uint32_t width, std::uint32_t height,
                                const Box& box, std::uint64_t sceneKey, double cellMm,
                                double stepMm, const OcclusionConfig& config, FrameStats& stats) {
    const auto start = std::chrono::steady_clock::now();
    mComparable = false;
    auto refuse = [&](const char* why) {
        stats.occlusionUsed = false;
        stats.occlusionReason = why;
        return false;
    };
    if (!mValid || width != mWidth || height != mHeight || config.blockPixels != mBlockPixels)
        return refuse("no previous frame of this size");
    if (sceneKey != mSceneKey) return refuse("volume, transfer function or options changed");
    mComparable = true; // from here on a plain frame measures what the proxies compete with
    if (mOffFor > 0) {
        --mOffFor;
        return refuse("policy: frustums cost more than they saved");
    }
    if ((mPlainMs < 0.0 && mUsedRun >= 1) || mUsedRun >= config.probeEvery) {
        mUsedRun = 0;
        return refuse("policy: probing the plain box");
    }
    if (insideBox(view.eye, box)) return refuse("camera inside the volume");
    // What can hide between the last frame's rays: rays must be denser than the cells.
    double deepest = 0.0;
    for (float z : mBlockDepth)
        if (z < kMiss) deepest = std::max(deepest, double(z));
    const double footprint = mView.orthographic ? 2.0 * glm::length(mView.upScaled) / double(height)
                                                : 2.0 * (deepest + cellMm * std::sqrt(3.0)) *
                                                      glm::length(mView.upScaled) / double(height);
    if (footprint > 0.5 * cellMm || stepMm > 0.5 * cellMm)
        return refuse("rays sparser than the occupancy cells");
    const double margin = cellMm * std::sqrt(3.0) + 2.0 * stepMm;
    const double nearMin = mView.orthographic ? 0.0 : 1e-4 * box.radius();
    // The new eye inside a frustum (seen from the old eye, behind a block's near cap): all of
    // its rays would start inside the union, so the plain box is exact and as fast.
    {
        const glm::dvec3 rel = view.eye - mView.eye;
        const double z = glm::dot(rel, mView.forward);
        if (z > nearMin) {
            const glm::dvec3 r = mView.right / glm::dot(mView.right, mView.right);
            const glm::dvec3 u = mView.upScaled / glm::dot(mView.upScaled, mView.upScaled);
            const double w = mView.orthographic ? 1.0 : z;
            const double px = (glm::dot(rel, r) / w + 1.0) * 0.5 * width;
            const double py = (glm::dot(rel, u) / w + 1.0) * 0.5 * height;
            const auto bx = std::int64_t(std::floor(px / mBlockPixels));
            const auto by = std::int64_t(std::floor(py / mBlockPixels));
            for (std::int64_t y = by - 1; y <= by + 1; ++y)
                for (std::int64_t x = bx - 1; x <= bx + 1; ++x) {
                    if (x < 0 || y < 0 || x >= std::int64_t(mBlocksX) ||
                        y >= std::int64_t(mBlocksY))
                        continue;
                    const float zb = mBlockDepth[std::size_t(y) * mBlocksX + std::size_t(x)];
                    if (zb < kMiss && z >= std::max(double(zb) - margin, nearMin))
                        return refuse("camera inside an occlusion frustum");
                }
        }
    }
    const double farMm = glm::length(box.centre() - mView.eye) + 2.0 * box.radius() + margin;
    const double newFar = glm::length(box.centre() - view.eye) + 4.0 * box.radius() + farMm;
    const glm::mat4 viewProj = viewProjection(view, 1e-4 * box.radius(), newFar);

    glBindFramebuffer(GL_FRAMEBUFFER, mStartFbo.get());
    glViewport(0, 0, GLsizei(width), GLsizei(height));
    const float clear[4] = {kMiss, 0, 0, 0};
    glClearBufferfv(GL_COLOR, 0, clear);
    glEnable(GL_BLEND);
    glBlendEquation(GL_MIN);
    glBlendFunc(GL_ONE, GL_ONE);
    for (GLuint p : {mFrustum.get(), mPieces.get()}) {
        glProgramUniformMatrix4fv(p, glGetUniformLocation(p, "uViewProj"), 1, GL_FALSE,
                                  &viewProj[0][0]);
        uniform3(p, "uEye", view.eye);
        uniform3(p, "uForward", view.forward);
        glProgramUniform1i(p, glGetUniformLocation(p, "uOrtho"), view.orthographic);
    }
    const GLuint fp = mFrustum.get();
    glProgramUniform2i(fp, glGetUniformLocation(fp, "uBlocks"), GLint(mBlocksX), GLint(mBlocksY));
    glProgramUniform1i(fp, glGetUniformLocation(fp, "uK"), GLint(mBlockPixels));
    glProgramUniform2f(fp, glGetUniformLocation(fp, "uOldSize"), float(width), float(height));
    uniform3(fp, "uOldEye", mView.eye);
    uniform3(fp, "uOldForward", mView.forward);
    uniform3(fp, "uOldRight", mView.right);
    uniform3(fp, "uOldUp", mView.upScaled);
    glProgramUniform1i(fp, glGetUniformLocation(fp, "uOldOrtho"), mView.orthographic);
    glProgramUniform1f(fp, glGetUniformLocation(fp, "uMargin"), float(margin));
    glProgramUniform1f(fp, glGetUniformLocation(fp, "uNearMin"), float(nearMin));
    glProgramUniform1f(fp, glGetUniformLocation(fp, "uFar"), float(farMm));
    glBindVertexArray(mVao.get());
    glBindBufferBase(GL_SHADER_STORAGE_BUFFER, 3, mBlocks.get());
    glUseProgram(fp);
    glDrawArrays(GL_POINTS, 0, GLsizei(mBlocksX * mBlocksY));
    const std::uint32_t pieceTriangles = drawOutsidePieces(view, box);
    glDisable(GL_BLEND);
    glBlendEquation(GL_FUNC_ADD);
    glMemoryBarrier(GL_TEXTURE_FETCH_BARRIER_BIT);
    glFinish();
    gl::glCheck("drawing occlusion frustums");
    std::uint64_t frustums = 0;
    for (float z : mBlockDepth)
        frustums += z < kMiss;
    stats.occlusionUsed = true;
    stats.occlusionReason = "";
    stats.occlusionFrustums = frustums;
    stats.occlusionTriangles = 12 * frustums + pieceTriangles;
    stats.occlusionBuildMs +=
        std::chrono::duration<double, std::milli>(std::chrono::steady_clock::now() - start).count();
    return true;
}

std::uint32_t OcclusionFrustums::drawOutsidePieces(const ViewBasis& view, const Box& box) {
    (void)view;
    const double nearMin = mView.orthographic ? 0.0 : 1e-4 * box.radius();
    std::vector<float> triangles;
    for (const HalfSpace& h : outsideOfView(mView, nearMin, 1e-3 * box.radius()))
        clipBox(box, h, triangles);
    if (triangles.empty()) return 0;
    mPieceVertices = gl::createBuffer();
    glNamedBufferStorage(mPieceVertices.get(), GLsizeiptr(triangles.size() * 4), triangles.data(),
                         0);
    GLuint vao = 0;
    glCreateVertexArrays(1, &vao);
    gl::VertexArray pieceVao(vao);
    glVertexArrayVertexBuffer(vao, 0, mPieceVertices.get(), 0, 3 * sizeof(float));
    glEnableVertexArrayAttrib(vao, 0);
    glVertexArrayAttribFormat(vao, 0, 3, GL_FLOAT, GL_FALSE, 0);
    glVertexArrayAttribBinding(vao, 0, 0);
    glBindVertexArray(vao);
    glUseProgram(mPieces.get());
    glDrawArrays(GL_TRIANGLES, 0, GLsizei(triangles.size() / 3));
    glBindVertexArray(mVao.get());
    return std::uint32_t(triangles.size() / 9);
}

void OcclusionFrustums::capture(const ViewBasis& view, std::uint64_t sceneKey, double frameMs,
                                bool proxiesUsed, const OcclusionConfig& config) {
    if (proxiesUsed) {
        ++mUsedRun;
        if (mPlainMs > 0.0 && frameMs >= mPlainMs) { // they do not pay: off for a while
            mOffFor = config.offFrames;
            mUsedRun = 0;
        }
    } else if (mComparable) {
        mPlainMs = frameMs;
    }
    mBlockPixels = config.blockPixels;
    mBlocksX = (mWidth + mBlockPixels - 1) / mBlockPixels;
    mBlocksY = (mHeight + mBlockPixels - 1) / mBlockPixels;
    const std::size_t blocks = std::size_t(mBlocksX) * mBlocksY;
    mBlocks = gl::createBuffer();
    glNamedBufferStorage(mBlocks.get(), GLsizeiptr(blocks * 4), nullptr, GL_MAP_READ_BIT);
    const GLuint p = mReduce.get();
    glProgramUniform2i(p, glGetUniformLocation(p, "uSize"), GLint(mWidth), GLint(mHeight));
    glProgramUniform2i(p, glGetUniformLocation(p, "uBlocks"), GLint(mBlocksX), GLint(mBlocksY));
    glProgramUniform1i(p, glGetUniformLocation(p, "uK"), GLint(mBlockPixels));
    uniform3(p, "uForward", view.forward);
    uniform3(p, "uRight", view.right);
    uniform3(p, "uUp", view.upScaled);
    glProgramUniform1i(p, glGetUniformLocation(p, "uOrtho"), view.orthographic);
    glMemoryBarrier(GL_TEXTURE_FETCH_BARRIER_BIT | GL_SHADER_IMAGE_ACCESS_BARRIER_BIT);
    glUseProgram(p);
    glBindTextureUnit(0, mFirstHit.get());
    glBindBufferBase(GL_SHADER_STORAGE_BUFFER, 3, mBlocks.get());
    glDispatchCompute((mBlocksX + 7) / 8, (mBlocksY + 7) / 8, 1);
    glMemoryBarrier(GL_BUFFER_UPDATE_BARRIER_BIT | GL_SHADER_STORAGE_BARRIER_BIT);
    mBlockDepth.resize(blocks);
    glGetNamedBufferSubData(mBlocks.get(), 0, GLsizeiptr(blocks * 4), mBlockDepth.data());
    gl::glCheck("reducing the first-hit image to occlusion blocks");
    mView = view;
    mSceneKey = sceneKey;
    mValid = true;
}

} // namespace bc::render::detail
