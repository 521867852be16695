#pragma once
// The GPU raycaster's uniforms (render/shaders/raycast.frag.glsl): those that stay the same for
// every pass of a frame, and the one-integer switches its passes flip.
#include "render/detail/Gl.h"

namespace bc::render {

class BrickPool;
class OccupancyTrees;
struct LevelGeometry;
struct RenderOptions;
struct TransferFunctionTable;
struct ViewBasis;

namespace detail {

/// Sets the int (or bool) uniform `name` of `program`.
void uniform1i(GLuint program, const char* name, GLint value);

/// Uniforms that stay the same for every batch of a frame: the view, the brick and pool grids,
/// the table's mapping from texels, the options and the shading model.
void setFrameUniforms(GLuint program, const LevelGeometry& g, const ViewBasis& v,
                      const RenderOptions& o, const TransferFunctionTable& table,
                      const BrickPool& pool);

/// The octree's shape (`occupancy` null: none, the shader walks bricks alone).
void setOccupancyUniforms(GLuint program, const OccupancyTrees* occupancy);

} // namespace detail
} // namespace bc::render
