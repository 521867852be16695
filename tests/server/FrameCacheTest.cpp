// The frame cache: a second session asking for a view already drawn gets the frame
// drawn before, without a render and with the same bytes; a delta-coded frame is each session's
// own delta; a change of transfer function, options or store is drawn anew; the cache is held
// under its byte budget; frames.cache_mb = 0 turns it off. And the key (frameKeyOf): two views
// that differ in any field are two keys, identical views one.
#include "ServerTestSupport.h"

#include "render/Camera.h"
#include "render/TransferFunction.h"
#include "server/FrameCache.h"

#include <fstream>
#include <functional>

namespace bc::server::test {
namespace {

void makeStore(const std::string& path, brickstore::SynthKind kind) {
    auto source = brickstore::makeSynthetic(kind, {32, 32, 32}, 1);
    brickstore::IngestConfig config;
    config.geometry = {32, 2, 8};
    brickstore::ingest(*source, path, config); // renamed into place: a new file
}

class FrameCacheTest : public ::testing::Test {
  protected:
    void start(std::uint64_t cacheBytes, std::uint64_t edge = 64) {
        DaemonConfig c = generatedConfig(dir, {{"phantom", edge}});
        serve(std::move(c), cacheBytes);
    }
    void serve(DaemonConfig c, std::uint64_t cacheBytes) {
        c.metricsHost = "127.0.0.1";
        c.metricsPort = 0;
        c.frameCacheBytes = cacheBytes;
        daemon = std::make_unique<TestDaemon>(std::move(c));
        metricsPort = daemon->daemon->metricsPort();
    }
    double metric(const std::string& name) {
        const std::string reply =
            scrape(metricsPort, "GET /metrics HTTP/1.1\r\nHost: 127.0.0.1\r\n\r\n");
        return sampleOf(reply.substr(reply.find("\r\n\r\n") + 4), "brickcast_" + name);
    }
    double drawn() { return metric("frames_total{renderer=\"cpu\"}"); }
    std::unique_ptr<client::Client> session(const std::string& volumeName = "phantom") {
        auto c = std::make_unique<client::Client>(daemon->clientConfig());
        volume = c->openVolume(volumeName);
        c->setRenderOptions(options);
        return c;
    }
    /// The Frame message (image as encoded) answering a request for `azDeg` under `preset`.
    protocol::Frame frame(client::Client& c, double azDeg, std::uint32_t cameraId,
                          const std::string& preset = "ct-bone") {
        protocol::SetTransferFunction tf;
        tf.preset = preset;
        c.setTransferFunction(tf);
        c.setCamera(orbitCamera(volume, azDeg, cameraId));
        c.requestFrame();
        for (;;) {
            auto m = c.nextMessage();
            if (auto* f = std::get_if<protocol::Frame>(&m)) return *f;
            if (auto* e = std::get_if<protocol::Error>(&m)) {
                ADD_FAILURE() << "Error: " << e->message;
                return {};
            }
        }
    }

    TempDir dir;
    std::unique_ptr<TestDaemon> daemon;
    std::uint16_t metricsPort = 0;
    protocol::VolumeInfo volume;
    protocol::RenderOptions options = smallCpuFrames(48);
};

TEST_F(FrameCacheTest, ASecondSessionGetsTheSameBytesWithoutARender) {
    start(64ull << 20);
    auto a = session();
    const protocol::Frame first = frame(*a, 30, 1);
    EXPECT_FALSE(first.header.cached);
    EXPECT_GT(first.header.samples, 0u);
    EXPECT_EQ(drawn(), 1);
    EXPECT_EQ(metric("frame_cache_misses_total"), 1);
    EXPECT_EQ(metric("frame_cache_entries"), 1);
    EXPECT_EQ(metric("frame_cache_bytes"), double(first.image.size()));

    auto b = session();
    const protocol::Frame second = frame(*b, 30, 7);
    EXPECT_TRUE(second.header.cached);
    EXPECT_EQ(second.image, first.image) << "not the bytes drawn for the first session";
    EXPECT_EQ(second.header.cameraId, 7u) << "the answer names this session's camera";
    EXPECT_EQ(second.header.samples, 0u) << "nothing was drawn";
    EXPECT_EQ(second.header.width, first.header.width);
    EXPECT_EQ(second.header.level, first.header.level);
    EXPECT_EQ(drawn(), 1) << "the second session's frame was drawn again";
    EXPECT_EQ(metric("frame_cache_hits_total"), 1);

    // The first session asking again (a refined frame at rest asked for twice) is a hit too.
    EXPECT_TRUE(frame(*a, 30, 2).header.cached);
    // So is an adaptive session's frame at rest: the refined frame of the same view.
    options.quality = protocol::Quality::Adaptive;
    const protocol::Frame adaptive = frame(*session(), 30, 3);
    EXPECT_TRUE(adaptive.header.cached);
    EXPECT_TRUE(adaptive.header.refined);
    EXPECT_EQ(adaptive.image, first.image);
    EXPECT_EQ(drawn(), 1);
}

TEST_F(FrameCacheTest, DeltaFramesFromTheCacheAreEachSessionsOwnDelta) {
    options.codec = protocol::Codec::ZstdDelta;
    start(64ull << 20);
    auto decoded = [&](client::Client& c, double azDeg, std::uint32_t cameraId) {
        c.setCamera(orbitCamera(volume, azDeg, cameraId));
        c.requestFrame();
        return c.nextFrame(); // decoded against this client's own delta base
    };
    auto a = session();
    const client::ReceivedFrame a30 = decoded(*a, 30, 1);
    const client::ReceivedFrame a60 = decoded(*a, 60, 2);
    ASSERT_FALSE(a60.header.keyframe);
    ASSERT_TRUE(decoded(*a, 30, 3).header.cached);

    auto b = session(); // a new connection: no delta base
    const client::ReceivedFrame b60 = decoded(*b, 60, 1);
    EXPECT_TRUE(b60.header.cached);
    EXPECT_TRUE(b60.header.keyframe) << "a first frame must be a keyframe";
    EXPECT_EQ(b60.rgba, a60.rgba);
    const client::ReceivedFrame b30 = decoded(*b, 30, 2);
    EXPECT_TRUE(b30.header.cached);
    EXPECT_FALSE(b30.header.keyframe) << "a delta against this session's previous frame";
    EXPECT_EQ(b30.rgba, a30.rgba);
    EXPECT_EQ(drawn(), 2);
}

TEST_F(FrameCacheTest, ATransferFunctionOrOptionChangeIsDrawnAnew) {
    start(64ull << 20);
    auto a = session();
    const protocol::Frame bone = frame(*a, 30, 1);
    auto b = session();
    const protocol::Frame skin = frame(*b, 30, 1, "ct-skin");
    EXPECT_FALSE(skin.header.cached) << "another transfer function";
    EXPECT_NE(skin.image, bone.image);
    EXPECT_TRUE(frame(*b, 30, 2, "ct-bone").header.cached) << "back to the first function";

    options.stepVoxels = 0.5f;
    b->setRenderOptions(options);
    EXPECT_FALSE(frame(*b, 30, 3).header.cached) << "another step";
    options.stepVoxels = 1;
    options.techniques &= ~protocol::kTechEarlyTermination;
    b->setRenderOptions(options);
    EXPECT_FALSE(frame(*b, 30, 4).header.cached) << "another technique set";
    options.techniques = protocol::kTechAll;
    options.codec = protocol::Codec::Png;
    b->setRenderOptions(options);
    EXPECT_FALSE(frame(*b, 30, 5).header.cached) << "another codec";
    EXPECT_FALSE(frame(*b, 31, 6).header.cached) << "another camera";
    options.codec = protocol::Codec::Zstd;
    b->setRenderOptions(options);
    const protocol::Frame again = frame(*b, 30, 7);
    EXPECT_TRUE(again.header.cached);
    EXPECT_EQ(again.image, bone.image);
    EXPECT_EQ(drawn(), 6);
}

TEST_F(FrameCacheTest, AStoreReopenedUnderTheSameNameIsDrawnAnew) {
    makeStore(dir.file("swap.bcs"), brickstore::SynthKind::Vessels);
    const std::string config = dir.file("brickcastd.toml");
    std::ofstream(config) << "[server]\nlisten = \"127.0.0.1:0\"\n[[volume]]\nname = \"swap\"\n"
                             "store = \"swap.bcs\"\n";
    serve(DaemonConfig::load(config), 64ull << 20);
    auto a = session("swap");
    const protocol::Frame before = frame(*a, 30, 1);
    ASSERT_TRUE(frame(*session("swap"), 30, 1).header.cached);

    // Another store of the same name and shape, other voxels: the session moves to it.
    makeStore(dir.file("swap.bcs"), brickstore::SynthKind::Checker);
    daemon->daemon->reload();
    for (bool moved = false; !moved;) { // the reload applied: the session is told, unasked
        auto m = a->nextMessage();
        if (std::holds_alternative<protocol::Error>(m)) FAIL() << "the session got an Error";
        moved = std::holds_alternative<protocol::VolumeOpened>(m);
    }
    auto fresh = session("swap");
    const protocol::Frame after = frame(*fresh, 30, 2);
    EXPECT_FALSE(after.header.cached) << "a frame of the replaced store was sent";
    EXPECT_NE(after.image, before.image);
    EXPECT_TRUE(frame(*session("swap"), 30, 3).header.cached) << "the new store's frame is kept";
}

TEST_F(FrameCacheTest, TheCacheStaysWithinItsBudget) {
    options.codec = protocol::Codec::Raw; // 64 x 64 x 4 = 16 KiB a frame, whatever it shows
    options.width = options.height = 64;
    const std::uint64_t budget = 100 * 1024; // six frames
    start(budget, 32);
    auto a = session();
    for (std::uint32_t i = 0; i < 12; ++i)
        EXPECT_FALSE(frame(*a, 10.0 * i, i + 1).header.cached);
    EXPECT_LE(metric("frame_cache_bytes"), double(budget));
    EXPECT_EQ(metric("frame_cache_entries"), 6);
    EXPECT_EQ(metric("frame_cache_evictions_total"), 6);
    EXPECT_TRUE(frame(*a, 110, 20).header.cached) << "the newest frame was evicted";
    EXPECT_FALSE(frame(*a, 0, 21).header.cached) << "the oldest frame was kept";

    // A frame over a quarter of the budget is not kept at all.
    options.width = options.height = 128; // 64 KiB
    a->setRenderOptions(options);
    EXPECT_FALSE(frame(*a, 0, 22).header.cached);
    EXPECT_FALSE(frame(*a, 0, 23).header.cached);
    EXPECT_EQ(metric("frame_cache_too_large_total"), 2);
}

TEST_F(FrameCacheTest, ABudgetOfZeroTurnsItOff) {
    start(0);
    auto a = session();
    frame(*a, 30, 1);
    auto b = session();
    const protocol::Frame again = frame(*b, 30, 2);
    EXPECT_FALSE(again.header.cached);
    EXPECT_GT(again.header.samples, 0u);
    EXPECT_EQ(drawn(), 2);
    EXPECT_EQ(metric("frame_cache_hits_total"), 0);
    EXPECT_EQ(metric("frame_cache_misses_total"), 0);
    EXPECT_EQ(metric("frame_cache_budget_bytes"), 0);
}

/// What a key is made of, each field as frameKeyOf takes it.
struct KeyFields {
    std::uint64_t storeInstance = 1;
    std::string renderer = "cpu";
    bool refined = true, shading = true;
    render::Camera camera;
    protocol::RenderOptions options = smallCpuFrames(48);
    std::shared_ptr<const render::TransferFunction> tf;
    protocol::SetModeAndClip modeAndClip;
    FrameKey key() const {
        return frameKeyOf(storeInstance, renderer, refined, shading, camera, options, tf,
                          modeAndClip);
    }
};

std::shared_ptr<const render::TransferFunction> functionPeakingAt(double value) {
    render::VolumeValueStats stats;
    stats.valueMin = 0;
    stats.valueMax = 255;
    const std::string json = R"({"name":"t","points":[{"value":)" + std::to_string(value) +
                             R"(,"rgba":[0.9,0.7,0.4,0]},{"value":255,"rgba":[0.9,0.7,0.4,0.6]}]})";
    return std::make_shared<const render::TransferFunction>(
        render::TransferFunction::parse(json, "<test>", stats));
}

TEST(FrameKeyTest, IdenticalViewsAreOneKey) {
    KeyFields a;
    a.camera.eye = {1, 2, 3};
    a.tf = functionPeakingAt(100);
    KeyFields b = a;
    b.tf = functionPeakingAt(100); // another object, the same function
    EXPECT_TRUE(a.key().matches(b.key()));
    EXPECT_EQ(a.key().hash(), b.key().hash());
    // What the renderer and quality asked for decide the key's renderer and refined: not kept.
    b.options.renderer = protocol::Renderer::Auto;
    b.options.quality = protocol::Quality::Interactive;
    EXPECT_TRUE(a.key().matches(b.key()));
    EXPECT_EQ(a.key().hash(), b.key().hash());
}

TEST(FrameKeyTest, ViewsDifferingInAnyFieldAreTwoKeys) {
    KeyFields base;
    base.camera.eye = {100, 50, 25};
    base.camera.target = {1, 2, 3};
    base.options.refinedCodec = protocol::Codec::Png;
    base.tf = functionPeakingAt(100);
    const std::vector<std::pair<std::string, std::function<void(KeyFields&)>>> changes = {
        {"store", [](KeyFields& v) { v.storeInstance = 2; }},
        {"renderer", [](KeyFields& v) { v.renderer = "gpu"; }},
        {"refined", [](KeyFields& v) { v.refined = false; }},
        {"shading", [](KeyFields& v) { v.shading = false; }},
        {"eye.x", [](KeyFields& v) { v.camera.eye.x += 1e-9; }},
        {"eye.y", [](KeyFields& v) { v.camera.eye.y += 1; }},
        {"eye.z", [](KeyFields& v) { v.camera.eye.z += 1; }},
        {"target.x", [](KeyFields& v) { v.camera.target.x += 1; }},
        {"target.y", [](KeyFields& v) { v.camera.target.y += 1; }},
        {"target.z", [](KeyFields& v) { v.camera.target.z += 1; }},
        {"up.x", [](KeyFields& v) { v.camera.up.x = 0.5; }},
        {"up.y", [](KeyFields& v) { v.camera.up.y = 0.5; }},
        {"up.z", [](KeyFields& v) { v.camera.up.z = 0.5; }},
        {"up.x -0 for 0", [](KeyFields& v) { v.camera.up.x = -0.0; }}, // bit for bit
        {"fovYDeg", [](KeyFields& v) { v.camera.fovYDeg = 31; }},
        {"orthographic", [](KeyFields& v) { v.camera.orthographic = true; }},
        {"orthoHeight", [](KeyFields& v) { v.camera.orthoHeight = 2; }},
        {"width", [](KeyFields& v) { v.options.width += 1; }},
        {"height", [](KeyFields& v) { v.options.height += 1; }},
        {"stepVoxels", [](KeyFields& v) { v.options.stepVoxels = 0.5f; }},
        {"techniques", [](KeyFields& v) { v.options.techniques &= ~protocol::kTechJitter; }},
        {"ertThreshold", [](KeyFields& v) { v.options.ertThreshold = 0.95f; }},
        {"codec", [](KeyFields& v) { v.options.codec = protocol::Codec::Raw; }},
        {"codecQuality", [](KeyFields& v) { v.options.codecQuality = 5; }},
        {"level", [](KeyFields& v) { v.options.level = 1; }},
        {"refinedCodec", [](KeyFields& v) { v.options.refinedCodec.reset(); }},
        {"flags", [](KeyFields& v) { v.options.flags = protocol::kFlagUnscaledInteractive; }},
        {"another function", [](KeyFields& v) { v.tf = functionPeakingAt(120); }},
        {"no function", [](KeyFields& v) { v.tf = nullptr; }},
        {"mode", [](KeyFields& v) { v.modeAndClip.mode = protocol::BlendMode::Maximum; }},
        {"isoValue", [](KeyFields& v) { v.modeAndClip.isoValue = 1; }},
        {"crop",
         [](KeyFields& v) {
             v.modeAndClip.cropped = true;
             v.modeAndClip.cropMax = {1, 1, 1};
         }},
        {"plane", [](KeyFields& v) { v.modeAndClip.planes = {protocol::ClipPlane{}}; }},
    };
    const FrameKey key = base.key();
    for (const auto& [field, change] : changes) {
        KeyFields other = base;
        change(other);
        EXPECT_FALSE(key.matches(other.key())) << field;
        EXPECT_FALSE(other.key().matches(key)) << field;
        EXPECT_TRUE(other.key().matches(other.key())) << field;
    }
}

} // namespace
} // namespace bc::server::test
