#include "render/detail/ShaderSources.h"

#include "render/Error.h"

namespace bc::render::detail {

const ShaderFileText* findShaderFile(std::string_view name) {
    for (std::size_t i = 0; i < kShaderFileCount; ++i)
        if (name == kShaderFiles[i].name) return &kShaderFiles[i];
    return nullptr;
}

GLenum shaderStageType(std::string_view name) {
    const auto endsWith = [&](std::string_view suffix) {
        return name.size() >= suffix.size() && name.substr(name.size() - suffix.size()) == suffix;
    };
    if (endsWith(".vert.glsl")) return GL_VERTEX_SHADER;
    if (endsWith(".geom.glsl")) return GL_GEOMETRY_SHADER;
    if (endsWith(".frag.glsl")) return GL_FRAGMENT_SHADER;
    if (endsWith(".comp.glsl")) return GL_COMPUTE_SHADER;
    return 0;
}

gl::ShaderStage shaderStage(std::string_view name, const std::vector<ShaderDefine>& defines) {
    const ShaderFileText* file = findShaderFile(name);
    const GLenum type = shaderStageType(name);
    if (!file || type == 0)
        throw RenderError("no shader stage file render/shaders/" + std::string(name) +
                          " is embedded");
    std::string source = file->text;
    if (!defines.empty()) {
        // EmbedText.cmake checked that a stage file starts with its #version line.
        std::string block;
        for (const ShaderDefine& d : defines)
            block += "#define " + d.name + " " + d.value + "\n";
        source.insert(source.find('\n') + 1, block + "#line 2\n");
    }
    return {type, std::move(source), std::string(name)};
}

} // namespace bc::render::detail
