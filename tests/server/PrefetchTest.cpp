// Prefetch: while the render thread is idle, the bricks of each GPU session's
// predicted next view that the pool lacks are uploaded ahead of need. A close-up orbit that
// brings new bricks into view every frame, with think time between frames: with prefetch on,
// frames wait for far fewer uploads, and every frame is the one drawn without it.
#include "ServerTestSupport.h"

#include "../render/RenderTestSupport.h"
#include "brickstore/Readers.h"

namespace bc::server::test {
namespace {

struct Flight {
    std::vector<client::ReceivedFrame> frames;
    double frameUploads = 0, prefetchUploads = 0;
};

double statOf(const std::vector<std::pair<std::string, double>>& stats, const std::string& name) {
    for (const auto& [k, v] : stats)
        if (k == name) return v;
    return -1;
}

Flight fly(const std::string& storePath, bool prefetch) {
    TempDir dir;
    DaemonConfig c;
    c.source = "<test>";
    c.storeDir = dir.path().string();
    CatalogEntry e;
    e.name = "p";
    e.store = storePath;
    c.volumes.push_back(e);
    c.gpuBudgetBytes =
        8ull << 20; // ~1000 slots of 20^3 u16: more than a view, less than the volume
    c.prefetch = prefetch;
    TestDaemon d(c);
    client::Client cl(d.clientConfig());
    const auto v = cl.openVolume("p");
    protocol::RenderOptions o;
    o.width = o.height = 40;
    o.renderer = protocol::Renderer::GpuRaycaster;
    o.quality = protocol::Quality::Refined;
    o.codec = protocol::Codec::Raw;
    cl.setRenderOptions(o);
    Flight run;
    for (std::uint32_t f = 0; f < 10; ++f) {
        cl.setCamera(client::orbitCamera(v, 30.0 + 6.0 * f, 15.0, 0.3, f + 1));
        cl.requestFrame();
        run.frames.push_back(cl.nextFrame());
        std::this_thread::sleep_for(std::chrono::milliseconds(150)); // a viewer's think time
    }
    const auto s = cl.stats();
    run.frameUploads = statOf(s, "gpu_frame_uploads_total{volume=\"p\"}");
    run.prefetchUploads = statOf(s, "gpu_prefetch_uploads_total{volume=\"p\"}");
    return run;
}

TEST(Prefetch, UploadsTheNextViewsBricksAheadAndChangesNoFrame) {
    bc::test::glContext();
    auto source = brickstore::makeSynthetic(brickstore::SynthKind::Phantom, {128, 128, 128}, 1);
    auto t = bc::test::ingestStore(*source, {16, 2, 8});
    const Flight off = fly(t->store->path(), false), on = fly(t->store->path(), true);
    std::printf("[prefetch] uploads while frames waited: %.0f off, %.0f on (+%.0f prefetched)\n",
                off.frameUploads, on.frameUploads, on.prefetchUploads);
    EXPECT_EQ(off.prefetchUploads, 0);
    EXPECT_GT(on.prefetchUploads, 0);
    EXPECT_GT(off.frameUploads, 0);
    // Frames 0 and 1 upload the same either way (a cold pool; no motion to extrapolate yet).
    auto bytesFrom = [](const Flight& f, std::size_t first) {
        std::uint64_t b = 0;
        for (std::size_t i = first; i < f.frames.size(); ++i)
            b += f.frames[i].header.bytesUploaded;
        return double(b);
    };
    constexpr double kSlotBytes = 20.0 * 20 * 20 * 2; // 16^3 bricks, 2-voxel apron, u16
    EXPECT_EQ(bytesFrom(off, 0), off.frameUploads * kSlotBytes) << "the counter is the frames' sum";
    EXPECT_EQ(bytesFrom(on, 0), on.frameUploads * kSlotBytes);
    EXPECT_LT(bytesFrom(on, 2), 0.5 * bytesFrom(off, 2))
        << "prefetch did not get ahead of the frames";
    ASSERT_EQ(on.frames.size(), off.frames.size());
    for (std::size_t i = 0; i < on.frames.size(); ++i)
        std::printf("[prefetch] frame %zu: %u bricks, uploaded %llu B off, %llu B on\n", i,
                    on.frames[i].header.bricksDrawn,
                    (unsigned long long)off.frames[i].header.bytesUploaded,
                    (unsigned long long)on.frames[i].header.bytesUploaded);
    for (std::size_t i = 0; i < on.frames.size(); ++i) {
        int worst = 0;
        for (std::size_t k = 0; k < on.frames[i].rgba.size(); ++k)
            worst =
                std::max(worst, std::abs(int(on.frames[i].rgba[k]) - int(off.frames[i].rgba[k])));
        EXPECT_LE(worst, 2) << "frame " << i; // the skipping invariant's bound (pool slots differ)
    }
}

} // namespace
} // namespace bc::server::test
