// The browser viewer's address: the embedded files and nothing else over HTTP, and
// the protocol over WebSocket as one more transport of the same sessions. Every piece of bad
// input tested below ends only the connection that sent it: a witness WebSocket
// session and a witness TCP client keep being answered after each.
#include "WebTestSupport.h"

#include "protocol/FrameCodec.h"
#include "render/TransferFunction.h"
#include "server/detail/WebAssets.h"
#include "server/detail/WebSocketTransport.h"

#include <boost/asio.hpp>
#include <boost/beast/core.hpp>
#include <boost/beast/websocket.hpp>
#include <nlohmann/json.hpp>

#include <atomic>

namespace bc::server::test {
namespace {

class WebViewer : public ::testing::Test {
  protected:
    static void SetUpTestSuite() {
        sDir = new TempDir;
        DaemonConfig c = generatedConfig(*sDir, {{"phantom", 48}});
        c.handshakeTimeoutMs = 1000;
        c.writeTimeoutMs = 1500;
        c.maxClients = 8;
        sDaemon = new TestDaemon(c);
        sPort = sDaemon->daemon->webPort();
    }
    static void TearDownTestSuite() {
        delete sDaemon;
        delete sDir;
    }
    void SetUp() override {
        ASSERT_NE(sPort, 0) << "the viewer is served by default (web = \"auto\")";
        mWitness = std::make_unique<WsClient>(sPort);
        mWitness->handshake();
        mTcpWitness = std::make_unique<client::Client>(sDaemon->clientConfig());
    }
    /// Both witnesses are still answered.
    void expectOthersServed(const std::string& after) {
        SCOPED_TRACE("after " + after);
        mWitness->send(protocol::ListVolumes{}, 9);
        EXPECT_EQ(mWitness->expect<protocol::VolumeList>().volumes.size(), 1u);
        EXPECT_EQ(mTcpWitness->listVolumes().size(), 1u);
        EXPECT_EQ(statusOf(scrape(sPort, get("/presets.json"))), 200);
    }

    static inline TempDir* sDir = nullptr;
    static inline TestDaemon* sDaemon = nullptr;
    static inline std::uint16_t sPort = 0;
    std::unique_ptr<WsClient> mWitness;
    std::unique_ptr<client::Client> mTcpWitness;
};

TEST_F(WebViewer, ServesTheEmbeddedPageAndThePresets) {
    const auto* index = detail::findWebAsset("/");
    ASSERT_NE(index, nullptr) << "web/index.html is embedded";
    const std::string page = scrape(sPort, get("/"));
    EXPECT_EQ(statusOf(page), 200);
    EXPECT_EQ(bodyOf(page), index->body);
    EXPECT_NE(page.find("Content-Type: text/html"), std::string::npos) << page.substr(0, 400);
    EXPECT_NE(page.find("Content-Security-Policy: default-src 'self'"), std::string::npos);
    EXPECT_NE(page.find("X-Content-Type-Options: nosniff"), std::string::npos);
    for (std::size_t i = 0; i < detail::kWebAssetCount; ++i) {
        const auto& a = detail::kWebAssets[i];
        const std::string reply = scrape(sPort, get(std::string(a.path)));
        EXPECT_EQ(statusOf(reply), 200) << a.path;
        EXPECT_EQ(bodyOf(reply), a.body) << a.path;
    }
    const std::string head =
        scrape(sPort, "HEAD / HTTP/1.1\r\nHost: 127.0.0.1\r\nConnection: close\r\n\r\n");
    EXPECT_EQ(statusOf(head), 200);
    EXPECT_EQ(bodyOf(head), "");
    EXPECT_NE(head.find("Content-Length: " + std::to_string(index->body.size())),
              std::string::npos);
    const auto presets = nlohmann::json::parse(bodyOf(scrape(sPort, get("/presets.json"))));
    ASSERT_TRUE(presets.is_array());
    std::vector<std::string> names;
    for (const auto& p : presets)
        names.push_back(p.at("name").get<std::string>());
    EXPECT_EQ(names, render::TransferFunction::presetNames());
}

TEST_F(WebViewer, PathsOutsideTheEmbeddedSetAre404AndNoFileIsOpened) {
    TempDir sentinels;
    for (const char* name : {"secret.txt", "index.html", "passwd"})
        std::ofstream(sentinels.path() / name) << "sentinel\n";
    OpenWatch watch(sentinels.path());
    const auto cwd = std::filesystem::current_path();
    std::filesystem::current_path(sentinels.path()); // where a relative path would resolve
    const std::string s = sentinels.path().string();
    const std::vector<std::string> targets = {
        "/secret.txt",
        "/../secret.txt",
        "/%2e%2e/secret.txt",
        "/%2E%2E%2Fpasswd",
        "/..%2f..%2fpasswd",
        "/js/../../secret.txt",
        s + "/secret.txt",
        "//" + s + "/passwd",
        "http://x" + s,
        "/index.html",
        "/README.md",
        "/test/",
        "/./",
        "/presets.json/",
        "/ws/../presets.json",
        "*",
        "/%00",
        "/ws",
    };
    for (const auto& t : targets)
        EXPECT_EQ(statusOf(scrape(sPort, get(t))), 404) << t;
    std::filesystem::current_path(cwd);
    EXPECT_EQ(statusOf(scrape(sPort, "POST / HTTP/1.1\r\nHost: 127.0.0.1\r\nContent-Length: 0\r\n"
                                     "Connection: close\r\n\r\n")),
              405);
    EXPECT_TRUE(watch.events().empty()) << "the daemon opened a file under " << s;
    expectOthersServed("404s");
}

TEST_F(WebViewer, AWebSocketSessionDrawsTheFramesATcpSessionDraws) {
    WsClient ws(sPort);
    ws.handshake();
    ws.send(protocol::ListVolumes{}, 3);
    const auto list = ws.expect<protocol::VolumeList>();
    ASSERT_EQ(list.volumes.size(), 1u);
    ws.send(protocol::OpenVolume{"phantom"}, 4);
    const auto info = ws.expect<protocol::VolumeOpened>().info;
    ws.send(protocol::RequestHistogram{}, 5);
    const auto h = ws.expect<protocol::Histogram>();
    std::uint64_t voxels = 0;
    for (auto n : h.counts)
        voxels += n;
    EXPECT_EQ(voxels, 48u * 48 * 48) << "level-0 voxels";
    EXPECT_EQ(h.valueMin, info.valueMin);

    protocol::RenderOptions o = smallCpuFrames(64);
    o.quality = protocol::Quality::Refined;
    o.codec = protocol::Codec::Jpeg;
    o.refinedCodec = protocol::Codec::Png; // refined frames lossless, whatever `codec` is
    ws.send(protocol::SetRenderOptions{o}, 6);
    ws.send(orbitCamera(info, 35, 7), 7);
    ws.send(protocol::RequestFrame{}, 8);
    const auto frame = ws.expect<protocol::Frame>();
    EXPECT_EQ(frame.header.codec, protocol::Codec::Png);
    EXPECT_EQ(frame.header.cameraId, 7u);
    const auto shown = protocol::FrameImageDecoder().decode(
        protocol::Codec::Png, frame.header.width, frame.header.height, false, frame.image);

    client::Client tcp(sDaemon->clientConfig());
    tcp.openVolume("phantom");
    o.codec = protocol::Codec::Raw;
    o.refinedCodec.reset();
    tcp.setRenderOptions(o);
    tcp.setCamera(orbitCamera(info, 35, 7));
    tcp.requestFrame();
    const auto direct = tcp.nextFrame();
    ASSERT_EQ(direct.rgba.size(), shown.size());
    int worst = 0, lit = 0;
    for (std::size_t i = 0; i < shown.size(); i += 4)
        for (int c = 0; c < 3; ++c) {
            worst = std::max(worst, std::abs(int(shown[i + c]) - int(direct.rgba[i + c])));
            lit += direct.rgba[i + c] > 0;
        }
    EXPECT_EQ(worst, 0) << "PNG frames are the raw frame's colour exactly";
    EXPECT_GT(lit, 500) << "the phantom is in view";
}

TEST_F(WebViewer, UnscaledInteractiveFramesAreTheScaledOnesBeforeTheirScaling) {
    client::Client tcp(sDaemon->clientConfig());
    const auto info = tcp.openVolume("phantom");
    protocol::RenderOptions o = smallCpuFrames(65);
    o.height = 47; // odd edges: the drawn size rounds up
    o.quality = protocol::Quality::Interactive;
    o.codec = protocol::Codec::Raw;
    auto frameWith = [&](std::uint16_t flags, std::uint32_t camera) {
        o.flags = flags;
        tcp.setRenderOptions(o);
        tcp.setCamera(orbitCamera(info, 60, camera));
        tcp.requestFrame();
        return tcp.nextFrame();
    };
    const auto scaled = frameWith(0, 1), drawn = frameWith(protocol::kFlagUnscaledInteractive, 2);
    ASSERT_EQ(scaled.header.width, 65);
    ASSERT_EQ(scaled.header.height, 47);
    ASSERT_EQ(drawn.header.width, 33);
    ASSERT_EQ(drawn.header.height, 24);
    EXPECT_FALSE(drawn.header.refined);
    int differing = 0, lit = 0;
    for (int y = 0; y < 47; ++y)
        for (int x = 0; x < 65; ++x)
            for (int c = 0; c < 4; ++c) {
                const auto a = scaled.rgba[(std::size_t(y) * 65 + x) * 4 + c];
                differing += a != drawn.rgba[(std::size_t(y / 2) * 33 + x / 2) * 4 + c];
                lit += a > 0;
            }
    EXPECT_EQ(differing, 0) << "the scaled frame is the drawn one, pixels replicated";
    EXPECT_GT(lit, 100);
}

TEST_F(WebViewer, BadUpgradesAreRefusedAndOthersServed) {
    const std::string upgrade = "Upgrade: websocket\r\nConnection: Upgrade\r\n";
    const std::string key = "Sec-WebSocket-Key: dGhlIHNhbXBsZSBub25jZQ==\r\n";
    auto ws = [&](const std::string& target, const std::string& headers) {
        return scrape(sPort, "GET " + target + " HTTP/1.1\r\nHost: 127.0.0.1:" +
                                 std::to_string(sPort) + "\r\n" + headers + "\r\n");
    };
    EXPECT_EQ(statusOf(ws("/ws", upgrade + "Sec-WebSocket-Version: 13\r\n")), 400) << "no key";
    const std::string v8 = ws("/ws", upgrade + key + "Sec-WebSocket-Version: 8\r\n");
    EXPECT_EQ(statusOf(v8), 426) << v8.substr(0, 200);
    EXPECT_NE(v8.find("Sec-WebSocket-Version: 13"), std::string::npos) << "says which it speaks";
    EXPECT_EQ(statusOf(ws("/other", upgrade + key + "Sec-WebSocket-Version: 13\r\n")), 404);
    EXPECT_EQ(statusOf(ws("/ws", upgrade + key + "Sec-WebSocket-Version: 13\r\n" +
                                     "Origin: http://evil.example\r\n")),
              403)
        << "a page of another origin cannot drive the daemon";
    EXPECT_EQ(statusOf(scrape(sPort, "GARBAGE\r\n\r\n")), 400);
    EXPECT_EQ(statusOf(scrape(sPort, "GET / HTTP/1.1\r\nHost x\r\n\r\n")), 400);
    EXPECT_EQ(statusOf(scrape(sPort, "GET / HTTP/1.1\r\nContent-Length: 5\r\nConnection: "
                                     "close\r\n\r\nhello")),
              413)
        << "requests have no body";
    WsClient sameOrigin(sPort, "http://127.0.0.1:" + std::to_string(sPort));
    sameOrigin.handshake();
    expectOthersServed("bad upgrades");
}

TEST_F(WebViewer, TextOversizedFragmentedAndFloodingPeersLoseOnlyTheirConnection) {
    {
        WsClient c(sPort);
        c.ws().text(true);
        c.ws().write(asio::buffer(std::string("hello")));
        EXPECT_EQ(c.closeCode(), int(websocket::close_code::unknown_data)) << "text message";
    }
    expectOthersServed("a text message");
    {
        WsClient c(sPort);
        const std::vector<std::uint8_t> big(
            protocol::kHeaderBytes + protocol::kMaxClientPayloadBytes + 1, 0x42);
        c.ws().write(asio::buffer(big));
        EXPECT_EQ(c.closeCode(), int(websocket::close_code::too_big)) << "one message too big";
    }
    expectOthersServed("a message over the limit");
    {
        WsClient c(sPort);
        const std::vector<std::uint8_t> part(4096, 0x42);
        try { // 20 fragments of one message: 80 KiB in all
            for (int i = 0; i < 20; ++i)
                c.ws().write_some(false, asio::buffer(part));
        } catch (const boost::system::system_error&) { // the server closed first
        }
        EXPECT_EQ(c.closeCode(), int(websocket::close_code::too_big)) << "fragments add up";
    }
    expectOthersServed("a fragmented message over the limit");
    {
        WsClient c(sPort);
        c.handshake();
        try {
            for (unsigned i = 0; i < 4 * detail::kMaxPingsPerSecond; ++i)
                c.ws().ping({});
        } catch (const boost::system::system_error&) {
        }
        EXPECT_EQ(sessionsDownTo(*mTcpWitness, 2.0, 10), 2.0)
            << "the flooding session is still served";
    }
    expectOthersServed("a ping flood");
}

TEST_F(WebViewer, OversizedHeadersAndTricklingClientsAreCut) {
    const std::string big = "X-Filler: " + std::string(20000, 'a') + "\r\n";
    EXPECT_EQ(statusOf(scrape(sPort, get("/", big))), 431);
    RawConnection trickle(sPort);
    const std::string request = get("/");
    const auto start = std::chrono::steady_clock::now();
    std::size_t sent = 0;
    for (; sent < request.size() && !trickle.closedByPeer(100); ++sent)
        trickle.send({std::uint8_t(request[sent])});
    const double s =
        std::chrono::duration<double>(std::chrono::steady_clock::now() - start).count();
    EXPECT_LT(sent, request.size()) << "a request trickled in over " << s << " s was served";
    EXPECT_LT(s, 3.0) << "cut at the 1 s request deadline";
    expectOthersServed("a trickling client");
}

TEST_F(WebViewer, AHundredParallelPageLoadsAreAllServed) {
    std::atomic<int> ok = 0, bad = 0;
    std::vector<std::thread> loads;
    for (int i = 0; i < 100; ++i)
        loads.emplace_back([&] {
            for (std::size_t a = 0; a < detail::kWebAssetCount; ++a) {
                const auto& asset = detail::kWebAssets[a];
                const std::string reply = scrape(sPort, get(std::string(asset.path)));
                (statusOf(reply) == 200 && bodyOf(reply) == asset.body ? ok : bad) += 1;
            }
        });
    for (auto& t : loads)
        t.join();
    EXPECT_EQ(bad.load(), 0);
    EXPECT_EQ(ok.load(), 100 * int(detail::kWebAssetCount));
    expectOthersServed("100 parallel page loads");
}

TEST_F(WebViewer, APageThatNeverReadsIsCutWhileOthersKeepGettingFrames) {
    WsClient stuck(sPort);
    {
        // A small receive buffer so that the server's writes stall at once.
        const int bytes = 4096;
        ::setsockopt(stuck.ws().next_layer().native_handle(), SOL_SOCKET, SO_RCVBUF, &bytes,
                     sizeof bytes);
    }
    stuck.handshake();
    stuck.send(protocol::OpenVolume{"phantom"}, 3);
    const auto info = stuck.expect<protocol::VolumeOpened>().info;
    protocol::RenderOptions big = smallCpuFrames(1024);
    big.codec = protocol::Codec::Raw; // 4 MiB a frame
    big.stepVoxels = 4;
    stuck.send(protocol::SetRenderOptions{big}, 4);
    stuck.send(orbitCamera(info, 0, 1), 5);
    stuck.send(protocol::RequestFrame{protocol::FrameMode::ContinuousOn}, 6);
    for (std::uint32_t i = 2; i < 6; ++i) // a page that keeps moving and never reads
        stuck.send(orbitCamera(info, 10.0 * i, i), 6 + i);

    mWitness->send(protocol::OpenVolume{"phantom"}, 20);
    mWitness->expect<protocol::VolumeOpened>();
    mWitness->send(protocol::SetRenderOptions{smallCpuFrames(48)}, 21);
    int frames = 0;
    for (std::uint32_t i = 0; i < 6; ++i) {
        mWitness->send(orbitCamera(info, 20.0 * i, 100 + i), 22);
        mWitness->send(protocol::RequestFrame{}, 23);
        frames += std::holds_alternative<protocol::Frame>(mWitness->next());
    }
    EXPECT_EQ(frames, 6) << "the witness got every frame it asked for";
    // Asked of the server (reading the stuck socket would unstick it): the two witnesses
    // are left once the write deadline has cut the page that never reads.
    EXPECT_EQ(sessionsDownTo(*mTcpWitness, 2.0, 30), 2.0)
        << "the server still holds a page that stopped reading";
    expectOthersServed("a page that never reads");
}

TEST(WebViewerAuth, TheTokenRuleAndTheClientLimitHoldOverWebSocket) {
    TempDir dir;
    DaemonConfig c = generatedConfig(dir, {{"phantom", 32}});
    c.token = "s3cret-token";
    c.maxClients = 2;
    TestDaemon d(c);
    const std::uint16_t port = d.daemon->webPort();
    {
        WsClient early(port);
        early.send(protocol::Hello{}, 1);
        const auto hello = early.expect<protocol::Hello>();
        EXPECT_TRUE(hello.capabilities & protocol::kCapAuthRequired);
        early.send(protocol::ListVolumes{}, 2);
        const auto refused = std::get<protocol::Error>(early.next());
        EXPECT_EQ(refused.code, ErrorCode::NotAuthenticated);
    }
    {
        WsClient wrong(port);
        wrong.send(protocol::Hello{}, 1);
        wrong.expect<protocol::Hello>();
        wrong.send(protocol::Auth{"guess"}, 2);
        const auto e = std::get<protocol::Error>(wrong.next());
        EXPECT_EQ(e.code, ErrorCode::AuthFailed);
        EXPECT_TRUE(e.fatal);
    }
    WsClient a(port), b(port);
    a.handshake("s3cret-token");
    b.handshake("s3cret-token");
    WsClient third(port);
    const auto busy = std::get<protocol::Error>(third.next());
    EXPECT_EQ(busy.code, ErrorCode::Busy) << "max_clients counts WebSocket sessions too";
    a.send(protocol::ListVolumes{}, 3);
    EXPECT_EQ(a.expect<protocol::VolumeList>().volumes.size(), 1u);
}

TEST(WebViewerConfig, OffWhenAskedAndOnItsOwnPort) {
    TempDir dir;
    DaemonConfig c = generatedConfig(dir, {{"phantom", 32}});
    c.web = "";
    TestDaemon off(c);
    EXPECT_EQ(off.daemon->webPort(), 0);
    c.web = "127.0.0.1:0";
    TestDaemon on(c);
    EXPECT_NE(on.daemon->webPort(), 0);
    EXPECT_NE(on.daemon->webPort(), on.port);
}

} // namespace
} // namespace bc::server::test
