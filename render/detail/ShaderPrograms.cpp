#include "render/detail/ShaderPrograms.h"

#include "render/Error.h"
#include "render/GpuSplatter.h"

#include <sstream>

namespace bc::render::detail {
namespace {

struct ProgramFiles {
    ShaderProgram program;
    const char* name;
    std::vector<const char*> files;
    std::vector<ShaderDefine> defines = {}; ///< the program's own, for every stage
};

const std::vector<ProgramFiles>& programTable() {
    static const std::vector<ProgramFiles> table = {
        // Two builds of one shader: the modes and cuts cost composite frames time on a
        // software rasteriser (about 1.8x on llvmpipe), so composite, uncut frames draw with
        // a program compiled without them.
        {ShaderProgram::Raycast,
         "raycast",
         {"fullscreen.vert.glsl", "raycast.frag.glsl"},
         {{"BC_MODES", "0"}}},
        {ShaderProgram::RaycastModes,
         "raycast with modes and cuts",
         {"fullscreen.vert.glsl", "raycast.frag.glsl"},
         {{"BC_MODES", "1"}}},
        {ShaderProgram::OcclusionReduce, "occlusion blocks", {"occlusion_reduce.comp.glsl"}},
        {ShaderProgram::OcclusionFrustums,
         "occlusion frustums",
         {"occlusion_frustum.vert.glsl", "occlusion_frustum.geom.glsl",
          "occlusion_start.frag.glsl"}},
        {ShaderProgram::OcclusionPieces,
         "occlusion outside pieces",
         {"occlusion_pieces.vert.glsl", "occlusion_start.frag.glsl"}},
        {ShaderProgram::Splat, "splat", {"splat_quad.vert.glsl", "splat.frag.glsl"}},
        {ShaderProgram::SplatPoint,
         "splat point",
         {"splat_quad.vert.glsl", "splat_point.frag.glsl"}},
        {ShaderProgram::SplatComposite,
         "splat slab composite",
         {"fullscreen.vert.glsl", "splat_composite.frag.glsl"}},
    };
    return table;
}

/// The constants the C++ gives the shaders, by the file that uses them (README.md there).
std::vector<std::pair<std::string, ShaderDefine>> constants() {
    return {{"footprint.inc.glsl",
             {"BC_FOOTPRINT_TEXELS", std::to_string(GpuSplatter::kFootprintTexels)}}};
}

/// The constants of stage file `name`: those of the file and of every snippet it includes.
std::vector<ShaderDefine> definesFor(const std::string& name) {
    std::vector<std::string> users = {name};
    if (const ShaderFileText* file = findShaderFile(name)) {
        std::istringstream includes(file->includes);
        for (std::string snippet; includes >> snippet;)
            users.push_back(snippet);
    }
    std::vector<ShaderDefine> defines;
    for (const auto& [user, define] : constants())
        for (const std::string& u : users)
            if (u == user) defines.push_back(define);
    return defines;
}

} // namespace

std::vector<ShaderProgram> allShaderPrograms() {
    std::vector<ShaderProgram> all;
    for (const ProgramFiles& p : programTable())
        all.push_back(p.program);
    return all;
}

ShaderProgramSource shaderProgramSource(ShaderProgram program) {
    for (const ProgramFiles& p : programTable()) {
        if (p.program != program) continue;
        ShaderProgramSource source{p.name, {}};
        for (const char* file : p.files) {
            std::vector<ShaderDefine> defines = definesFor(file);
            defines.insert(defines.end(), p.defines.begin(), p.defines.end());
            source.stages.push_back(shaderStage(file, defines));
        }
        return source;
    }
    throw RenderError("shader program " + std::to_string(int(program)) +
                      " has no entry in the table");
}

gl::Program buildShaderProgram(ShaderProgram program) {
    const ShaderProgramSource source = shaderProgramSource(program);
    return gl::buildProgram(source.name, source.stages);
}

} // namespace bc::render::detail
