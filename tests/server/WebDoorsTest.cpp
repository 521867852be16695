// Who the browser viewer's address answers: only requests that name this server in Host (a
// page whose DNS name was rebound to the daemon's address cannot read it), WebSocket upgrades
// only from this server's own origin, and page loads however many slow clients hold
// connections open.
#include "WebTestSupport.h"

#include "server/detail/WebAssets.h"
#include "server/detail/WebHosts.h"

#include <atomic>
#include <sys/resource.h>

namespace bc::server::test {
namespace {

using Clock = std::chrono::steady_clock;

std::string upgrade(const std::string& host, const std::string& origin) {
    return "GET /ws HTTP/1.1\r\nHost: " + host +
           "\r\nUpgrade: websocket\r\nConnection: Upgrade\r\n"
           "Sec-WebSocket-Key: dGhlIHNhbXBsZSBub25jZQ==\r\nSec-WebSocket-Version: 13\r\n" +
           (origin.empty() ? "" : "Origin: " + origin + "\r\n") + "\r\n";
}

/// The status of the answer to `request`, read up to the end of its headers (an upgrade's
/// connection is then closed, not held open as a session).
int statusOnly(std::uint16_t port, const std::string& request) {
    RawConnection c(port);
    c.send(std::vector<std::uint8_t>(request.begin(), request.end()));
    std::string reply;
    while (reply.find("\r\n\r\n") == std::string::npos) {
        const auto more = c.receive(5000);
        if (more.empty()) break;
        reply += more;
    }
    return statusOf(reply);
}

std::string page(const std::string& host) {
    return "GET / HTTP/1.1\r\nHost: " + host + "\r\nConnection: close\r\n\r\n";
}

TEST(WebHosts, TheListenAddressLocalhostAndConfiguredNamesOnly) {
    const detail::WebHosts loopback("127.0.0.1", asio::ip::make_address("127.0.0.1"),
                                    {"viewer.test"});
    for (const char* ok : {"127.0.0.1:7412", "127.0.0.1", "localhost:7412", "LOCALHOST",
                           "[::1]:7412", "viewer.test", "Viewer.Test:443"})
        EXPECT_FALSE(loopback.hostProblem(ok)) << ok;
    for (const char* bad :
         {"evil.com:7412", "evil.com", "127.0.0.2:7412", "10.0.0.5", "localhost.evil.com", "",
          ":7412", "127.0.0.1:x", "[::1", "127.0.0.1:7412:1"})
        EXPECT_TRUE(loopback.hostProblem(bad)) << bad;
    const detail::WebHosts any("0.0.0.0", asio::ip::make_address("0.0.0.0"), {});
    EXPECT_FALSE(any.hostProblem("192.168.1.20:7412")) << "any address of an all-address listen";
    EXPECT_FALSE(any.hostProblem("[fe80::1]:7412"));
    EXPECT_TRUE(any.hostProblem("evil.com:7412")) << "but no name it was not given";
    EXPECT_TRUE(any.hostProblem("localhost")) << "not loopback: localhost is another machine";
}

TEST(WebHosts, AnOriginIsThisServersOwnOverHttpOrHttps) {
    using detail::WebHosts;
    EXPECT_FALSE(WebHosts::originProblem("http://127.0.0.1:7412", "127.0.0.1:7412"));
    EXPECT_FALSE(WebHosts::originProblem("https://Viewer.Test", "viewer.test"));
    for (const char* bad :
         {"http://evil.com:7412", "ftp://127.0.0.1:7412", "null", "http://127.0.0.1:7413",
          "http://127.0.0.1:7412/x", "", "http://127.0.0.1"})
        EXPECT_TRUE(WebHosts::originProblem(bad, "127.0.0.1:7412")) << bad;
}

class WebDoors : public ::testing::Test {
  protected:
    static void SetUpTestSuite() {
        sDir = new TempDir;
        DaemonConfig c = generatedConfig(*sDir, {{"phantom", 32}});
        c.handshakeTimeoutMs = 1000;
        c.webHosts = {"viewer.test"};
        sDaemon = new TestDaemon(c);
        sPort = sDaemon->daemon->webPort();
        sHost = "127.0.0.1:" + std::to_string(sPort);
    }
    static void TearDownTestSuite() {
        delete sDaemon;
        delete sDir;
    }
    static inline TempDir* sDir = nullptr;
    static inline TestDaemon* sDaemon = nullptr;
    static inline std::uint16_t sPort = 0;
    static inline std::string sHost;
};

TEST_F(WebDoors, ARebindingPageIsRefusedTheViewerAndItsWebSocket) {
    const std::string evil = "evil.example:" + std::to_string(sPort);
    EXPECT_EQ(statusOf(scrape(sPort, page(evil))), 403) << "the page under a foreign name";
    EXPECT_EQ(statusOnly(sPort, upgrade(evil, "http://" + evil)), 403)
        << "Host and Origin both the rebound name";
    EXPECT_EQ(statusOnly(sPort, upgrade(sHost, "http://evil.example")), 403)
        << "a foreign Origin with a correct Host";
    EXPECT_EQ(statusOnly(sPort, upgrade(sHost, "ftp://" + sHost)), 403)
        << "an Origin of another scheme";
    EXPECT_EQ(statusOnly(sPort, upgrade(sHost, "null")), 403) << "an opaque Origin";
    EXPECT_EQ(statusOf(scrape(sPort, "GET / HTTP/1.1\r\nConnection: close\r\n\r\n")), 403)
        << "no Host at all";
}

TEST_F(WebDoors, LoopbackNamesAndAConfiguredNameAreServed) {
    for (const std::string& host :
         {sHost, "localhost:" + std::to_string(sPort), "viewer.test:" + std::to_string(sPort)}) {
        EXPECT_EQ(statusOf(scrape(sPort, page(host))), 200) << host;
        EXPECT_EQ(statusOnly(sPort, upgrade(host, "http://" + host)), 101) << host;
        EXPECT_EQ(statusOnly(sPort, upgrade(host, "https://" + host)), 101) << host;
    }
    WsClient c(sPort, "http://" + sHost);
    c.handshake();
    c.send(protocol::ListVolumes{}, 3);
    EXPECT_EQ(c.expect<protocol::VolumeList>().volumes.size(), 1u);
}

/// Connections that send a request line and then one header byte every 300 ms, reopened as
/// the daemon cuts them (slowloris), until stopped.
class SlowClients {
  public:
    SlowClients(std::uint16_t port, std::size_t count)
        : mThread([this, port, count] { run(port, count); }) {}
    ~SlowClients() {
        mStop = true;
        mThread.join();
    }
    std::size_t opened() const { return mOpened; }

  private:
    void run(std::uint16_t port, std::size_t count) {
        std::vector<std::unique_ptr<RawConnection>> held;
        while (!mStop) {
            std::erase_if(held, [](auto& c) { return c->peerGone(); });
            while (held.size() < count && !mStop) {
                held.push_back(std::make_unique<RawConnection>(port));
                held.back()->send(std::vector<std::uint8_t>{'G', 'E', 'T', ' ', '/', ' '});
                ++mOpened;
            }
            for (auto& c : held)
                c->send(std::vector<std::uint8_t>{'X'});
            for (int i = 0; i < 15 && !mStop; ++i)
                std::this_thread::sleep_for(std::chrono::milliseconds(20));
        }
    }
    std::atomic<bool> mStop = false;
    std::atomic<std::size_t> mOpened = 0;
    std::thread mThread;
};

TEST_F(WebDoors, PageLoadsAreAnsweredBesideSixHundredSlowConnections) {
    rlimit files{};
    ::getrlimit(RLIMIT_NOFILE, &files);
    files.rlim_cur = std::max<rlim_t>(files.rlim_cur, std::min<rlim_t>(files.rlim_max, 4096));
    ::setrlimit(RLIMIT_NOFILE, &files);
    if (files.rlim_cur < 2048) GTEST_SKIP() << "needs 2048 open files, may have " << files.rlim_cur;
    SlowClients slow(sPort, 600);
    while (slow.opened() < 600)
        std::this_thread::sleep_for(std::chrono::milliseconds(20));
    int answered = 0;
    for (int i = 0; i < 15; ++i) {
        const auto start = Clock::now();
        const std::string reply = scrape(sPort, page(sHost));
        const double s = std::chrono::duration<double>(Clock::now() - start).count();
        answered += statusOf(reply) == 200 && s <= 2.0;
        std::this_thread::sleep_for(std::chrono::milliseconds(100));
    }
    std::printf("[doors] %d of 15 page loads answered within 2 s beside 600 slow connections\n",
                answered);
    EXPECT_GE(answered, 14) << "page loads answered within 2 s beside 600 slow connections";
}

} // namespace
} // namespace bc::server::test
