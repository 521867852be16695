// Derived state is committed once: sessions viewing one volume under one transfer
// function share one classification (TF table and per-brick octrees), counted by the daemon's
// classification_builds_total and held once in host memory.
#include "ServerTestSupport.h"

namespace bc::server::test {
namespace {

class SharedClassification : public ::testing::Test {
  protected:
    void SetUp() override {
        DaemonConfig c = generatedConfig(dir, {{"phantom", 96}});
        c.metricsHost = "127.0.0.1";
        c.metricsPort = 0;
        c.maxClients = 20;
        daemon = std::make_unique<TestDaemon>(c);
        port = daemon->daemon->metricsPort();
    }
    double metric(const std::string& name) {
        const std::string reply = scrape(port, "GET /metrics HTTP/1.1\r\nHost: 127.0.0.1\r\n\r\n");
        return sampleOf(reply.substr(reply.find("\r\n\r\n") + 4), "brickcast_" + name);
    }
    /// One frame under preset `tf` from `c` (a new camera each time).
    void frameWith(client::Client& c, const std::string& tf, std::uint32_t cameraId) {
        protocol::SetTransferFunction m;
        m.preset = tf;
        c.setTransferFunction(m);
        c.setCamera(orbitCamera(volume, 10.0 * cameraId, cameraId));
        c.requestFrame();
        const auto f = c.nextFrame();
        EXPECT_EQ(f.header.cameraId, cameraId);
    }

    TempDir dir;
    std::unique_ptr<TestDaemon> daemon;
    std::uint16_t port = 0;
    protocol::VolumeInfo volume;
};

TEST_F(SharedClassification, SixteenSessionsUnderOneTransferFunctionBuildItOnce) {
    std::vector<std::unique_ptr<client::Client>> sessions;
    for (int i = 0; i < 16; ++i) {
        sessions.push_back(std::make_unique<client::Client>(daemon->clientConfig()));
        volume = sessions.back()->openVolume("phantom");
        sessions.back()->setRenderOptions(smallCpuFrames(32));
    }
    frameWith(*sessions[0], "ct-bone", 1);
    EXPECT_EQ(metric("classification_builds_total"), 1);
    const double oneCopy = metric("classification_bytes");
    EXPECT_GT(oneCopy, 0);
    for (std::uint32_t i = 1; i < 16; ++i)
        frameWith(*sessions[i], "ct-bone", i + 1);
    EXPECT_EQ(metric("classification_builds_total"), 1) << "one build for 16 sessions";
    EXPECT_EQ(metric("classifications"), 1);
    EXPECT_EQ(metric("classification_bytes"), oneCopy) << "octrees held once";
    EXPECT_GE(metric("classification_hits_total"), 15);

    frameWith(*sessions[3], "ct-bone", 40); // the same function again builds nothing
    EXPECT_EQ(metric("classification_builds_total"), 1);

    for (std::uint32_t i = 0; i < 16; ++i) // a new function: built once, for all of them
        frameWith(*sessions[i], "ct-skin", 50 + i);
    EXPECT_EQ(metric("classification_builds_total"), 2);
    EXPECT_GT(metric("classification_bricks_rebuilt_total"), 0);
}

} // namespace
} // namespace bc::server::test
