// `auto` in the daemon: decided once, at the first frame that asks for it, from the render
// thread's OpenGL context. A session asking for auto gets the frames of the raycaster chosen
// (on llvmpipe, the dev VM and CI: the CPU raycaster's, byte for byte), and the metrics and
// the frame counters say which and why. (Without EGL at all: tests/tools/DaemonProcessTest.cpp.)
#include "ServerTestSupport.h"

#include <sstream>

namespace bc::server::test {
namespace {

/// The renderer and reason labels of brickcast_auto_renderer in `metrics`, empty when absent.
std::pair<std::string, std::string> autoRendererOf(const std::string& metrics) {
    const std::string prefix = "brickcast_auto_renderer{renderer=\"";
    std::istringstream in(metrics);
    for (std::string line; std::getline(in, line);) {
        if (!line.starts_with(prefix)) continue;
        const std::size_t nameEnd = line.find('"', prefix.size());
        const std::size_t reasonStart = line.find("reason=\"", nameEnd) + 8;
        const std::size_t reasonEnd = line.rfind("\"}");
        return {line.substr(prefix.size(), nameEnd - prefix.size()),
                line.substr(reasonStart, reasonEnd - reasonStart)};
    }
    return {};
}

std::vector<client::ReceivedFrame> twoFrames(client::Client& c, const protocol::VolumeInfo& v,
                                             protocol::Renderer renderer) {
    auto options = smallCpuFrames(40);
    options.renderer = renderer;
    c.setRenderOptions(options);
    std::vector<client::ReceivedFrame> out;
    for (std::uint32_t f = 1; f <= 2; ++f) {
        c.setCamera(orbitCamera(v, 25.0 * f, f));
        c.requestFrame();
        out.push_back(c.nextFrame());
    }
    return out;
}

TEST(AutoRenderer, ASessionAskingForAutoGetsTheChosenRaycastersFramesAndTheMetricsSayWhy) {
    TempDir dir;
    DaemonConfig config = generatedConfig(dir, {{"p", 32}});
    config.metricsHost = "127.0.0.1";
    config.metricsPort = 0;
    config.frameCacheBytes = 0; // every frame below is drawn, and counted as drawn
    TestDaemon daemon(config);
    auto metrics = [&] {
        return scrape(daemon.daemon->metricsPort(), "GET /metrics HTTP/1.1\r\n\r\n");
    };
    EXPECT_EQ(autoRendererOf(metrics()).first, "") << "decided before a session asked for it";
    client::Client automatic(daemon.clientConfig()), named(daemon.clientConfig());
    const auto v = automatic.openVolume("p");
    named.openVolume("p");
    EXPECT_EQ(protocol::RenderOptions{}.renderer, protocol::Renderer::Auto) << "the default";
    const auto autoFrames = twoFrames(automatic, v, protocol::Renderer::Auto);

    const auto [chosen, reason] = autoRendererOf(metrics());
    std::printf("[auto] %s\n", reason.c_str());
    ASSERT_TRUE(chosen == "cpu" || chosen == "gpu") << "'" << chosen << "'";
    EXPECT_TRUE(reason.starts_with("auto: " + chosen + " (")) << reason;
    if (reason.find("llvmpipe") != std::string::npos ||
        reason.find("no EGL") != std::string::npos) {
        EXPECT_EQ(chosen, "cpu") << reason;
    }
    const std::string text = metrics();
    EXPECT_EQ(sampleOf(text, "brickcast_frames_total{renderer=\"" + chosen + "\"}"), 2.0);
    EXPECT_EQ(sampleOf(text, std::string("brickcast_frames_total{renderer=\"") +
                                 (chosen == "cpu" ? "gpu" : "cpu") + "\"}"),
              0.0);

    const auto namedFrames = twoFrames(named, v,
                                       chosen == "cpu" ? protocol::Renderer::CpuRaycaster
                                                       : protocol::Renderer::GpuRaycaster);
    for (std::size_t i = 0; i < autoFrames.size(); ++i) {
        EXPECT_EQ(autoFrames[i].header.cameraId, namedFrames[i].header.cameraId);
        EXPECT_EQ(autoFrames[i].header.samples, namedFrames[i].header.samples);
        EXPECT_TRUE(autoFrames[i].rgba == namedFrames[i].rgba)
            << "frame " << i << ": auto's frame is not " << chosen << "'s";
    }
    // Decided once: a third session asking for auto does not decide again.
    client::Client again(daemon.clientConfig());
    again.openVolume("p");
    twoFrames(again, v, protocol::Renderer::Auto);
    EXPECT_EQ(autoRendererOf(metrics()), std::make_pair(chosen, reason));
    EXPECT_EQ(sampleOf(metrics(), "brickcast_frames_total{renderer=\"" + chosen + "\"}"), 6.0);
}

} // namespace
} // namespace bc::server::test
