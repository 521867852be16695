#pragma once
// OpenGL for the render module's own sources: the core-profile prototypes (GLVND's
// libOpenGL), move-only owners of GL objects, and the one place GL errors become exceptions.
// Every object is created and destroyed on the thread that owns the context.
#define GL_GLEXT_PROTOTYPES 1
#include <GL/glcorearb.h>

#include <string>
#include <utility>
#include <vector>

namespace bc::render::gl {

/// Throws RenderError naming `what` if glGetError reports anything (clears all pending errors).
void glCheck(const char* what);

/// Move-only owner of one GL name; Deleter is a function deleting one name.
template <void (*Deleter)(GLuint)> class Handle {
  public:
    Handle() = default;
    explicit Handle(GLuint name) : mName(name) {}
    Handle(Handle&& o) noexcept : mName(std::exchange(o.mName, 0)) {}
    Handle& operator=(Handle&& o) noexcept {
        if (this != &o) {
            reset();
            mName = std::exchange(o.mName, 0);
        }
        return *this;
    }
    Handle(const Handle&) = delete;
    Handle& operator=(const Handle&) = delete;
    ~Handle() { reset(); }
    GLuint get() const { return mName; }
    explicit operator bool() const { return mName != 0; }
    void reset() {
        if (mName) Deleter(mName);
        mName = 0;
    }

  private:
    GLuint mName = 0;
};

void deleteTexture(GLuint n);
void deleteBuffer(GLuint n);
void deleteFramebuffer(GLuint n);
void deleteVertexArray(GLuint n);
void deleteProgram(GLuint n);

using Texture = Handle<deleteTexture>;
using Buffer = Handle<deleteBuffer>;
using Framebuffer = Handle<deleteFramebuffer>;
using VertexArray = Handle<deleteVertexArray>;
using Program = Handle<deleteProgram>;

Texture createTexture(GLenum target);
Buffer createBuffer();

struct ShaderStage {
    GLenum type; ///< GL_VERTEX_SHADER, GL_GEOMETRY_SHADER, GL_FRAGMENT_SHADER, GL_COMPUTE_SHADER
    std::string source;
    std::string file; ///< the render/shaders file it comes from, for error messages
};

/// Compiles and links a program from its stages (vertex + fragment, + geometry, or compute).
/// @throw RenderError with the driver's log (which gives the line), naming `name` and the
/// failing stage's file.
Program buildProgram(const std::string& name, const std::vector<ShaderStage>& stages);

} // namespace bc::render::gl
