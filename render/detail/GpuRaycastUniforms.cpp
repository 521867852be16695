#include "render/detail/GpuRaycastUniforms.h"

#include "render/BrickPlan.h"
#include "render/BrickPool.h"
#include "render/Camera.h"
#include "render/Occupancy.h"
#include "render/RenderTypes.h"
#include "render/TransferFunction.h"

#include <glm/vec3.hpp>

#include <array>

namespace bc::render::detail {
namespace {

void vec3(GLuint p, const char* name, const glm::dvec3& x) {
    glProgramUniform3f(p, glGetUniformLocation(p, name), float(x.x), float(x.y), float(x.z));
}

void f1(GLuint p, const char* name, double x) {
    glProgramUniform1f(p, glGetUniformLocation(p, name), float(x));
}

/// The camera and the viewport.
void setViewUniforms(GLuint p, const ViewBasis& v, const RenderOptions& o) {
    glProgramUniform2f(p, glGetUniformLocation(p, "uViewport"), float(o.width), float(o.height));
    vec3(p, "uEye", v.eye);
    vec3(p, "uForward", v.forward);
    vec3(p, "uRight", v.right);
    vec3(p, "uUp", v.upScaled);
    uniform1i(p, "uOrtho", v.orthographic);
}

/// The level's voxel and brick grids, the step, and the pool's slots.
void setGridUniforms(GLuint p, const LevelGeometry& g, const RenderOptions& o,
                     const BrickPool& pool) {
    vec3(p, "uInvSpacing", 1.0 / g.spacing);
    vec3(p, "uDims", glm::dvec3(double(g.dims[0]), double(g.dims[1]), double(g.dims[2])));
    f1(p, "uStepMm", o.stepVoxels * g.minSpacing());
    uniform1i(p, "uBrick", int(g.brickVoxels));
    uniform1i(p, "uApron", int(g.apronVoxels));
    uniform1i(p, "uEdge", int(pool.edge()));
    glProgramUniform3i(p, glGetUniformLocation(p, "uGrid"), int(g.bricks[0]), int(g.bricks[1]),
                       int(g.bricks[2]));
    const auto sg = pool.slotGrid();
    glProgramUniform3i(p, glGetUniformLocation(p, "uSlotGrid"), int(sg[0]), int(sg[1]), int(sg[2]));
    const auto ts = pool.textureSize();
    vec3(p, "uInvPoolSize", glm::dvec3(1.0 / ts[0], 1.0 / ts[1], 1.0 / ts[2]));
}

/// The table's mapping from pool texels, the options' switches and the shading model.
void setShadingUniforms(GLuint p, const LevelGeometry& g, const RenderOptions& o,
                        const TransferFunctionTable& table, const BrickPool& pool) {
    // texel t -> native v = t*scale + offset -> entry position (v - min)/(max - min) * (N - 1)
    const TexelMapping m = pool.texelMapping();
    const double span = table.domainMax - table.domainMin, n = table.entries;
    f1(p, "uTfScale", m.scale / span * (n - 1.0));
    f1(p, "uTfOffset", (m.offset - table.domainMin) / span * (n - 1.0));
    uniform1i(p, "uTfEntries", int(table.entries));
    f1(p, "uErt", o.earlyTermination ? o.ertThreshold : 2.0);
    uniform1i(p, "uShading", o.shading);
    uniform1i(p, "uHardwareFilter", o.hardwareFilter);
    uniform1i(p, "uJitter", o.jitter);
    const double perVoxel = 0.5 * m.scale / span * g.minSpacing();
    vec3(p, "uGradScale", perVoxel / g.spacing);
    f1(p, "uGradFade", ShadingModel::kGradientFade);
    f1(p, "uAmbient", ShadingModel::kAmbient);
    f1(p, "uDiffuse", ShadingModel::kDiffuse);
    f1(p, "uSpecular", ShadingModel::kSpecular);
    f1(p, "uShininess", ShadingModel::kShininess);
}

/// The mode (the iso value as a pool texel) and the clip.
void setModeUniforms(GLuint p, const RenderOptions& o, const BrickPool& pool) {
    const TexelMapping m = pool.texelMapping();
    uniform1i(p, "uMode", int(o.mode));
    f1(p, "uIso", (o.isoValue - m.offset) / m.scale);
    const Clip& c = o.clip;
    uniform1i(p, "uCropped", c.cropped);
    vec3(p, "uCropMin", glm::dvec3(c.cropMin[0], c.cropMin[1], c.cropMin[2]));
    vec3(p, "uCropMax", glm::dvec3(c.cropMax[0], c.cropMax[1], c.cropMax[2]));
    // The planes as the CPU raycaster's rays take them: unit normals, offsets float holds.
    const ClipF f = ClipF::of(c);
    std::array<float, 4 * Clip::kMaxPlanes> planes{};
    for (int i = 0; i < f.planeCount; ++i) {
        const auto k = std::size_t(i);
        planes[4 * k] = f.normals[k].x;
        planes[4 * k + 1] = f.normals[k].y;
        planes[4 * k + 2] = f.normals[k].z;
        planes[4 * k + 3] = f.offsets[k];
    }
    uniform1i(p, "uPlaneCount", f.planeCount);
    uniform1i(p, "uCap", capsCuts(o));
    f1(p, "uCapPower", o.mode == BlendMode::Composite ? 1.0 / o.stepVoxels : 1.0);
    glProgramUniform4fv(p, glGetUniformLocation(p, "uPlanes"), GLsizei(Clip::kMaxPlanes),
                        planes.data());
}

} // namespace

void uniform1i(GLuint program, const char* name, GLint value) {
    glProgramUniform1i(program, glGetUniformLocation(program, name), value);
}

void setFrameUniforms(GLuint program, const LevelGeometry& g, const ViewBasis& v,
                      const RenderOptions& o, const TransferFunctionTable& table,
                      const BrickPool& pool) {
    setViewUniforms(program, v, o);
    setGridUniforms(program, g, o, pool);
    setShadingUniforms(program, g, o, table, pool);
    setModeUniforms(program, o, pool);
    gl::glCheck("setting raycaster uniforms");
}

void setOccupancyUniforms(GLuint program, const OccupancyTrees* occupancy) {
    uniform1i(program, "uOctDepth", occupancy ? int(occupancy->depth()) : 0);
    uniform1i(program, "uOccWords", occupancy ? int(occupancy->wordsPerBrick()) : 0);
    uniform1i(program, "uLeafAxis", occupancy ? int(occupancy->leavesPerAxis()) : 1);
    glProgramUniform1f(program, glGetUniformLocation(program, "uLeaf"),
                       occupancy ? float(occupancy->leafVoxels()) : 1.0f);
    gl::glCheck("setting occupancy uniforms");
}

} // namespace bc::render::detail
