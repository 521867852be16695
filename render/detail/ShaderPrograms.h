#pragma once
// The GL programs of the renderers, each made of stage files of render/shaders/: one table, used
// by the renderers to build them and by tests/render/ShaderCompileTest.cpp to compile them all.
#include "render/detail/Gl.h"
#include "render/detail/ShaderSources.h"

#include <string>
#include <vector>

namespace bc::render::detail {

/// The programs the renderers build; each has one row in the table of ShaderPrograms.cpp.
enum class ShaderProgram {
    Raycast,           ///< GpuRaycaster: one full-screen pass per brick batch (composite, uncut)
    RaycastModes,      ///< the same with every mode and the crop and clip (BC_MODES 1)
    OcclusionReduce,   ///< OcclusionFrustums: first-hit image -> nearest depth per block
    OcclusionFrustums, ///< OcclusionFrustums: one frustum per block -> ray starts
    OcclusionPieces,   ///< OcclusionFrustums: the box outside the last view -> ray starts
    Splat,             ///< GpuSplatter: splats
    SplatPoint,        ///< GpuSplatter: points into the slab
    SplatComposite,    ///< GpuSplatter: the slab onto the image
};

/// Every program of the table in ShaderPrograms.cpp, in its order (what the compile test builds).
std::vector<ShaderProgram> allShaderPrograms();

/// A program's name and its stages, as the renderers build it (files, #defines).
struct ShaderProgramSource {
    std::string name;
    std::vector<gl::ShaderStage> stages;
};

/// The stages of `program`. @throw RenderError when one of its files is not embedded.
ShaderProgramSource shaderProgramSource(ShaderProgram program);

/// Compiles and links `program` on the current context.
/// @throw RenderError naming the program, the failing file and the driver's log.
gl::Program buildShaderProgram(ShaderProgram program);

} // namespace bc::render::detail
