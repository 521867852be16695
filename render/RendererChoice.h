#pragma once
// `auto`, the default renderer: the GPU raycaster on a hardware GPU, the CPU raycaster where
// the only OpenGL is a software rasteriser (Mesa's llvmpipe draws the GPU raycaster's frames
// 3-10x slower than the CPU raycaster on the same cores) or where no EGL context can be made.
// Decided once from the GL_RENDERER and GL_VENDOR of an EGL context, never per frame.
#include <memory>
#include <string>
#include <string_view>

namespace bc::render {

class EglContext;

/// The name that asks for the choice below ("auto").
inline constexpr std::string_view kAutoRenderer = "auto";

/// True when GL_RENDERER or GL_VENDOR names a software rasteriser: llvmpipe, softpipe, swrast,
/// SwiftShader, a "Software Rasterizer" or "Software Renderer" (Apple's, Microsoft's Basic
/// Render Driver, GDI Generic). Case-insensitive.
bool isSoftwareRasterizer(std::string_view glRenderer, std::string_view glVendor = {});

/// A renderer of the registry and why it draws.
struct RendererChoice {
    std::string name; ///< the registry's name ("gpu", "cpu", ...), never "auto"
    /// For the log and the frame stats, e.g. "auto: cpu (GL_RENDERER 'llvmpipe (LLVM 15.0.6,
    /// 256 bits)' is a software rasteriser)", or "asked for cpu".
    std::string reason;
    bool operator==(const RendererChoice&) const = default;
};

/// auto's choice on an OpenGL context that names itself so.
RendererChoice chooseAuto(std::string_view glRenderer, std::string_view glVendor);
/// auto's choice where no EGL context could be made (`why`): the CPU raycaster.
RendererChoice chooseAutoWithoutGl(std::string_view why);

/// `name` as asked ("asked for NAME"), or for "auto" the choice above: makes an EglContext
/// into `context` when it holds none (this thread's, DESIGN.md), keeps it when the GPU
/// raycaster is chosen and releases it otherwise (the CPU raycaster needs none).
/// Never throws for want of EGL: that chooses the CPU raycaster.
RendererChoice resolveRenderer(std::string_view name, std::unique_ptr<EglContext>& context);

} // namespace bc::render
