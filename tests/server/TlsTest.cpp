// The daemon with a certificate (tls_cert, tls_key): the protocol and the viewer speak TLS
// only, and everything above the encryption is unchanged: the same frames, the same token rule,
// the same answers to bad input. A client that does not speak TLS, or does not trust the
// certificate, gets nowhere, and the daemon keeps serving the others.
#include "WebTestSupport.h"

#include "server/Error.h"

#include <boost/asio/ssl.hpp>
#include <boost/beast/ssl.hpp>
#include <boost/beast/websocket/ssl.hpp>

namespace bc::server::test {
namespace {

namespace ssl = boost::asio::ssl;
using ErrorCode = protocol::ErrorCode;
constexpr const char* kToken = "tls-test-token";

/// A self-signed certificate for 127.0.0.1 (as an IP address) and localhost, in `dir`.
std::pair<std::string, std::string> selfSigned(const TempDir& dir) {
    const std::string cert = dir.file("cert.pem"), key = dir.file("key.pem");
    const auto r = bc::test::runCommand(
        "openssl req -x509 -newkey rsa:2048 -nodes -days 1 -keyout " + key + " -out " + cert +
        " -subj /CN=127.0.0.1 -addext subjectAltName=IP:127.0.0.1,DNS:localhost 2>&1");
    if (r.exitCode != 0) throw std::runtime_error("openssl req: " + r.text);
    return {cert, key};
}

class Tls : public ::testing::Test {
  protected:
    static void SetUpTestSuite() {
        sDir = new TempDir;
        std::tie(sCert, sKey) = selfSigned(*sDir);
        DaemonConfig c = generatedConfig(*sDir, {{"phantom", 40}});
        c.token = kToken;
        c.readTimeoutMs = 400;
        sPlain = new TestDaemon(c);
        c.tlsCert = sCert;
        c.tlsKey = sKey;
        sTls = new TestDaemon(c);
    }
    static void TearDownTestSuite() {
        delete sTls;
        delete sPlain;
        delete sDir;
    }
    static client::ClientConfig tlsClient(const std::string& token = kToken) {
        auto cc = sTls->clientConfig(token);
        cc.tls = true;
        cc.tlsCaFile = sCert;
        return cc;
    }

    static inline TempDir* sDir = nullptr;
    static inline TestDaemon *sPlain = nullptr, *sTls = nullptr;
    static inline std::string sCert, sKey;
};

TEST_F(Tls, AFrameOverTlsIsTheFrameOverPlainTcp) {
    client::Client secure(tlsClient()), plain(sPlain->clientConfig(kToken));
    std::vector<std::vector<std::uint8_t>> frames;
    for (auto* c : {&secure, &plain}) {
        const auto v = c->openVolume("phantom");
        c->setRenderOptions(smallCpuFrames(48));
        c->setCamera(orbitCamera(v, 35, 4));
        c->requestFrame();
        const auto f = c->nextFrame();
        EXPECT_EQ(f.header.cameraId, 4u);
        frames.push_back(f.rgba);
    }
    EXPECT_EQ(frames[0], frames[1]) << "the same pixels, encrypted or not";
    const auto stats = secure.stats();
    EXPECT_FALSE(stats.empty());
}

TEST_F(Tls, TheTokenRuleAndBadInputAreAnsweredAsOverTcp) {
    EXPECT_THROW(client::Client(tlsClient("wrong token")), client::ServerError);
    client::Client c(tlsClient());
    c.sendRaw(rawHeader(std::uint8_t(protocol::MessageType::ListVolumes), 1u << 30));
    try {
        c.listVolumes();
        ADD_FAILURE() << "a length over the limit was accepted";
    } catch (const client::ServerError& e) {
        EXPECT_EQ(e.code(), ErrorCode::TooLarge) << e.what();
        EXPECT_TRUE(e.fatal());
    }
    EXPECT_EQ(client::Client(tlsClient()).listVolumes().size(), 1u) << "others are served";
}

bool resolves(const std::string& host) {
    asio::io_context io;
    boost::system::error_code ec;
    asio::ip::tcp::resolver(io).resolve(host, "0", ec);
    return !ec;
}

TEST_F(Tls, AClientThatDoesNotSpeakTlsOrTrustTheCertificateGetsNowhere) {
    {
        auto cc = sTls->clientConfig(kToken);
        cc.timeoutMs = 3000;
        EXPECT_THROW(client::Client{cc}, client::ClientError) << "plain TCP to the TLS address";
    }
    {
        auto cc = tlsClient();
        cc.tlsCaFile.clear(); // the system's CAs do not know a self-signed certificate
        try {
            client::Client c(cc);
            ADD_FAILURE() << "an unknown certificate was trusted";
        } catch (const client::ClientError& e) {
            EXPECT_NE(std::string(e.what()).find("certificate"), std::string::npos) << e.what();
        }
    }
    if (resolves("localhost")) {
        auto cc = tlsClient();
        cc.host = "localhost"; // named in the certificate too
        EXPECT_EQ(client::Client(cc).listVolumes().size(), 1u);
    } else { // a bare chroot may have no /etc/hosts
        std::printf("[tls] localhost does not resolve here: the name in the certificate is not "
                    "tried\n");
    }
    {
        auto cc = tlsClient();
        cc.tlsCaFile.clear();
        cc.tlsVerify = false; // encrypted, not authenticated: the caller's choice
        EXPECT_EQ(client::Client(cc).listVolumes().size(), 1u);
    }
    EXPECT_EQ(client::Client(tlsClient()).listVolumes().size(), 1u) << "others are served";
}

TEST_F(Tls, TheViewerIsServedOverHttpsAndItsWebSocketOverWss) {
    asio::io_context io;
    ssl::context trust(ssl::context::tls_client);
    trust.load_verify_file(sCert);
    trust.set_verify_mode(ssl::verify_peer);
    const std::uint16_t port = sTls->daemon->webPort();
    const std::string host = "127.0.0.1:" + std::to_string(port);
    {
        beast::ssl_stream<asio::ip::tcp::socket> s(io, trust);
        s.next_layer().connect({asio::ip::make_address("127.0.0.1"), port});
        s.handshake(ssl::stream_base::client);
        beast::http::request<beast::http::empty_body> req{beast::http::verb::get, "/", 11};
        req.set(beast::http::field::host, host);
        beast::http::write(s, req);
        beast::flat_buffer b;
        beast::http::response<beast::http::string_body> res;
        beast::http::read(s, b, res);
        EXPECT_EQ(res.result_int(), 200u);
        EXPECT_NE(res.body().find("<html"), std::string::npos);
    }
    websocket::stream<beast::ssl_stream<asio::ip::tcp::socket>> ws(io, trust);
    beast::get_lowest_layer(ws).connect({asio::ip::make_address("127.0.0.1"), port});
    ws.next_layer().handshake(ssl::stream_base::client);
    ws.set_option(websocket::stream_base::decorator(
        [&](websocket::request_type& r) { r.set(beast::http::field::origin, "https://" + host); }));
    ws.handshake(host, "/ws");
    ws.binary(true);
    for (const protocol::Message& m :
         {protocol::Message(protocol::Hello{}), protocol::Message(protocol::Auth{kToken}),
          protocol::Message(protocol::ListVolumes{})}) {
        const auto bytes = protocol::encode(m, 1);
        ws.write(asio::buffer(bytes));
    }
    protocol::Decoder d(protocol::kDefaultMaxServerPayloadBytes);
    std::vector<protocol::MessageType> got;
    while (got.size() < 3) {
        beast::flat_buffer b;
        ws.read(b);
        const auto data = b.cdata();
        d.feed({static_cast<const std::uint8_t*>(data.data()), data.size()});
        for (auto r = d.next(); r.status == protocol::Decoder::Status::Message; r = d.next())
            got.push_back(protocol::typeOf(r.message));
    }
    EXPECT_EQ(got, (std::vector<protocol::MessageType>{protocol::MessageType::Hello,
                                                       protocol::MessageType::AuthOk,
                                                       protocol::MessageType::VolumeList}));
}

TEST(TlsConfig, AMissingOrMismatchedCertificateStopsTheStartNamingIt) {
    TempDir dir, other;
    const auto [cert, key] = selfSigned(dir);
    const auto [otherCert, otherKey] = selfSigned(other);
    DaemonConfig c = generatedConfig(dir, {{"phantom", 16}});
    for (const auto& [useCert, useKey, named] :
         {std::tuple{dir.file("missing.pem"), key, std::string("missing.pem")},
          std::tuple{cert, otherKey, otherKey}, std::tuple{key, key, std::string("tls_cert")}}) {
        c.tlsCert = useCert;
        c.tlsKey = useKey;
        try {
            TestDaemon d(c);
            ADD_FAILURE() << "started with " << useCert << " and " << useKey;
        } catch (const ConfigError& e) {
            EXPECT_NE(std::string(e.what()).find(named), std::string::npos) << e.what();
        }
    }
    EXPECT_THROW(DaemonConfig::parse("[server]\ntls_cert = \"c.pem\"\n[[volume]]\nname = \"p\"\n"
                                     "generate = \"phantom\"\ndims = [8, 8, 8]\n",
                                     "t.toml", dir.path().string()),
                 ConfigError)
        << "a certificate without its key";
}

} // namespace
} // namespace bc::server::test
