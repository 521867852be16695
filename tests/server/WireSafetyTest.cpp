// Nothing that arrives on the wire names a file. Every hostile preset string and
// every bad set of points gets an Error that names the field and no path; a folder of sentinel
// files, watched with inotify while the hostile names point into it, sees no open; a witness
// client that connected first gets exactly the frame it got before.
#include "ServerTestSupport.h"

#include "server/DaemonConfig.h"
#include "server/Error.h"

#include <cstring>
#include <filesystem>
#include <limits>

namespace bc::server::test {
namespace {

using protocol::ErrorCode;
using Bytes = std::vector<std::uint8_t>;

/// A transfer function that would change every frame: opaque red wherever there is anything.
constexpr const char* kRedTf =
    R"({"name": "red", "points": [{"fraction": 0, "rgba": [1, 0, 0, 0]},
                                  {"fraction": 0.05, "rgba": [1, 0, 0, 1]}]})";

struct RawPoint {
    std::uint8_t placement = 0;
    double position = 0;
    std::array<float, 4> rgba{1, 1, 1, 1};
};

/// A SetTransferFunction of kind 1 as bytes, with `count` claimed whatever `points` holds.
Bytes pointsMessage(std::uint16_t count, const std::vector<RawPoint>& points,
                    std::uint32_t request) {
    Bytes p = {1, 1, 0, std::uint8_t(count), std::uint8_t(count >> 8)};
    auto put = [&](const void* v, std::size_t n) {
        const auto* b = static_cast<const std::uint8_t*>(v);
        p.insert(p.end(), b, b + n); // little-endian host (x86-64, as the protocol)
    };
    for (const RawPoint& q : points) {
        p.push_back(q.placement);
        put(&q.position, 8);
        for (float c : q.rgba)
            put(&c, 4);
    }
    Bytes m = rawHeader(std::uint8_t(protocol::MessageType::SetTransferFunction),
                        std::uint32_t(p.size()), request);
    m.insert(m.end(), p.begin(), p.end());
    return m;
}

class WireSafety : public ::testing::Test {
  protected:
    void SetUp() override {
        sentinels = dir.path() / "s";
        std::filesystem::create_directories(sentinels);
        for (const char* name : {"x.json", "ct-bone", "ct-bone.json", "tf.json"})
            bc::test::writeFile((sentinels / name).string(), kRedTf);
        bc::test::writeFile(dir.file("site.json"), kRedTf);
        DaemonConfig c = generatedConfig(dir, {{"phantom", 40}});
        c.presets.push_back({"site-red", dir.file("site.json"), kRedTf});
        daemon = std::make_unique<TestDaemon>(c);
        witness = std::make_unique<client::Client>(daemon->clientConfig());
        witnessFrame = frameOf(*witness, 7);
    }
    /// The witness, connected before any offender, gets exactly the frame it got before.
    void TearDown() override {
        const auto f = frameOf(*witness, 8);
        EXPECT_EQ(f.rgba, witnessFrame.rgba) << "the witness's frame changed";
    }
    static client::ReceivedFrame frameOf(client::Client& c, std::uint32_t cameraId) {
        const auto v = c.openVolume("phantom");
        c.setRenderOptions(smallCpuFrames(32));
        c.setCamera(orbitCamera(v, 30, cameraId));
        c.requestFrame();
        return c.nextFrame();
    }
    /// A connection with the volume open.
    std::unique_ptr<RawConnection> viewer() {
        auto c = std::make_unique<RawConnection>(daemon->port);
        c->handshake("");
        c->send(protocol::OpenVolume{"phantom"}, 2);
        auto m = c->next();
        EXPECT_TRUE(m && std::holds_alternative<protocol::VolumeOpened>(*m));
        return c;
    }
    static protocol::Error errorFor(RawConnection& c, const std::string& what) {
        const auto e = c.nextError();
        EXPECT_TRUE(e) << what << ": no Error";
        return e.value_or(protocol::Error{});
    }

    TempDir dir;
    std::filesystem::path sentinels;
    std::unique_ptr<TestDaemon> daemon;
    std::unique_ptr<client::Client> witness;
    client::ReceivedFrame witnessFrame;
};

TEST_F(WireSafety, PresetStringsThatLookLikePathsAreNotFoundAndNoFileIsOpened) {
    const std::string absolute = (sentinels / "x.json").string();
    ASSERT_LE(absolute.size(), protocol::kMaxPresetBytes);
    const std::vector<std::string> hostile{
        "../../etc/passwd",   "/etc/hostname", "x.json",        "ct-bone/../x", "",
        std::string(64, '/'), absolute,        "./x.json",      "tf.json",      "ct-bone.json",
        "s/x.json",           "CT-BONE",       "ct-bone\\..\\x"};
    const auto cwd = std::filesystem::current_path();
    std::filesystem::current_path(sentinels); // relative names would resolve into the sentinels
    OpenWatch watch(sentinels);
    auto c = viewer();
    std::uint32_t request = 10;
    for (const std::string& name : hostile) {
        protocol::SetTransferFunction tf;
        tf.preset = name;
        c->send(tf, ++request);
        const auto e = errorFor(*c, "preset '" + name + "'");
        EXPECT_EQ(e.code, ErrorCode::NotFound) << name << ": " << e.message;
        EXPECT_FALSE(e.fatal) << name;
        EXPECT_NE(e.message.find("SetTransferFunction.preset"), std::string::npos) << e.message;
        EXPECT_EQ(e.message.find('/'), std::string::npos) << "a path in: " << e.message;
        if (name.size() > 2) {
            EXPECT_EQ(e.message.find(name), std::string::npos) << e.message;
        }
    }
    // The session still serves, with the transfer function it had.
    c->send(protocol::ListVolumes{}, ++request);
    auto m = c->next();
    EXPECT_TRUE(m && std::holds_alternative<protocol::VolumeList>(*m));
    std::filesystem::current_path(cwd);
    EXPECT_EQ(watch.events(), std::vector<std::string>{}) << "the daemon opened a sentinel";
    // The watch sees an open when there is one: the check above can fail.
    bc::test::readFile(absolute);
    EXPECT_FALSE(watch.events().empty());
}

TEST_F(WireSafety, PresetsAreTheBuiltInOnesAndThoseTheConfigNames) {
    auto c = viewer();
    for (const std::string name : {"ct-bone", "site-red"}) {
        protocol::SetTransferFunction tf;
        tf.preset = name;
        c->send(tf, 20);
        c->send(protocol::SetRenderOptions{smallCpuFrames(32)}, 21);
        c->send(orbitCamera(witness->openVolume("phantom"), 30, 5), 22);
        c->send(protocol::RequestFrame{}, 23);
        bool framed = false;
        while (auto m = c->next()) {
            if (auto* e = std::get_if<protocol::Error>(&*m)) {
                ADD_FAILURE() << name << ": " << e->message;
                break;
            }
            if ((framed = std::holds_alternative<protocol::Frame>(*m))) break;
        }
        EXPECT_TRUE(framed) << name;
    }
}

TEST_F(WireSafety, BadPointsAreRefusedNamingTheField) {
    const double nan = std::numeric_limits<double>::quiet_NaN();
    const double inf = std::numeric_limits<double>::infinity();
    const float fnan = std::numeric_limits<float>::quiet_NaN();
    const float finf = std::numeric_limits<float>::infinity();
    const RawPoint good{0, 100, {1, 1, 1, 0.5f}};
    struct Case {
        const char* what;
        std::uint16_t count;
        std::vector<RawPoint> points;
        std::string field;
    };
    const std::vector<Case> cases{
        {"no points", 0, {}, "SetTransferFunction.points"},
        {"65535 points claimed", 65535, {good}, "SetTransferFunction.points"},
        {"NaN position", 1, {{0, nan, {1, 1, 1, 1}}}, "SetTransferFunction.points[0].position"},
        {"inf position",
         2,
         {good, {0, inf, {1, 1, 1, 1}}},
         "SetTransferFunction.points[1].position"},
        {"NaN colour", 1, {{0, 1, {1, fnan, 1, 1}}}, "SetTransferFunction.points[0].rgba[1]"},
        {"inf opacity", 1, {{0, 1, {1, 1, 1, finf}}}, "SetTransferFunction.points[0].rgba[3]"},
        {"colour above 1", 1, {{0, 1, {1.5f, 1, 1, 1}}}, "SetTransferFunction.points[0].rgba[0]"},
        {"placement 3", 1, {{3, 1, {1, 1, 1, 1}}}, "SetTransferFunction.points[0].placement"},
        {"percentile below 0",
         2,
         {good, {2, -1, {1, 1, 1, 1}}},
         "SetTransferFunction.points[1].position"},
        {"fraction above 1",
         2,
         {good, {1, 1.5, {1, 1, 1, 1}}},
         "SetTransferFunction: points[1].fraction"},
    };
    auto c = viewer();
    std::uint32_t request = 30;
    for (const Case& k : cases) {
        c->send(pointsMessage(k.count, k.points, ++request));
        const auto e = errorFor(*c, k.what);
        EXPECT_TRUE(e.code == ErrorCode::OutOfRange || e.code == ErrorCode::BadPayload)
            << k.what << ": " << e.message;
        EXPECT_FALSE(e.fatal) << k.what;
        EXPECT_NE(e.message.find(k.field), std::string::npos) << k.what << ": " << e.message;
        EXPECT_EQ(e.message.find('/'), std::string::npos) << k.what << ": " << e.message;
    }
    c->send(protocol::ListVolumes{}, ++request);
    auto m = c->next();
    EXPECT_TRUE(m && std::holds_alternative<protocol::VolumeList>(*m));
}

// PROTOCOL.md: points need not be sorted. Out of order is not an error; it is the same
// function, so the same frame.
TEST_F(WireSafety, PointsOutOfOrderDrawTheSameFrameAsSorted) {
    protocol::SetTransferFunction a;
    a.kind = protocol::TfKind::Points;
    a.shadingSource = protocol::ShadingSource::Message;
    a.points = {{protocol::Placement::Fraction, 0.1, {1, 0.5f, 0.2f, 0}},
                {protocol::Placement::Fraction, 0.3, {1, 1, 1, 0.4f}},
                {protocol::Placement::Fraction, 0.6, {0.2f, 0.4f, 1, 0.8f}}};
    protocol::SetTransferFunction b = a;
    std::swap(b.points[0], b.points[2]);
    std::vector<std::vector<std::uint8_t>> frames;
    for (const auto& tf : {a, b}) {
        client::Client c(daemon->clientConfig());
        const auto v = c.openVolume("phantom");
        c.setRenderOptions(smallCpuFrames(32));
        c.setTransferFunction(tf);
        c.setCamera(orbitCamera(v, 45, 3));
        c.requestFrame();
        frames.push_back(c.nextFrame().rgba);
    }
    EXPECT_EQ(frames[0], frames[1]);
}

// The config's presets are read at start-up; what is wrong with one names the file and key.
TEST(DaemonConfigPresets, BadPresetEntriesNameTheKey) {
    TempDir dir;
    bc::test::writeFile(dir.file("ok.json"), kRedTf);
    bc::test::writeFile(dir.file("bad.json"),
                        R"({"points": [{"value": 1, "rgba": [1, 1, 1, 2]}]})");
    const std::string volume =
        "[[volume]]\nname = \"v\"\ngenerate = \"phantom\"\ndims = [8, 8, 8]\n";
    const auto parse = [&](const std::string& presets) {
        return DaemonConfig::parse(volume + presets, "t.toml", dir.path().string());
    };
    const auto ok = parse("[[preset]]\nname = \"mine\"\nfile = \"ok.json\"\n");
    ASSERT_EQ(ok.presets.size(), 1u);
    EXPECT_EQ(ok.presets[0].json, kRedTf);
    const std::vector<std::pair<std::string, std::string>> bad{
        {"[[preset]]\nname = \"ct-bone\"\nfile = \"ok.json\"\n", "built-in preset"},
        {"[[preset]]\nname = \"a/b\"\nfile = \"ok.json\"\n", "[[preset]] 1 .name"},
        {"[[preset]]\nname = \"m\"\nfile = \"missing.json\"\n", "not a readable file"},
        {"[[preset]]\nname = \"m\"\nfile = \"bad.json\"\n", "points[0].rgba[3]"},
        {"[[preset]]\nname = \"m\"\n", "[[preset]] 1 .file"},
        {"[[preset]]\nname = \"m\"\nfile = \"ok.json\"\n[[preset]]\nname = \"m\"\nfile = "
         "\"ok.json\"\n",
         "already [[preset]] 1"},
        {"[[preset]]\nname = \"m\"\nfile = \"ok.json\"\npath = \"x\"\n", "path"},
    };
    for (const auto& [text, why] : bad) {
        try {
            parse(text);
            ADD_FAILURE() << "accepted: " << text;
        } catch (const ConfigError& e) {
            EXPECT_NE(std::string(e.what()).find(why), std::string::npos) << e.what();
        }
    }
}

} // namespace
} // namespace bc::server::test

namespace bc::server::test {
namespace {

// A client's Error message reaches the log: it cannot start a line of its own there.
TEST(LogLines, ControlCharactersAreEscapedSoALineIsOneLine) {
    Log log(false);
    ::testing::internal::CaptureStderr();
    log.info("client error Internal: x\n2026-12-02T00:00:00.000Z error forged\r\x01");
    const std::string out = ::testing::internal::GetCapturedStderr();
    EXPECT_EQ(std::count(out.begin(), out.end(), '\n'), 1) << out;
    EXPECT_NE(out.find("x\\n2026-12-02T00:00:00.000Z error forged\\x0d\\x01"), std::string::npos)
        << out;
}

} // namespace
} // namespace bc::server::test
