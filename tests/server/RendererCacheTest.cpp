// What the render thread keeps between turns (server/RendererCache.h): the GPU pool rule that
// the daemon and the MPI ranks share (a pool is made anew only when its volume's share moved by
// more than an eighth), the sessions' own state and its pruning, and renderers made once and
// shared per volume or kept per session. Nothing here needs a GPU.
#include "ServerTestSupport.h"

#include "render/RendererRegistry.h"
#include "server/Catalog.h"
#include "server/RenderService.h"
#include "server/RendererCache.h"

#include <chrono>
#include <limits>

namespace bc::server::test {
namespace {

TEST(RendererCacheTest, APoolIsKeptWhileItsShareStaysWithinAnEighth) {
    const std::uint64_t pool = 800;
    for (const std::uint64_t share : {800ull, 700ull, 900ull, 750ull, 850ull})
        EXPECT_FALSE(poolOutgrown(pool, share)) << share;
    EXPECT_TRUE(poolOutgrown(pool, 699)) << "shrunk past an eighth";
    EXPECT_TRUE(poolOutgrown(pool, 901)) << "grown past an eighth";
    EXPECT_TRUE(poolOutgrown(pool, 400)) << "half";
    EXPECT_TRUE(poolOutgrown(pool, 1600)) << "twice";
    // A session more or fewer among eight on one volume keeps the pool; among two it does not.
    const std::uint64_t gpu = 512ull << 20;
    EXPECT_FALSE(poolOutgrown(gpu / 8 * 8, gpu / 8 * 7));
    EXPECT_FALSE(poolOutgrown(gpu / 8 * 8, gpu / 8 * 9));
    EXPECT_TRUE(poolOutgrown(gpu / 2 * 2, gpu / 2 * 1));
}

TEST(RendererCacheTest, ThePoolRuleAtItsEdges) {
    // No budget yet: any share is another pool; an eighth of under 8 bytes is nothing.
    EXPECT_FALSE(poolOutgrown(0, 0));
    EXPECT_TRUE(poolOutgrown(0, 1));
    EXPECT_FALSE(poolOutgrown(7, 7));
    EXPECT_TRUE(poolOutgrown(7, 6));
    EXPECT_TRUE(poolOutgrown(7, 8));
    EXPECT_FALSE(poolOutgrown(8, 7));
    EXPECT_FALSE(poolOutgrown(8, 9));
    EXPECT_TRUE(poolOutgrown(8, 6));
    EXPECT_TRUE(poolOutgrown(8, 10));
    // The bounds are inclusive, exactly an eighth either way, at any size.
    const std::uint64_t big = 1ull << 40, eighth = big / 8;
    EXPECT_FALSE(poolOutgrown(big, big - eighth));
    EXPECT_FALSE(poolOutgrown(big, big + eighth));
    EXPECT_TRUE(poolOutgrown(big, big - eighth - 1));
    EXPECT_TRUE(poolOutgrown(big, big + eighth + 1));
    EXPECT_TRUE(poolOutgrown(big, 0));
}

TEST(RendererCacheTest, ASlotHoldsOneStoredBrickApronIncluded) {
    const TempDir dir;
    auto source = brickstore::makeSynthetic(brickstore::SynthKind::Phantom, {32, 32, 32}, 1);
    brickstore::IngestConfig config;
    config.geometry = {16, 2, 8};
    brickstore::ingest(*source, dir.file("p.bcs"), config);
    const auto store = brickstore::BrickStore::open(dir.file("p.bcs"));
    EXPECT_EQ(store->layout().storedEdge(), 20u);
    EXPECT_EQ(slotBytesOf(*store),
              20u * 20u * 20u * brickstore::voxelBytes(store->info().volume.type));
    EXPECT_EQ(slotBytesOf(*store), store->brickBytes());
}

/// A render service to make slots for (its thread never sees them), and a cache of its own.
struct RendererCacheSessions : ::testing::Test {
    Log log{true};
    DaemonConfig config;
    Catalog catalog{config, log};
    RenderService service{RenderServiceConfig{}, catalog, log};
    std::vector<std::string> retired;
    RendererCache cache{catalog, 64ull << 20,
                        [this](const std::string& volume) { retired.push_back(volume); }};

    std::shared_ptr<RenderSlot> slot() {
        return std::make_shared<RenderSlot>(service, nullptr, 4, 1ull << 20);
    }
    static std::shared_ptr<Volume> volume(const std::string& name) {
        auto v = std::make_shared<Volume>();
        v->name = name;
        return v;
    }
};

TEST_F(RendererCacheSessions, EachSlotHasItsOwnSessionUntilItGoes) {
    auto a = slot(), b = slot();
    cache.of(a).lastPassIndex = 3;
    EXPECT_EQ(cache.of(a).lastPassIndex, 3u) << "the same session on every turn";
    EXPECT_EQ(cache.of(b).lastPassIndex, 0u);
    EXPECT_FALSE(cache.drawing(a.get()));
    cache.of(a).drawing = std::make_unique<FrameDrawing>();
    EXPECT_TRUE(cache.drawing(a.get()));
    EXPECT_FALSE(cache.drawing(b.get()));
    EXPECT_EQ(cache.prune(), 0u) << "both slots are open";
    EXPECT_EQ(cache.sessions.size(), 2u);
    a.reset();
    EXPECT_EQ(cache.prune(), 1u) << "the closed session's frame in progress is dropped";
    EXPECT_EQ(cache.sessions.size(), 1u);
    b.reset();
    EXPECT_EQ(cache.prune(), 0u);
    EXPECT_TRUE(cache.sessions.empty());
}

TEST_F(RendererCacheSessions, AVolumesRenderersStayWhileItHasSessionsOrAFrameInProgress) {
    auto v = volume("v");
    cache.volumes[v.get()].volume = v;
    v->sessions = 1;
    cache.prune();
    EXPECT_EQ(cache.volumes.size(), 1u) << "a session views it";
    v->sessions = 0;
    auto s = slot();
    cache.of(s).drawing = std::make_unique<FrameDrawing>();
    cache.of(s).drawing->job.state.volume = v;
    cache.prune();
    EXPECT_EQ(cache.volumes.size(), 1u) << "a frame of it is being drawn";
    cache.of(s).drawing.reset();
    cache.prune();
    EXPECT_TRUE(cache.volumes.empty());
    EXPECT_TRUE(retired.empty()) << "it had no GPU pool to retire";
}

TEST_F(RendererCacheSessions, InteractiveSessionsAreThoseRecentlyMovingOrDrawingAMovingFrame) {
    const auto now = Clock::now();
    auto a = slot(), b = slot(), c = slot(), gone = slot();
    cache.of(a).lastInteractive = now - std::chrono::milliseconds(500);
    cache.of(b).lastInteractive = now - std::chrono::seconds(2);
    cache.of(c).drawing = std::make_unique<FrameDrawing>();
    cache.of(c).drawing->job.refined = false;
    cache.of(gone).lastInteractive = now;
    gone.reset();
    EXPECT_EQ(cache.interactiveSessions(now, std::chrono::seconds(1)), 2u);
    EXPECT_EQ(cache.interactiveSessions(now, std::chrono::seconds(1), a.get()), 1u);
    EXPECT_EQ(cache.interactiveSessions(now, std::chrono::seconds(3)), 3u);
    cache.of(c).drawing->job.refined = true;
    EXPECT_EQ(cache.interactiveSessions(now, std::chrono::milliseconds(100)), 0u);
}

TEST_F(RendererCacheSessions, RenderersAreMadeOnceAndSharedPerVolumeOrKeptPerSession) {
    const render::RendererRegistry& registry = render::RendererRegistry::builtin();
    auto v = volume("v");
    auto a = slot(), b = slot();
    const auto cpuA = cache.rendererFor(a, *registry.find("cpu"), v);
    EXPECT_EQ(cpuA.pool, nullptr) << "a CPU renderer draws from no GPU pool";
    EXPECT_EQ(&cache.rendererFor(a, *registry.find("cpu"), v).renderer, &cpuA.renderer);
    EXPECT_NE(&cache.rendererFor(b, *registry.find("cpu"), v).renderer, &cpuA.renderer)
        << "a session's raycaster keeps what is the session's";
    const auto refA = cache.rendererFor(a, *registry.find("reference"), v);
    EXPECT_EQ(&cache.rendererFor(b, *registry.find("reference"), v).renderer, &refA.renderer)
        << "the reference holds nothing of one viewer: one per volume";
    EXPECT_EQ(cache.volumes.at(v.get()).volume, v);
    EXPECT_EQ(cache.volumes.at(v.get()).shared.size(), 1u);
    EXPECT_EQ(cache.sessions.at(a.get()).own.size(), 1u);
}

} // namespace
} // namespace bc::server::test
