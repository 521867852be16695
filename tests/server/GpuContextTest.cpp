// The render thread makes its OpenGL context when the first GPU frame asks for one, never
// before: a daemon that draws on the CPU only never loads the GL driver (and its leaks).
// (The path where EGL is unavailable is tests/tools/DaemonProcessTest.cpp: it needs a process
// of its own, started with no EGL vendor.)
#include "ServerTestSupport.h"

namespace bc::server::test {
namespace {

TEST(GpuContext, ADaemonThatDrawsOnTheCpuOnlyNeverMakesAGlContext) {
    TempDir dir;
    DaemonConfig config = generatedConfig(dir, {{"p", 32}});
    config.metricsHost = "127.0.0.1";
    config.metricsPort = 0;
    TestDaemon daemon(config);
    client::Client c(daemon.clientConfig());
    // Nothing is known against the GPU renderers: announced (their first frame makes the
    // context, or says why it cannot).
    EXPECT_TRUE(c.server().capabilities & protocol::kCapGpuRenderer);
    const auto v = c.openVolume("p");
    for (auto renderer : {protocol::Renderer::CpuRaycaster, protocol::Renderer::Splatter,
                          protocol::Renderer::Reference}) {
        auto options = smallCpuFrames(32);
        options.renderer = renderer;
        c.setRenderOptions(options);
        c.setCamera(orbitCamera(v, 10, 1));
        c.requestFrame();
        c.nextFrame();
    }
    const std::string metrics =
        scrape(daemon.daemon->metricsPort(), "GET /metrics HTTP/1.1\r\n\r\n");
    EXPECT_EQ(sampleOf(metrics, "brickcast_gpu_context"), 0.0)
        << "the render thread made a GL context nobody asked for";
}

} // namespace
} // namespace bc::server::test
