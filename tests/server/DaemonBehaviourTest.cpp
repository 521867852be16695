// What the daemon does beyond answering: camera updates coalesce, adaptive quality sends
// interactive frames while the camera moves and one refined frame when it rests, sessions
// share a volume's cache with fair budget shares, and a trickling client is cut. (SIGTERM
// draining a real brickcastd process: tests/tools/DaemonProcessTest.cpp.)
#include "ServerTestSupport.h"

#include "server/Catalog.h"

namespace bc::server::test {
namespace {

class DaemonBehaviour : public ::testing::Test {
  protected:
    static void SetUpTestSuite() {
        sDir = new TempDir;
        DaemonConfig c = generatedConfig(*sDir, {{"small", 32}, {"other", 24}});
        c.readTimeoutMs = 400;
        c.restMs = 500; // far above a 64^2 frame here, even on a loaded CI machine
        sDaemon = new TestDaemon(c);
    }
    static void TearDownTestSuite() {
        delete sDaemon;
        delete sDir;
    }
    static TempDir* sDir;
    static TestDaemon* sDaemon;
};
TempDir* DaemonBehaviour::sDir = nullptr;
TestDaemon* DaemonBehaviour::sDaemon = nullptr;

TEST_F(DaemonBehaviour, CameraUpdatesCoalesceAndTheFrameAnswersTheLatest) {
    client::Client c(sDaemon->clientConfig());
    const auto v = c.openVolume("small");
    c.setRenderOptions(smallCpuFrames(200)); // slow enough that cameras pile up behind a frame
    c.requestFrame(protocol::FrameMode::ContinuousOn);
    for (std::uint32_t i = 1; i <= 40; ++i)
        c.setCamera(orbitCamera(v, 3.0 * i, i));
    std::vector<std::uint32_t> answered;
    while (answered.empty() || answered.back() != 40)
        answered.push_back(c.nextFrame().header.cameraId);
    c.requestFrame(protocol::FrameMode::ContinuousOff);
    std::printf("[coalesce] 40 cameras answered by %zu frames\n", answered.size());
    EXPECT_LT(answered.size(), 40u) << "every camera was drawn: nothing coalesced";
    EXPECT_TRUE(std::is_sorted(answered.begin(), answered.end()))
        << "an older view after a newer one";
}

TEST_F(DaemonBehaviour, MovingCameraGetsInteractiveFramesThenOneRefinedFrameAtRest) {
    client::Client c(sDaemon->clientConfig());
    const auto v = c.openVolume("small");
    auto o = smallCpuFrames(64);
    o.quality = protocol::Quality::Adaptive;
    c.setRenderOptions(o);
    c.requestFrame(protocol::FrameMode::ContinuousOn);
    int interactive = 0;
    for (std::uint32_t i = 1; i <= 5; ++i) { // one camera a frame, faster than the rest interval
        c.setCamera(orbitCamera(v, 10.0 * i, i));
        auto f = c.nextFrame();
        while (f.header.cameraId != i)
            f = c.nextFrame();
        interactive += !f.header.refined;
    }
    const auto rest = c.nextFrame(); // nothing sent: the refined frame follows rest_ms later
    c.requestFrame(protocol::FrameMode::ContinuousOff);
    EXPECT_GE(interactive, 4) << "frames while moving should be interactive";
    EXPECT_TRUE(rest.header.refined);
    EXPECT_EQ(rest.header.cameraId, 5u);
}

TEST_F(DaemonBehaviour, SessionsOnOneVolumeShareItsCacheAndBudgetsFollowTheSessions) {
    client::Client a(sDaemon->clientConfig()), b(sDaemon->clientConfig());
    const auto v = a.openVolume("small");
    b.openVolume("small");
    double azDeg = 10;
    for (auto* c : {&a, &b}) { // views of their own: the same view would be the frame cache's
        c->setRenderOptions(smallCpuFrames(48));
        c->setCamera(orbitCamera(v, azDeg, 1));
        c->requestFrame();
        c->nextFrame();
        azDeg += 2;
    }
    auto counter = [](const std::vector<std::pair<std::string, double>>& s, const std::string& k) {
        for (const auto& [name, value] : s)
            if (name == k) return value;
        return -1.0;
    };
    const auto s = b.stats();
    EXPECT_GT(counter(s, "host_cache_hits_total{volume=\"small\"}"), 0)
        << "the second session loaded its own bricks";
    // Budgets: a catalog of two volumes, three leases on one and one on the other.
    Log quiet(true);
    DaemonConfig config = generatedConfig(*sDir, {{"small", 32}, {"other", 24}});
    config.hostBudgetBytes = 400ull << 20;
    Catalog catalog(config, quiet);
    auto l1 = catalog.lease("small"), l2 = catalog.lease("small"), l3 = catalog.lease("small");
    auto l4 = catalog.lease("other");
    EXPECT_FALSE(catalog.lease("missing"));
    EXPECT_EQ(catalog.sessions(), 4u);
    EXPECT_EQ(catalog.shareOf(*l1.volume(), 400), 300u);
    EXPECT_EQ(catalog.shareOf(*l4.volume(), 400), 100u);
    l2 = {};
    l3 = {};
    EXPECT_EQ(catalog.shareOf(*l1.volume(), 400), 200u) << "a released lease gives its share back";
}

TEST_F(DaemonBehaviour, AClientThatTricklesBytesIsTimedOut) {
    RawConnection c(sDaemon->port);
    c.handshake("");
    const auto bytes = protocol::encode(protocol::OpenVolume{"small"}, 3);
    // A byte every 100 ms, each well inside any per-read timeout, but the message as a whole
    // past the 400 ms read deadline; the last byte is never sent, so only the deadline ends it.
    std::optional<protocol::Message> reply;
    for (std::size_t i = 0; i + 1 < bytes.size() && !reply; ++i) {
        c.send(std::vector<std::uint8_t>{bytes[i]});
        reply = c.next(100);
    }
    if (!reply) reply = c.next(10000);
    ASSERT_TRUE(reply) << "a message trickled for " << (bytes.size() - 1) * 100
                       << " ms was not cut";
    auto* e = std::get_if<protocol::Error>(&*reply);
    ASSERT_TRUE(e);
    EXPECT_EQ(e->code, protocol::ErrorCode::Timeout);
    EXPECT_TRUE(c.closedByPeer());
}

} // namespace
} // namespace bc::server::test
