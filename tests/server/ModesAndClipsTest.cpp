// SetModeAndClip through the daemon: a session's MIP, isosurface and average of a cropped,
// clipped volume are the direct render of the same request, to the byte (raw codec); the
// cut is part of the frame cache's key; bad values are answered naming the field and the
// session goes on.
#include "ServerTestSupport.h"

#include "../render/RenderTestSupport.h"
#include "render/CpuRaycaster.h"
#include "server/ViewRequest.h"

namespace bc::server::test {
namespace {

class ModesAndClips : public ::testing::Test {
  protected:
    static void SetUpTestSuite() {
        auto source = brickstore::makeSynthetic(brickstore::SynthKind::Phantom, {48, 48, 40}, 1);
        sStore = bc::test::ingestStore(*source, {16, 2, 4}).release();
    }
    static void TearDownTestSuite() {
        delete sStore;
        sStore = nullptr;
    }
    static DaemonConfig config() {
        DaemonConfig c;
        c.source = "<test>";
        CatalogEntry e;
        e.name = "p";
        e.store = sStore->store->path();
        c.volumes.push_back(e);
        return c;
    }
    static protocol::RenderOptions options(protocol::Renderer renderer) {
        protocol::RenderOptions o;
        o.width = 64;
        o.height = 56;
        o.renderer = renderer;
        o.codec = protocol::Codec::Raw;
        o.quality = protocol::Quality::Refined;
        return o;
    }
    /// A MIP inside a crop box of the volume's middle and on one side of an oblique plane.
    static protocol::SetModeAndClip cutMip(const protocol::VolumeInfo& v) {
        protocol::SetModeAndClip m;
        m.mode = protocol::BlendMode::Maximum;
        m.cropped = true;
        for (int a = 0; a < 3; ++a) {
            const double size = v.dims[a] * v.spacingMm[a];
            m.cropMin[a] = 0.15 * size;
            m.cropMax[a] = 0.85 * size;
        }
        m.planes = {protocol::ClipPlane{{1, 0.5, -0.25}, -0.5 * v.dims[0] * v.spacingMm[0]}};
        return m;
    }
    /// The frame the CPU raycaster draws for the same request.
    static std::vector<std::uint8_t> direct(const protocol::SetCamera& camera,
                                            const protocol::SetTransferFunction& tfMessage,
                                            const protocol::RenderOptions& o,
                                            const protocol::SetModeAndClip& m) {
        const auto tf = toTransferFunction(
            tfMessage, render::VolumeValueStats::fromStore(sStore->store->info()), {});
        render::RenderOptions r = toRenderOptions(o, 1);
        applyModeAndClip(r, m);
        r.shading = shadingFor(o, tfMessage, *tf);
        render::CpuRaycaster cpu;
        render::FrameStats stats;
        return render::toRgba8(
            cpu.render(*sStore->store, *sStore->cache, *tf, toCamera(camera), r, stats));
    }
    static bc::test::TestStore* sStore;
};
bc::test::TestStore* ModesAndClips::sStore = nullptr;

protocol::SetTransferFunction preset(const std::string& name) {
    protocol::SetTransferFunction tf;
    tf.preset = name;
    return tf;
}

TEST_F(ModesAndClips, EachModeOfACutVolumeIsTheDirectRenderOfTheRequest) {
    TestDaemon d(config());
    client::Client c(d.clientConfig());
    EXPECT_TRUE(c.server().capabilities & protocol::kCapModesAndClips);
    const auto v = c.openVolume("p");
    const auto o = options(protocol::Renderer::CpuRaycaster);
    c.setRenderOptions(o);
    const auto tf = preset("ct-bone");
    c.setTransferFunction(tf);
    protocol::SetModeAndClip m = cutMip(v);
    std::uint32_t id = 1;
    for (const auto mode : {protocol::BlendMode::Maximum, protocol::BlendMode::Isosurface,
                            protocol::BlendMode::Average, protocol::BlendMode::Composite}) {
        SCOPED_TRACE(int(mode));
        m.mode = mode;
        m.isoValue = mode == protocol::BlendMode::Isosurface ? 0.5 * (v.valueMin + v.valueMax) : 0;
        c.setModeAndClip(m);
        const auto camera = orbitCamera(v, 30.0 * id, id);
        c.setCamera(camera);
        c.requestFrame();
        const client::ReceivedFrame f = c.nextFrame();
        EXPECT_EQ(f.header.cameraId, id);
        EXPECT_EQ(f.rgba, direct(camera, tf, o, m));
        ++id;
    }
    // Uncut, the same view differs: the cut reached the renderer.
    const auto camera = orbitCamera(v, 30.0 * (id - 1), id);
    c.setModeAndClip({});
    c.setCamera(camera);
    c.requestFrame();
    const client::ReceivedFrame uncut = c.nextFrame();
    EXPECT_EQ(uncut.rgba, direct(camera, tf, o, {}));
    EXPECT_NE(uncut.rgba, direct(camera, tf, o, m));
}

TEST_F(ModesAndClips, TheCutIsPartOfTheFrameCachesKey) {
    TestDaemon d(config()); // the frame cache is on by default
    client::Client c(d.clientConfig());
    const auto v = c.openVolume("p");
    c.setRenderOptions(options(protocol::Renderer::CpuRaycaster));
    const auto camera = orbitCamera(v, 40, 1);
    c.setCamera(camera);
    c.requestFrame();
    const auto plain = c.nextFrame();
    c.setModeAndClip(cutMip(v));
    c.requestFrame();
    const auto cut = c.nextFrame();
    EXPECT_FALSE(cut.header.cached) << "a cut view was answered with the uncut frame";
    EXPECT_NE(cut.rgba, plain.rgba);
    c.requestFrame();
    EXPECT_TRUE(c.nextFrame().header.cached) << "the same cut view again is the cache's";
}

TEST_F(ModesAndClips, BadValuesAreNamedAndTheSessionGoesOn) {
    TestDaemon d(config());
    client::Client c(d.clientConfig());
    const auto v = c.openVolume("p");
    c.setRenderOptions(options(protocol::Renderer::CpuRaycaster));
    auto expectError = [&](const protocol::SetModeAndClip& m, const std::string& named) {
        c.setModeAndClip(m);
        try {
            c.listVolumes(); // the Error arrives before this reply
            ADD_FAILURE() << "accepted: " << named;
        } catch (const client::ServerError& e) {
            EXPECT_EQ(e.code(), protocol::ErrorCode::OutOfRange) << e.what();
            EXPECT_NE(std::string(e.what()).find(named), std::string::npos) << e.what();
            EXPECT_FALSE(e.fatal());
        }
    };
    protocol::SetModeAndClip iso;
    iso.mode = protocol::BlendMode::Isosurface;
    iso.isoValue = v.valueMax + 1;
    expectError(iso, "SetModeAndClip.isoValue");
    // The encoder refuses what the decoder would: such bytes are written by hand.
    protocol::SetModeAndClip inverted = cutMip(v);
    std::vector<std::uint8_t> bytes = protocol::encode(inverted, 77);
    const double zero = 0.0;
    std::memcpy(bytes.data() + protocol::kHeaderBytes + 34, &zero, 8); // cropMax[0] = 0
    RawConnection raw(d.port);
    raw.send(protocol::Hello{}, 1);
    ASSERT_TRUE(raw.next());
    raw.send(bytes);
    const auto e = raw.nextError();
    ASSERT_TRUE(e);
    EXPECT_NE(e->message.find("SetModeAndClip.cropMax"), std::string::npos) << e->message;
    EXPECT_FALSE(e->fatal);
    // A renderer that draws composite only: its frame is an Error naming the mode.
    protocol::SetModeAndClip mip;
    mip.mode = protocol::BlendMode::Maximum;
    c.setModeAndClip(mip);
    c.setRenderOptions(options(protocol::Renderer::Splatter));
    c.setCamera(orbitCamera(v, 20, 1));
    c.requestFrame();
    try {
        c.nextFrame();
        ADD_FAILURE() << "the splatter drew a MIP";
    } catch (const client::ServerError& e) {
        EXPECT_NE(std::string(e.what()).find("composite only, not mip"), std::string::npos)
            << e.what();
    }
    // The session goes on.
    c.setRenderOptions(options(protocol::Renderer::CpuRaycaster));
    c.requestFrame();
    EXPECT_EQ(c.nextFrame().header.width, 64u);
}

} // namespace
} // namespace bc::server::test
