#pragma once
// A headless OpenGL 4.5 core context through EGL: the EGL device platform first (a real GPU
// where one is present), Mesa's surfaceless platform (llvmpipe) otherwise. The context is
// current on the thread that created it and belongs to that thread (DESIGN.md).
#include <memory>
#include <string>

namespace bc::render {

struct EglContextConfig {
    bool preferHardware = true; ///< try non-software EGL devices before Mesa's software one
    bool debugOutput = false;   ///< GL_KHR_debug messages to stderr
};

class EglContext {
  public:
    /// Creates the context and makes it current on this thread.
    /// @throw RenderError with what was tried when no platform gives an OpenGL 4.5 core context.
    explicit EglContext(const EglContextConfig& config = {});
    ~EglContext();
    EglContext(const EglContext&) = delete;
    EglContext& operator=(const EglContext&) = delete;

    /// GL_RENDERER, e.g. "llvmpipe (LLVM 15.0.6, 256 bits)" or "NVIDIA H100 ...".
    const std::string& renderer() const { return mRenderer; }
    /// GL_VENDOR, e.g. "Mesa" or "NVIDIA Corporation".
    const std::string& vendor() const { return mVendor; }
    /// GL_VERSION.
    const std::string& version() const { return mVersion; }
    /// Which EGL path succeeded: "device N", "surfaceless", or "default display".
    const std::string& platform() const { return mPlatform; }
    /// True for a software rasteriser (Mesa's llvmpipe, softpipe...: isSoftwareRasterizer).
    bool software() const;

  private:
    struct Impl;
    std::unique_ptr<Impl> mImpl;
    std::string mRenderer, mVendor, mVersion, mPlatform;
};

} // namespace bc::render
