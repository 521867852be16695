#include "render/EglContext.h"

#include "render/Error.h"
#include "render/RendererChoice.h"
#include "render/detail/Gl.h"

#include <EGL/egl.h>
#include <EGL/eglext.h>

#include <cstdio>
#include <cstring>
#include <vector>

namespace bc::render {
namespace {

const char* eglErrorName(EGLint e) {
    switch (e) {
    case EGL_SUCCESS:
        return "EGL_SUCCESS";
    case EGL_NOT_INITIALIZED:
        return "EGL_NOT_INITIALIZED";
    case EGL_BAD_ACCESS:
        return "EGL_BAD_ACCESS";
    case EGL_BAD_ALLOC:
        return "EGL_BAD_ALLOC";
    case EGL_BAD_ATTRIBUTE:
        return "EGL_BAD_ATTRIBUTE";
    case EGL_BAD_CONFIG:
        return "EGL_BAD_CONFIG";
    case EGL_BAD_CONTEXT:
        return "EGL_BAD_CONTEXT";
    case EGL_BAD_DISPLAY:
        return "EGL_BAD_DISPLAY";
    case EGL_BAD_MATCH:
        return "EGL_BAD_MATCH";
    case EGL_BAD_PARAMETER:
        return "EGL_BAD_PARAMETER";
    default:
        return "EGL error";
    }
}

/// The one translation of EGL failures into text.
std::string eglFailure(const char* what) {
    char buf[128];
    EGLint e = eglGetError();
    std::snprintf(buf, sizeof buf, "%s failed (%s 0x%x)", what, eglErrorName(e), unsigned(e));
    return buf;
}

bool hasExtension(const char* list, const char* name) {
    if (!list) return false;
    const std::size_t n = std::strlen(name);
    for (const char* p = list; (p = std::strstr(p, name)); p += n)
        if ((p == list || p[-1] == ' ') && (p[n] == ' ' || p[n] == '\0')) return true;
    return false;
}

template <class F> F eglProc(const char* name) {
    return reinterpret_cast<F>(eglGetProcAddress(name));
}

void APIENTRY debugCallback(GLenum, GLenum type, GLuint, GLenum severity, GLsizei,
                            const GLchar* message, const void*) {
    if (severity == GL_DEBUG_SEVERITY_NOTIFICATION) return;
    std::fprintf(stderr, "GL debug (type 0x%x): %s\n", unsigned(type), message);
}

} // namespace

struct EglContext::Impl {
    EGLDisplay display = EGL_NO_DISPLAY;
    EGLContext context = EGL_NO_CONTEXT;

    /// Initialises `d` and creates a current 4.5 core context on it; false (and cleans up) if not.
    bool tryDisplay(EGLDisplay d, std::string& log) {
        if (d == EGL_NO_DISPLAY) return false;
        EGLint major = 0, minor = 0;
        if (!eglInitialize(d, &major, &minor)) {
            log += eglFailure("eglInitialize") + "; ";
            return false;
        }
        const char* exts = eglQueryString(d, EGL_EXTENSIONS);
        if (!hasExtension(exts, "EGL_KHR_surfaceless_context") || !eglBindAPI(EGL_OPENGL_API)) {
            log += "display lacks surfaceless OpenGL; ";
            eglTerminate(d);
            return false;
        }
        EGLConfig config = EGL_NO_CONFIG_KHR;
        if (!hasExtension(exts, "EGL_KHR_no_config_context")) {
            const EGLint want[] = {EGL_RENDERABLE_TYPE, EGL_OPENGL_BIT, EGL_NONE};
            EGLint count = 0;
            if (!eglChooseConfig(d, want, &config, 1, &count) || count == 0) {
                log += eglFailure("eglChooseConfig") + "; ";
                eglTerminate(d);
                return false;
            }
        }
        const EGLint attribs[] = {EGL_CONTEXT_MAJOR_VERSION,
                                  4,
                                  EGL_CONTEXT_MINOR_VERSION,
                                  5,
                                  EGL_CONTEXT_OPENGL_PROFILE_MASK,
                                  EGL_CONTEXT_OPENGL_CORE_PROFILE_BIT,
                                  EGL_NONE};
        EGLContext c = eglCreateContext(d, config, EGL_NO_CONTEXT, attribs);
        if (c == EGL_NO_CONTEXT || !eglMakeCurrent(d, EGL_NO_SURFACE, EGL_NO_SURFACE, c)) {
            log += eglFailure("OpenGL 4.5 core context") + "; ";
            if (c != EGL_NO_CONTEXT) eglDestroyContext(d, c);
            eglTerminate(d);
            return false;
        }
        display = d;
        context = c;
        return true;
    }

    /// EGL devices (EGL_EXT_device_enumeration), hardware ones first when asked.
    bool tryDevices(bool preferHardware, std::string& platform, std::string& log) {
        auto queryDevices = eglProc<PFNEGLQUERYDEVICESEXTPROC>("eglQueryDevicesEXT");
        auto queryString = eglProc<PFNEGLQUERYDEVICESTRINGEXTPROC>("eglQueryDeviceStringEXT");
        auto platformDisplay = eglProc<PFNEGLGETPLATFORMDISPLAYEXTPROC>("eglGetPlatformDisplayEXT");
        if (!queryDevices || !queryString || !platformDisplay) {
            log += "no EGL device enumeration; ";
            return false;
        }
        EGLDeviceEXT devices[16];
        EGLint count = 0;
        if (!queryDevices(16, devices, &count)) return false;
        for (int pass = 0; pass < 2; ++pass) {
            const bool wantSoftware = (pass == 0) != preferHardware;
            for (EGLint i = 0; i < count; ++i) {
                const bool software = hasExtension(queryString(devices[i], EGL_EXTENSIONS),
                                                   "EGL_MESA_device_software");
                if (software != wantSoftware) continue;
                if (tryDisplay(platformDisplay(EGL_PLATFORM_DEVICE_EXT, devices[i], nullptr),
                               log)) {
                    platform = "device " + std::to_string(i) + (software ? " (software)" : "");
                    return true;
                }
            }
        }
        return false;
    }

    bool trySurfaceless(std::string& platform, std::string& log) {
        auto platformDisplay = eglProc<PFNEGLGETPLATFORMDISPLAYEXTPROC>("eglGetPlatformDisplayEXT");
        if (!platformDisplay) return false;
        if (!tryDisplay(
                platformDisplay(EGL_PLATFORM_SURFACELESS_MESA, EGL_DEFAULT_DISPLAY, nullptr), log))
            return false;
        platform = "surfaceless";
        return true;
    }

    ~Impl() {
        if (display == EGL_NO_DISPLAY) return;
        eglMakeCurrent(display, EGL_NO_SURFACE, EGL_NO_SURFACE, EGL_NO_CONTEXT);
        eglDestroyContext(display, context);
        eglTerminate(display);
    }
};

EglContext::EglContext(const EglContextConfig& config) : mImpl(std::make_unique<Impl>()) {
    std::string log;
    if (!mImpl->tryDevices(config.preferHardware, mPlatform, log) &&
        !mImpl->trySurfaceless(mPlatform, log)) {
        if (!mImpl->tryDisplay(eglGetDisplay(EGL_DEFAULT_DISPLAY), log))
            throw RenderError(
                "no usable EGL: no OpenGL 4.5 core context on any EGL device, the surfaceless "
                "platform or the default display (" +
                log + ")");
        mPlatform = "default display";
    }
    auto text = [](GLenum name) {
        const GLubyte* s = glGetString(name);
        return s ? std::string(reinterpret_cast<const char*>(s)) : std::string("?");
    };
    mRenderer = text(GL_RENDERER);
    mVendor = text(GL_VENDOR);
    mVersion = text(GL_VERSION);
    if (config.debugOutput) {
        glEnable(GL_DEBUG_OUTPUT);
        glDebugMessageCallback(debugCallback, nullptr);
    }
}

EglContext::~EglContext() = default;

bool EglContext::software() const {
    return isSoftwareRasterizer(mRenderer, mVendor);
}

} // namespace bc::render
