#include "render/detail/Gl.h"

#include "render/Error.h"

#include <cstdio>
#include <vector>

namespace bc::render::gl {

void glCheck(const char* what) {
    GLenum first = glGetError();
    if (first == GL_NO_ERROR) return;
    while (glGetError() != GL_NO_ERROR) {
    }
    char buf[160];
    const char* name = first == GL_OUT_OF_MEMORY       ? "GL_OUT_OF_MEMORY"
                       : first == GL_INVALID_VALUE     ? "GL_INVALID_VALUE"
                       : first == GL_INVALID_OPERATION ? "GL_INVALID_OPERATION"
                       : first == GL_INVALID_ENUM      ? "GL_INVALID_ENUM"
                       : first == GL_INVALID_FRAMEBUFFER_OPERATION
                           ? "GL_INVALID_FRAMEBUFFER_OPERATION"
                           : "GL error";
    std::snprintf(buf, sizeof buf, "%s: %s (0x%x)", what, name, unsigned(first));
    throw RenderError(buf);
}

void deleteTexture(GLuint n) {
    glDeleteTextures(1, &n);
}
void deleteBuffer(GLuint n) {
    glDeleteBuffers(1, &n);
}
void deleteFramebuffer(GLuint n) {
    glDeleteFramebuffers(1, &n);
}
void deleteVertexArray(GLuint n) {
    glDeleteVertexArrays(1, &n);
}
void deleteProgram(GLuint n) {
    glDeleteProgram(n);
}

Texture createTexture(GLenum target) {
    GLuint n = 0;
    glCreateTextures(target, 1, &n);
    return Texture(n);
}

Buffer createBuffer() {
    GLuint n = 0;
    glCreateBuffers(1, &n);
    return Buffer(n);
}

namespace {

const char* stageName(GLenum type) {
    return type == GL_VERTEX_SHADER     ? "vertex"
           : type == GL_GEOMETRY_SHADER ? "geometry"
           : type == GL_FRAGMENT_SHADER ? "fragment"
           : type == GL_COMPUTE_SHADER  ? "compute"
                                        : "unknown stage";
}

GLuint compile(const std::string& name, const ShaderStage& stage) {
    GLuint shader = glCreateShader(stage.type);
    const char* text = stage.source.c_str();
    glShaderSource(shader, 1, &text, nullptr);
    glCompileShader(shader);
    GLint ok = 0;
    glGetShaderiv(shader, GL_COMPILE_STATUS, &ok);
    if (ok) return shader;
    GLint length = 0;
    glGetShaderiv(shader, GL_INFO_LOG_LENGTH, &length);
    std::vector<char> log(std::size_t(length) + 1, '\0');
    glGetShaderInfoLog(shader, length, nullptr, log.data());
    glDeleteShader(shader);
    const std::string where = stage.file.empty() ? "" : stage.file + ", ";
    throw RenderError("shader " + name + " (" + where + stageName(stage.type) +
                      ") does not compile: " + log.data());
}

} // namespace

Program buildProgram(const std::string& name, const std::vector<ShaderStage>& stages) {
    Program program(glCreateProgram());
    std::vector<GLuint> shaders;
    try {
        for (const ShaderStage& stage : stages)
            shaders.push_back(compile(name, stage));
    } catch (...) {
        for (GLuint sh : shaders)
            glDeleteShader(sh);
        throw;
    }
    for (GLuint sh : shaders)
        glAttachShader(program.get(), sh);
    glLinkProgram(program.get());
    for (GLuint sh : shaders)
        glDeleteShader(sh);
    GLint ok = 0;
    glGetProgramiv(program.get(), GL_LINK_STATUS, &ok);
    if (!ok) {
        GLint length = 0;
        glGetProgramiv(program.get(), GL_INFO_LOG_LENGTH, &length);
        std::vector<char> log(std::size_t(length) + 1, '\0');
        glGetProgramInfoLog(program.get(), length, nullptr, log.data());
        throw RenderError("shader " + name + " does not link: " + log.data());
    }
    glCheck(("building shader " + name).c_str());
    return program;
}

} // namespace bc::render::gl
