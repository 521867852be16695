// `auto`: the GL renderer strings it takes for software rasterisers and for hardware GPUs, the
// reasons it gives, and its choice on this machine's EGL context.
#include "render/RendererChoice.h"
#include "RenderTestSupport.h"

#include <gtest/gtest.h>

namespace bc::render {
namespace {

TEST(RendererChoice, SoftwareRasterisersAreNamedByRendererOrVendor) {
    for (const char* renderer :
         {"llvmpipe (LLVM 15.0.6, 256 bits)", "llvmpipe (LLVM 12.0.0, 128 bits)", "softpipe",
          "Gallium 0.4 on softpipe", "Mesa X11 swrast", "swrast", "zink (llvmpipe (LLVM 15.0.6))",
          "Google SwiftShader", "SwiftShader Device (Subzero)",
          "ANGLE (Google, Vulkan 1.3.0 "
          "(SwiftShader Device (Subzero) (0x0000C0DE)), SwiftShader driver)",
          "Apple Software Renderer", "Software Rasterizer", "GDI Generic",
          "Microsoft Basic Render Driver", "LLVMPIPE"})
        EXPECT_TRUE(isSoftwareRasterizer(renderer, "Mesa")) << renderer;
    EXPECT_TRUE(isSoftwareRasterizer("Generic", "Software Rasterizer Inc."));
}

TEST(RendererChoice, HardwareGpusAreNotSoftware) {
    for (const char* renderer :
         {"NVIDIA H200/PCIe/SSE2", "NVIDIA GeForce RTX 4090/PCIe/SSE2", "AMD Radeon RX 7900 XTX",
          "AMD Radeon Graphics (radeonsi, gfx1103_r1, LLVM 15.0.7, DRM 3.54, 6.5.0)",
          "Mesa Intel(R) UHD Graphics 630 (CFL GT2)", "Mesa Intel(R) Arc(tm) A770 Graphics (DG2)",
          "Apple M2", "Tesla T4/PCIe/SSE2", "virgl"})
        EXPECT_FALSE(isSoftwareRasterizer(renderer, "NVIDIA Corporation")) << renderer;
    EXPECT_FALSE(isSoftwareRasterizer("", ""));
}

TEST(RendererChoice, AutoPicksTheCpuRaycasterOnASoftwareRasteriserAndSaysWhy) {
    EXPECT_EQ(chooseAuto("llvmpipe (LLVM 15.0.6, 256 bits)", "Mesa"),
              (RendererChoice{"cpu", "auto: cpu (GL_RENDERER 'llvmpipe (LLVM 15.0.6, 256 bits)' "
                                     "is a software rasteriser)"}));
    EXPECT_EQ(chooseAuto("NVIDIA H200/PCIe/SSE2", "NVIDIA Corporation"),
              (RendererChoice{"gpu", "auto: gpu (GL_RENDERER 'NVIDIA H200/PCIe/SSE2' is a "
                                     "hardware GPU)"}));
    EXPECT_EQ(chooseAuto("Generic", "SwiftShader").name, "cpu");
    EXPECT_EQ(chooseAutoWithoutGl("no usable EGL: ..."),
              (RendererChoice{"cpu", "auto: cpu (no EGL context: no usable EGL: ...)"}));
}

TEST(RendererChoice, ANamedRendererIsTakenAsAskedWithoutAContext) {
    std::unique_ptr<EglContext> context;
    for (const char* name : {"gpu", "cpu", "splat", "splat-gpu", "reference"}) {
        EXPECT_EQ(resolveRenderer(name, context),
                  (RendererChoice{name, "asked for " + std::string(name)}));
        EXPECT_EQ(context, nullptr) << name << ": no EGL context is made for a named renderer";
    }
}

// GL: this machine's context. On llvmpipe (the dev VM, CI) auto is the CPU raycaster.
TEST(RendererChoiceGl, AutoOnThisMachineFollowsItsGlRenderer) {
    const EglContext& gl = test::glContext();
    const RendererChoice choice = chooseAuto(gl.renderer(), gl.vendor());
    std::printf("[gl] %s (GL_VENDOR '%s')\n", choice.reason.c_str(), gl.vendor().c_str());
    EXPECT_EQ(choice.name, gl.software() ? "cpu" : "gpu");
    EXPECT_NE(choice.reason.find("GL_RENDERER '" + gl.renderer() + "'"), std::string::npos);
    if (gl.renderer().find("llvmpipe") != std::string::npos) {
        EXPECT_EQ(choice.reason,
                  "auto: cpu (GL_RENDERER '" + gl.renderer() + "' is a software rasteriser)");
    }
}

} // namespace
} // namespace bc::render
