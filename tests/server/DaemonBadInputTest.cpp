// Every bad input of the protocol's table, each against one running daemon: the offender gets the
// Error PROTOCOL.md names (and is closed when it is fatal), and a witness client that connected
// before it still gets frames afterwards.
#include "ServerTestSupport.h"

#include <cmath>
#include <cstring>
#include <limits>

namespace bc::server::test {
namespace {

using protocol::ErrorCode;
constexpr const char* kToken = "correct horse battery staple";

class DaemonBadInput : public ::testing::Test {
  protected:
    static void SetUpTestSuite() {
        sDir = new TempDir;
        DaemonConfig c = generatedConfig(*sDir, {{"phantom", 40}});
        c.token = kToken;
        c.maxClients = 6;
        c.handshakeTimeoutMs = 1500;
        c.readTimeoutMs = 400;
        c.writeTimeoutMs = 1500;
        sDaemon = new TestDaemon(c);
    }
    static void TearDownTestSuite() {
        delete sDaemon;
        delete sDir;
    }
    void SetUp() override {
        mWitness = std::make_unique<client::Client>(sDaemon->clientConfig(kToken));
    }
    /// The witness, connected before the offender, still gets a frame.
    void TearDown() override {
        const auto v = mWitness->openVolume("phantom");
        mWitness->setRenderOptions(smallCpuFrames(32));
        mWitness->setCamera(orbitCamera(v, 30, 7));
        mWitness->requestFrame();
        const auto f = mWitness->nextFrame();
        EXPECT_EQ(f.header.cameraId, 7u);
        EXPECT_EQ(f.rgba.size(), 32u * 32u * 4u);
    }
    /// A connection past Hello and Auth.
    std::unique_ptr<RawConnection> ready() {
        auto c = std::make_unique<RawConnection>(sDaemon->port);
        c->handshake(kToken);
        return c;
    }
    static void expectError(RawConnection& c, ErrorCode code, bool fatal, const char* what) {
        const auto e = c.nextError();
        ASSERT_TRUE(e) << what << ": no Error message";
        EXPECT_EQ(e->code, code) << what << ": " << e->message;
        EXPECT_EQ(e->fatal, fatal) << what;
        if (fatal) {
            EXPECT_TRUE(c.closedByPeer()) << what << ": still open after a fatal error";
        }
    }
    /// After a non-fatal error the session still answers.
    static void expectStillServing(RawConnection& c) {
        c.send(protocol::ListVolumes{}, 99);
        const auto m = c.next();
        ASSERT_TRUE(m);
        EXPECT_TRUE(std::holds_alternative<protocol::VolumeList>(*m));
    }

    static TempDir* sDir;
    static TestDaemon* sDaemon;
    std::unique_ptr<client::Client> mWitness;
};

TempDir* DaemonBadInput::sDir = nullptr;
TestDaemon* DaemonBadInput::sDaemon = nullptr;

TEST_F(DaemonBadInput, LengthOverTheLimitIsFatalBeforeAnyPayloadArrives) {
    for (std::uint32_t length : {protocol::kMaxClientPayloadBytes + 1, 0xFFFFFFFFu}) {
        auto c = ready();
        c->send(rawHeader(std::uint8_t(protocol::MessageType::SetCamera), length));
        expectError(*c, ErrorCode::TooLarge, true, "length over the limit");
    }
}

TEST_F(DaemonBadInput, WrongMagicOrVersionIsFatal) {
    auto a = ready();
    a->send(rawHeader(0x04, 0, 1, 0x12345678));
    expectError(*a, ErrorCode::BadMagic, true, "bad magic");
    auto b = ready();
    b->send(rawHeader(0x04, 0, 1, 0x54534342, 9));
    expectError(*b, ErrorCode::UnsupportedVersion, true, "bad version");
}

TEST_F(DaemonBadInput, UnknownTypeIsAnsweredAndTheSessionGoesOn) {
    auto c = ready();
    auto bytes = rawHeader(0x7F, 3);
    bytes.insert(bytes.end(), {1, 2, 3});
    c->send(bytes);
    expectError(*c, ErrorCode::UnknownType, false, "unknown type");
    expectStillServing(*c);
}

TEST_F(DaemonBadInput, PayloadSizeWrongForItsTypeIsBadPayload) {
    auto c = ready();
    const auto options = protocol::encode(protocol::SetRenderOptions{smallCpuFrames()}, 5);
    for (int delta : {-1, +1}) { // one byte short, one byte long (length field adjusted)
        std::vector<std::uint8_t> b(options.begin(), options.end() + std::min(delta, 0));
        if (delta > 0) b.push_back(0);
        const std::uint32_t length = std::uint32_t(b.size() - protocol::kHeaderBytes);
        for (int i = 0; i < 4; ++i)
            b[8 + i] = std::uint8_t(length >> (8 * i));
        c->send(b);
        expectError(*c, ErrorCode::BadPayload, false, "wrong payload size");
    }
    c->send(rawHeader(std::uint8_t(protocol::MessageType::RequestFrame), 0));
    expectError(*c, ErrorCode::BadPayload, false, "empty RequestFrame");
    expectStillServing(*c);
}

TEST_F(DaemonBadInput, TruncatedMessageTimesOutAndClosesOnlyThatClient) {
    auto c = ready();
    const auto bytes = protocol::encode(protocol::ListVolumes{}, 3);
    c->send(std::vector<std::uint8_t>(bytes.begin(), bytes.begin() + 10)); // then nothing
    expectError(*c, ErrorCode::Timeout, true, "trickled header");
}

TEST_F(DaemonBadInput, OutOfRangeEnumsAreRefusedAndStateIsKept) {
    auto c = ready();
    auto frame = protocol::encode(protocol::RequestFrame{}, 4);
    frame.back() = 7; // mode
    c->send(frame);
    expectError(*c, ErrorCode::OutOfRange, false, "RequestFrame.mode 7");
    auto options = protocol::encode(protocol::SetRenderOptions{smallCpuFrames()}, 5);
    options[protocol::kHeaderBytes + 16] = 9; // renderer
    c->send(options);
    expectError(*c, ErrorCode::OutOfRange, false, "renderer 9");
    expectStillServing(*c);
}

TEST_F(DaemonBadInput, NanOrInfiniteCameraIsRefused) {
    auto c = ready();
    protocol::SetCamera cam;
    cam.eye = {100, 0, 0};
    for (double bad :
         {std::numeric_limits<double>::quiet_NaN(), std::numeric_limits<double>::infinity()}) {
        auto bytes = protocol::encode(cam, 6);
        std::memcpy(bytes.data() + protocol::kHeaderBytes + 4, &bad, 8); // eye[0]
        c->send(bytes);
        expectError(*c, ErrorCode::OutOfRange, false, "non-finite eye");
    }
    expectStillServing(*c);
}

TEST_F(DaemonBadInput, ViewportZeroOrHugeIsRefused) {
    auto c = ready();
    for (std::uint16_t edge : {std::uint16_t(0), std::uint16_t(65535)}) {
        protocol::RenderOptions o = smallCpuFrames();
        auto bytes = protocol::encode(protocol::SetRenderOptions{o}, 8);
        for (int i = 0; i < 4; ++i)
            bytes[protocol::kHeaderBytes + i] = std::uint8_t(edge >> (8 * (i % 2)));
        c->send(bytes);
        expectError(*c, ErrorCode::OutOfRange, false, "viewport");
    }
    expectStillServing(*c);
}

TEST_F(DaemonBadInput, VolumeNamesThatArePathsOrUnknownAreRefused) {
    auto c = ready();
    auto bytes = protocol::encode(protocol::OpenVolume{"phantom"}, 9);
    const std::string evil = "../etc/";
    bytes.resize(protocol::kHeaderBytes);
    bytes.push_back(std::uint8_t(evil.size()));
    bytes.push_back(0);
    bytes.insert(bytes.end(), evil.begin(), evil.end());
    bytes[8] = std::uint8_t(2 + evil.size());
    c->send(bytes);
    expectError(*c, ErrorCode::OutOfRange, false, "../ in a name");
    c->send(protocol::OpenVolume{"no-such-volume"}, 10);
    expectError(*c, ErrorCode::UnknownVolume, false, "unknown name");
    expectStillServing(*c);
}

TEST_F(DaemonBadInput, NothingIsRevealedBeforeAuthAndAWrongTokenIsFatal) {
    RawConnection none(sDaemon->port);
    none.send(protocol::Hello{}, 1);
    ASSERT_TRUE(none.next());
    none.send(protocol::ListVolumes{}, 2);
    auto m = none.next();
    ASSERT_TRUE(m);
    ASSERT_TRUE(std::holds_alternative<protocol::Error>(*m))
        << "a reply other than Error before Auth";
    EXPECT_EQ(std::get<protocol::Error>(*m).code, ErrorCode::NotAuthenticated);
    EXPECT_TRUE(none.closedByPeer());
    for (std::string wrong : {"correct horse battery stapl", "correct horse battery staple!"}) {
        RawConnection c(sDaemon->port);
        c.send(protocol::Hello{}, 1);
        ASSERT_TRUE(c.next());
        c.send(protocol::Auth{wrong}, 2);
        expectError(c, ErrorCode::AuthFailed, true, "wrong token");
    }
    EXPECT_THROW(client::Client(sDaemon->clientConfig("wrong")), client::ServerError);
}

TEST_F(DaemonBadInput, HandshakeNotCompletedInTimeIsClosed) {
    RawConnection c(sDaemon->port);
    expectError(c, ErrorCode::Timeout, true, "silent client");
}

TEST_F(DaemonBadInput, ConnectionsOverTheLimitGetBusyThenClose) {
    std::vector<std::unique_ptr<client::Client>> clients; // the witness is one already
    for (int i = 1; i < 6; ++i)
        clients.push_back(std::make_unique<client::Client>(sDaemon->clientConfig(kToken)));
    RawConnection extra(sDaemon->port);
    expectError(extra, ErrorCode::Busy, true, "one client too many");
}

TEST_F(DaemonBadInput, AClientThatStopsReadingIsCutWhileOthersKeepGettingFrames) {
    RawConnection c(sDaemon->port, 4096);
    c.handshake(kToken);
    c.send(protocol::OpenVolume{"phantom"}, 3);
    auto opened = c.next();
    ASSERT_TRUE(opened && std::holds_alternative<protocol::VolumeOpened>(*opened));
    const auto info = std::get<protocol::VolumeOpened>(*opened).info;
    protocol::RenderOptions big = smallCpuFrames(1024);
    big.codec = protocol::Codec::Raw; // 4 MiB a frame: more than the socket buffers hold
    big.stepVoxels = 4;
    c.send(protocol::SetRenderOptions{big}, 4);
    c.send(orbitCamera(info, 0, 1), 5);
    c.send(protocol::RequestFrame{protocol::FrameMode::ContinuousOn}, 6);
    for (int i = 0; i < 6; ++i) { // the witness is served while the reader is stuck
        c.send(orbitCamera(info, 10.0 * i, std::uint32_t(10 + i)), std::uint32_t(20 + i));
        const auto v = mWitness->openVolume("phantom");
        mWitness->setRenderOptions(smallCpuFrames(32));
        mWitness->setCamera(orbitCamera(v, 5.0 * i, std::uint32_t(100 + i)));
        mWitness->requestFrame();
        EXPECT_EQ(mWitness->nextFrame().header.cameraId, std::uint32_t(100 + i));
    }
    // Asked of the server (reading the stuck socket would unstick it): the session leases end
    // when it is cut at the write deadline, however slowly this machine draws the big frames.
    EXPECT_EQ(sessionsDownTo(*mWitness, 1.0, 30), 1.0)
        << "the server still holds a client that stopped reading";
    EXPECT_TRUE(c.closedByPeer(5000));
}

TEST_F(DaemonBadInput, AClientThatDisconnectsMidFrameHurtsNoOne) {
    for (int i = 0; i < 3; ++i) {
        auto c = ready();
        c->send(protocol::OpenVolume{"phantom"}, 3);
        auto opened = c->next();
        ASSERT_TRUE(opened && std::holds_alternative<protocol::VolumeOpened>(*opened));
        protocol::RenderOptions o = smallCpuFrames(512);
        o.codec = protocol::Codec::Raw;
        c->send(protocol::SetRenderOptions{o}, 4);
        c->send(orbitCamera(std::get<protocol::VolumeOpened>(*opened).info, 40, 1), 5);
        c->send(protocol::RequestFrame{}, 6);
        // gone while the frame is drawn (i = 0) or being written (later, the server is warm)
        std::this_thread::sleep_for(std::chrono::milliseconds(40 * i));
        c->close();
    }
}

} // namespace
} // namespace bc::server::test
