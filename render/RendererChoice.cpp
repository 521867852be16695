#include "render/RendererChoice.h"

#include "render/EglContext.h"

#include <algorithm>
#include <cctype>
#include <exception>
#include <iterator>

namespace bc::render {
namespace {

std::string lower(std::string_view s) {
    std::string out(s);
    std::transform(out.begin(), out.end(), out.begin(),
                   [](unsigned char c) { return char(std::tolower(c)); });
    return out;
}

bool namesSoftware(std::string_view text) {
    // Mesa's (llvmpipe, softpipe, swrast; zink on lavapipe reports "zink (llvmpipe ...)"),
    // Google's SwiftShader, Apple's "Software Renderer", Microsoft's Basic Render Driver and
    // GDI Generic, and any other "Software Rasterizer".
    static constexpr std::string_view kSoftware[] = {"llvmpipe",
                                                     "softpipe",
                                                     "swrast",
                                                     "swiftshader",
                                                     "software rasterizer",
                                                     "software rasteriser",
                                                     "software renderer",
                                                     "basic render",
                                                     "gdi generic"};
    const std::string l = lower(text);
    return std::any_of(std::begin(kSoftware), std::end(kSoftware),
                       [&](std::string_view s) { return l.find(s) != std::string::npos; });
}

} // namespace

bool isSoftwareRasterizer(std::string_view glRenderer, std::string_view glVendor) {
    return namesSoftware(glRenderer) || namesSoftware(glVendor);
}

RendererChoice chooseAuto(std::string_view glRenderer, std::string_view glVendor) {
    const std::string renderer = "GL_RENDERER '" + std::string(glRenderer) + "'";
    if (namesSoftware(glRenderer))
        return {"cpu", "auto: cpu (" + renderer + " is a software rasteriser)"};
    if (namesSoftware(glVendor))
        return {"cpu", "auto: cpu (" + renderer + " of GL_VENDOR '" + std::string(glVendor) +
                           "' is a software rasteriser)"};
    return {"gpu", "auto: gpu (" + renderer + " is a hardware GPU)"};
}

RendererChoice chooseAutoWithoutGl(std::string_view why) {
    return {"cpu", "auto: cpu (no EGL context: " + std::string(why) + ")"};
}

RendererChoice resolveRenderer(std::string_view name, std::unique_ptr<EglContext>& context) {
    if (name != kAutoRenderer) return {std::string(name), "asked for " + std::string(name)};
    if (!context) {
        try {
            context = std::make_unique<EglContext>();
        } catch (const std::exception& e) {
            return chooseAutoWithoutGl(e.what());
        }
    }
    RendererChoice choice = chooseAuto(context->renderer(), context->vendor());
    if (choice.name != "gpu") context.reset();
    return choice;
}

} // namespace bc::render
