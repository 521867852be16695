// Prefetch: while the render thread is idle, the bricks of each GPU session's
// predicted next view that the pool lacks are uploaded ahead of need. A close-up orbit that
// brings new bricks into view every frame, with think time between frames: with prefetch on,
// frames wait for far fewer uploads, and every frame is the one drawn without it. And what is
// planned without a GPU (server/Prefetch.h): the view predicted, the bricks to leave in the pool
// and the bounded steps.
#include "ServerTestSupport.h"

#include "../render/RenderTestSupport.h"
#include "brickstore/Readers.h"
#include "render/View.h"
#include "server/Prefetch.h"

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
        // A viewer's think time: the render thread prefetches what the next view may need, and
        // goes idle once it has.
        EXPECT_TRUE(renderIdle(cl));
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

void expectSameCamera(const render::Camera& a, const render::Camera& b) {
    EXPECT_EQ(a.eye, b.eye);
    EXPECT_EQ(a.target, b.target);
    EXPECT_EQ(a.up, b.up);
    EXPECT_EQ(a.fovYDeg, b.fovYDeg);
    EXPECT_EQ(a.orthographic, b.orthographic);
    EXPECT_EQ(a.orthoHeight, b.orthoHeight);
}

TEST(PrefetchPlanTest, TheNextViewIsPredictedFromTheLastTwo) {
    render::Box box;
    box.max = glm::dvec3(100.0);
    const render::Camera c1 = render::Camera::orbit(box, 30, 20),
                         c2 = render::Camera::orbit(box, 36, 20),
                         c3 = render::Camera::orbit(box, 42, 20),
                         c4 = render::Camera::orbit(box, 48, 20);
    SessionPrefetch p;
    EXPECT_FALSE(p.afterFrame(c1, true).has_value()) << "one view: no motion to go on";
    const auto next = p.afterFrame(c2, true);
    ASSERT_TRUE(next.has_value());
    expectSameCamera(*next, render::predictNext(c1, c2));
    // Not planned (prefetch off, or no pool yet): the job planned before is dropped, and the
    // views are still followed.
    p.job = PrefetchJob{};
    EXPECT_FALSE(p.afterFrame(c3, false).has_value());
    EXPECT_FALSE(p.job.has_value());
    const auto after = p.afterFrame(c4, true);
    ASSERT_TRUE(after.has_value());
    expectSameCamera(*after, render::predictNext(c3, c4));
}

TEST(PrefetchPlanTest, AStepLeavesTheLastFramesBricksAndUploadsAtMost32) {
    PrefetchStep s = prefetchStep(60, 100);
    EXPECT_EQ(s.room, 40u);
    EXPECT_EQ(s.bricks, kPrefetchStepBricks);
    EXPECT_TRUE(s.continues(32)) << "all it could upload: more may be missing";
    EXPECT_FALSE(s.continues(31)) << "the view's missing bricks ran out";
    s = prefetchStep(90, 100);
    EXPECT_EQ(s.room, 10u);
    EXPECT_EQ(s.bricks, 10u);
    EXPECT_FALSE(s.continues(10)) << "the pool's room is used up";
    EXPECT_EQ(prefetchStep(100, 100).room, 0u);
    EXPECT_EQ(prefetchStep(500, 100).room, 0u) << "a frame larger than the pool";
    EXPECT_EQ(prefetchStep(0, 0).room, 0u);
    s = prefetchStep(0, 1000);
    EXPECT_EQ(s.room, 1000u);
    EXPECT_EQ(s.bricks, 32u);
}

TEST(PrefetchPlanTest, AFramesResidentBricksAreThoseItDrewLessThoseLeftUnloaded) {
    render::FrameStats s;
    s.bricksVisited = 10;
    s.bricksConstant = 2;
    EXPECT_EQ(residentBricks(s), 8u);
    s.bricksDeferred = 3;
    s.bricksRequested = 1;
    EXPECT_EQ(residentBricks(s), 6u);
    s.bricksRequested = 5; // more requested than deferred (slices' sums): none unloaded
    EXPECT_EQ(residentBricks(s), 8u);
    s.bricksDeferred = 20;
    s.bricksRequested = 0;
    EXPECT_EQ(residentBricks(s), 0u) << "never below zero";
}

} // namespace
} // namespace bc::server::test
