#pragma once
// The GLSL of render/shaders/, embedded at build time by bc_embed_text (cmake/EmbedText.cmake; the
// generated EmbeddedShaders.cpp lives in the build tree). How the files are named, included and
// given constants from the C++: render/shaders/README.md.
#include "render/detail/Gl.h"

#include <cstddef>
#include <string>
#include <string_view>
#include <vector>

namespace bc::render::detail {

/// One file of render/shaders/ as embedded.
struct ShaderFileText {
    const char* name; ///< file name, e.g. "raycast.frag.glsl"
    /// The snippets a stage file includes, space-separated: the compiler's log gives line k of
    /// the n-th as line n * 1000 + k (the file's own lines are as they are).
    const char* includes;
    const char* text; ///< a stage file's text has its #include lines expanded
};

/// The embedded files, stage files and snippets (NAME.inc.glsl), sorted by name.
extern const ShaderFileText kShaderFiles[];
extern const std::size_t kShaderFileCount;

/// A constant the C++ gives a shader: `#define name value` after its #version line.
struct ShaderDefine {
    std::string name, value;
};

/// The embedded file `name`, or nullptr.
const ShaderFileText* findShaderFile(std::string_view name);

/// The stage of a file name (GL_VERTEX_SHADER for NAME.vert.glsl, ...), or 0 for a snippet.
GLenum shaderStageType(std::string_view name);

/// The stage file `name` ready to compile: `defines` go after its #version line, followed by a
/// #line directive, so the compiler's log still counts the file's own lines.
/// @throw RenderError when `name` is not an embedded stage file.
gl::ShaderStage shaderStage(std::string_view name, const std::vector<ShaderDefine>& defines = {});

} // namespace bc::render::detail
