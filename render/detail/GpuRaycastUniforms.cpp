#include "render/detail/GpuRaycastUniforms.h"

#include "render/BrickPlan.h"
#include "render/BrickPool.h"
#include "render/Camera.h"
#include "render/Occupancy.h"
#include "render/RenderTypes.h"
#include "render/TransferFunction.h"

#include <glm/vec3.hpp>

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
