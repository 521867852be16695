// The GPU brick pool's counters on scripted access patterns whose hits, uploads, evictions
// and re-fetches can be counted by hand (the host -> GPU tier of the bus model).
#include "render/BrickPool.h"
#include "RenderTestSupport.h"

#include <cstddef>
#include <vector>

namespace bc::render {
namespace {

constexpr std::uint32_t kEdge = 8;

struct Fixture {
    explicit Fixture(std::uint32_t slots)
        : pool((test::glContext(), brickstore::VoxelType::U8), kEdge,
               BrickPoolConfig{std::uint64_t(slots) * kEdge * kEdge * kEdge}),
          voxels(kEdge * kEdge * kEdge, std::byte{7}) {}
    /// One frame: every key acquired (pinned), then the frame ends.
    void frame(std::initializer_list<std::uint64_t> keys) {
        for (std::uint64_t k : keys)
            ASSERT_TRUE(pool.acquire(k, [&] { return std::span<const std::byte>(voxels); }));
        pool.unpinAll();
    }
    BrickPool pool;
    std::vector<std::byte> voxels;
};

// The slot grid uses the budget: the old layout (a cube root wide, the rest in one row, then
// depth) lost up to 45% of the slots once the row met the texture's size limit.
TEST(BrickPool, SlotGridHoldsNearlyEverySlotTheBudgetPays) {
    for (std::uint64_t perAxis : {4, 30, 102, 240, 2048})
        for (std::uint64_t n = 1; n <= std::min<std::uint64_t>(perAxis * perAxis * perAxis, 20000);
             n += 1 + n / 7) {
            const auto g = BrickPool::slotGridFor(n, perAxis);
            const std::uint64_t count = std::uint64_t(g[0]) * g[1] * g[2];
            ASSERT_LE(count, n) << n << " slots, " << perAxis << " a side";
            for (std::uint32_t side : g) {
                ASSERT_LE(side, perAxis);
            }
            if (n >= 100 && n * 8 <= perAxis * perAxis * perAxis) {
                EXPECT_GE(double(count), 0.95 * double(n))
                    << n << " slots, " << perAxis << " a side";
            }
        }
    const auto g = BrickPool::slotGridFor(2796, 102); // 16^3 u16 bricks on llvmpipe: was 1530
    EXPECT_GE(std::uint64_t(g[0]) * g[1] * g[2], 2700u);
}

TEST(BrickPool, CountsHitsUploadsEvictionsAndRefetchesOfAScriptedPath) {
    Fixture f(4);
    ASSERT_EQ(f.pool.capacity(), 4u);
    // One brick a frame, so that recency is strict (bricks of one frame are equally recent).
    for (std::uint64_t k : {0, 1, 2, 3})
        f.frame({k}); // 4 uploads; least recent first: 0 1 2 3
    f.frame({4});     // evicts 0
    f.frame({0});     // re-fetch, evicts 1
    f.frame({1, 2});  // 1 re-fetched (evicts 2), then 2 re-fetched (evicts 3)
    f.frame({4});     // a hit
    const auto& s = f.pool.stats();
    EXPECT_EQ(s.uploads, 8u);
    EXPECT_EQ(s.hits, 1u);
    EXPECT_EQ(s.evictions, 4u);
    EXPECT_EQ(s.refetches, 3u);
    EXPECT_EQ(s.bytesUploaded, 8u * f.pool.slotBytes());
    EXPECT_EQ(s.bytesRefetched, 3u * f.pool.slotBytes());
    for (std::uint64_t k : {0, 1, 2, 4})
        EXPECT_TRUE(f.pool.resident(k)) << k;
    EXPECT_FALSE(f.pool.resident(3));
    f.pool.clear(); // a new volume: what came before is not a re-fetch
    f.frame({3});
    EXPECT_EQ(f.pool.stats().refetches, 3u);
    EXPECT_EQ(f.pool.stats().uploads, 9u);
}

// Every slot pinned in one frame: the next brick does not fit and nothing is evicted.
TEST(BrickPool, AFullyPinnedPoolRefusesWithoutEvicting) {
    Fixture f(2);
    auto load = [&] { return std::span<const std::byte>(f.voxels); };
    ASSERT_TRUE(f.pool.acquire(0, load));
    ASSERT_TRUE(f.pool.acquire(1, load));
    EXPECT_FALSE(f.pool.acquire(2, load));
    EXPECT_EQ(f.pool.stats().evictions, 0u);
    f.pool.unpinAll();
    EXPECT_TRUE(f.pool.acquire(2, load));
    EXPECT_EQ(f.pool.stats().evictions, 1u);
}

} // namespace
} // namespace bc::render
