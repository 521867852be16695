// BrickCache over a fake loader (counting, LRU order, pins, byte accounting, concurrency)
// and over a real store.
#include "brickstore/BrickCache.h"
#include "brickstore/BrickStore.h"
#include "brickstore/Error.h"
#include "brickstore/Ingest.h"
#include "brickstore/Readers.h"
#include "tests/TestSupport.h"

#include <gtest/gtest.h>

#include <algorithm>
#include <atomic>
#include <chrono>
#include <cstddef>
#include <cstdint>
#include <deque>
#include <latch>
#include <random>
#include <thread>
#include <vector>

namespace bc::brickstore {
namespace {

constexpr std::size_t kBrickBytes = 1024;

/// Brick `i` of a small level-0 grid (8 x 8 x n).
BrickKey keyOf(std::uint32_t i) {
    return BrickKey{0, {i % 8, (i / 8) % 8, i / 64}};
}

/// The byte a brick holds at `offset`; distinct first bytes for the first 256 keys.
std::byte expectedByte(const BrickKey& key, std::size_t offset) {
    const std::uint64_t seed =
        key.pos[0] + 8ull * key.pos[1] + 64ull * key.pos[2] + 97ull * key.level;
    return static_cast<std::byte>((seed + 13 * offset) & 0xffu);
}

bool holdsBytesOf(std::span<const std::byte> data, const BrickKey& key, std::size_t bytes) {
    if (data.size() != bytes) return false;
    for (std::size_t i = 0; i < data.size(); ++i)
        if (data[i] != expectedByte(key, i)) return false;
    return true;
}

/// Stands in for a BrickStore: fills bricks with key-derived bytes, counts and optionally
/// delays calls, and fails the first `failures` loads of `failKey`. Set up before use.
struct FakeLoader {
    std::chrono::milliseconds delay{0};
    BrickKey failKey{99, {0, 0, 0}};
    std::atomic<int> failures{0};
    bool variableSize = false; ///< brick i is kBrickBytes + 16 i long
    std::atomic<int> calls{0};
    std::atomic<int> inFlight{0};
    std::atomic<int> maxInFlight{0};

    std::size_t bytesOf(const BrickKey& key) const {
        return variableSize ? kBrickBytes + 16 * (key.pos[0] + 8 * key.pos[1]) : kBrickBytes;
    }

    BrickCache::Loader loader() {
        return [this](const BrickKey& key, std::vector<std::byte>& out) { load(key, out); };
    }

    void load(const BrickKey& key, std::vector<std::byte>& out) {
        ++calls;
        const int now = ++inFlight;
        int seen = maxInFlight.load();
        while (now > seen && !maxInFlight.compare_exchange_weak(seen, now)) {
        }
        if (delay.count() > 0) std::this_thread::sleep_for(delay);
        --inFlight;
        if (key == failKey && failures.fetch_sub(1) > 0)
            throw StoreCorrupt("fake store: " + key.toString() + ": checksum mismatch");
        out.resize(bytesOf(key));
        for (std::size_t i = 0; i < out.size(); ++i)
            out[i] = expectedByte(key, i);
    }
};

BrickCacheConfig budgetOf(std::uint64_t bricks) {
    return BrickCacheConfig{bricks * kBrickBytes};
}

bool resident(BrickCache& cache, std::uint32_t i) {
    return cache.tryPin(keyOf(i)).has_value();
}

TEST(BrickCacheTest, CountsMissOnFirstPinAndHitAfterwards) {
    FakeLoader fake;
    BrickCache cache(fake.loader(), budgetOf(8));
    { BrickPin pin = cache.pin(keyOf(1)); }
    EXPECT_EQ(cache.stats().misses, 1u);
    EXPECT_EQ(cache.stats().hits, 0u);
    { BrickPin pin = cache.pin(keyOf(1)); }
    EXPECT_EQ(cache.stats().misses, 1u);
    EXPECT_EQ(cache.stats().hits, 1u);
    EXPECT_EQ(fake.calls, 1);
}

TEST(BrickCacheTest, PinnedBrickHoldsTheLoadersBytesForItsKey) {
    FakeLoader fake;
    BrickCache cache(fake.loader(), budgetOf(8));
    BrickPin a = cache.pin(keyOf(3));
    BrickPin b = cache.pin(keyOf(4));
    EXPECT_EQ(a.key(), keyOf(3));
    EXPECT_EQ(b.key(), keyOf(4));
    EXPECT_TRUE(holdsBytesOf(a.data(), keyOf(3), kBrickBytes));
    EXPECT_TRUE(holdsBytesOf(b.data(), keyOf(4), kBrickBytes));
}

TEST(BrickCacheTest, TryPinCountsHitOnlyForResidentBrick) {
    FakeLoader fake;
    BrickCache cache(fake.loader(), budgetOf(8));
    EXPECT_FALSE(cache.tryPin(keyOf(2)).has_value());
    EXPECT_EQ(cache.stats().hits, 0u);
    EXPECT_EQ(cache.stats().misses, 0u);
    EXPECT_EQ(fake.calls, 0);
    { BrickPin pin = cache.pin(keyOf(2)); }
    std::optional<BrickPin> pin = cache.tryPin(keyOf(2));
    ASSERT_TRUE(pin.has_value());
    EXPECT_TRUE(holdsBytesOf(pin->data(), keyOf(2), kBrickBytes));
    EXPECT_EQ(cache.stats().hits, 1u);
    EXPECT_EQ(cache.stats().misses, 1u);
    EXPECT_EQ(fake.calls, 1);
}

TEST(BrickCacheTest, EvictsLeastRecentlyUsedUnpinnedBrick) {
    FakeLoader fake;
    BrickCache cache(fake.loader(), budgetOf(3));
    for (std::uint32_t i : {0u, 1u, 2u})
        cache.pin(keyOf(i));
    cache.pin(keyOf(0)); // order, least recent first: 1 2 0
    cache.pin(keyOf(3));
    EXPECT_EQ(cache.stats().evictions, 1u);
    EXPECT_FALSE(resident(cache, 1));
    // Each tryPin moves its brick to the most recent end, so the order ends as 2 0 3.
    EXPECT_TRUE(resident(cache, 2));
    EXPECT_TRUE(resident(cache, 0));
    EXPECT_TRUE(resident(cache, 3));
    cache.pin(keyOf(4));
    EXPECT_EQ(cache.stats().evictions, 2u);
    EXPECT_FALSE(resident(cache, 2));
    EXPECT_EQ(cache.stats().residentBricks, 3u);
    EXPECT_EQ(fake.calls, 5);
}

// A brick let go cold is the first to go, ahead of older ones; resident() says what is
// loaded without counting or moving anything.
TEST(BrickCacheTest, ColdReleasedBrickIsEvictedFirstAndResidentCountsNothing) {
    FakeLoader fake;
    BrickCache cache(fake.loader(), budgetOf(3));
    {
        BrickPin a = cache.pin(keyOf(0));
        BrickPin b = cache.pin(keyOf(1));
        BrickPin c = cache.pin(keyOf(2));
        a = {};          // order, least recent first: 0
        b.releaseCold(); // 1 0
        EXPECT_FALSE(b); // released
        b.releaseCold(); // a second time does nothing
    }                    // 1 0 2
    const BrickCacheStats before = cache.stats();
    for (std::uint32_t i : {0u, 1u, 2u})
        EXPECT_TRUE(cache.resident(keyOf(i)));
    EXPECT_FALSE(cache.resident(keyOf(3)));
    EXPECT_EQ(cache.stats().hits, before.hits);
    EXPECT_EQ(cache.stats().misses, before.misses);
    cache.pin(keyOf(3)); // evicts 1, the cold one, though 0 is older
    EXPECT_FALSE(cache.resident(keyOf(1)));
    EXPECT_TRUE(cache.resident(keyOf(0)));
    cache.pin(keyOf(4)); // then the least recent: 0 (resident() did not move it)
    EXPECT_FALSE(cache.resident(keyOf(0)));
    EXPECT_TRUE(cache.resident(keyOf(2)));
    // A brick pinned twice goes cold only when its last pin goes, and as that pin says.
    {
        BrickPin x = cache.pin(keyOf(2));
        BrickPin y = cache.pin(keyOf(2));
        x.releaseCold();
        y = {}; // the last pin: to the most recent end
    }           // order: 3 4 2
    cache.pin(keyOf(5));
    EXPECT_FALSE(cache.resident(keyOf(3)));
    EXPECT_TRUE(cache.resident(keyOf(2)));
}

// A reused buffer reaches the loader with an evicted brick's bytes; the brick loaded into it
// holds its own bytes only.
TEST(BrickCacheTest, BrickLoadedIntoAnEvictedBricksBufferHoldsOnlyItsOwnBytes) {
    FakeLoader fake;
    fake.variableSize = true; // a smaller brick into a larger brick's buffer, and back
    BrickCache cache(fake.loader(), budgetOf(2));
    for (std::uint32_t i : {9u, 1u, 8u, 2u, 7u}) {
        BrickPin pin = cache.pin(keyOf(i));
        EXPECT_TRUE(holdsBytesOf(pin.data(), keyOf(i), kBrickBytes + 16 * i)) << i;
    }
    EXPECT_GE(cache.stats().evictions, 3u);
}

// A scripted path whose misses can be counted by hand: a cycle over four bricks through a
// cache of three thrashes LRU (every access misses, and each brick's second load is a
// re-fetch); the same cycle through a cache of four misses only the first time round.
TEST(BrickCacheTest, CountsRefetchesOfEvictedBricksOnAScriptedCycle) {
    FakeLoader fake;
    BrickCache small(fake.loader(), budgetOf(3));
    for (int round = 0; round < 2; ++round)
        for (std::uint32_t i : {0u, 1u, 2u, 3u})
            small.pin(keyOf(i));
    auto s = small.stats();
    EXPECT_EQ(s.misses, 8u);
    EXPECT_EQ(s.hits, 0u);
    EXPECT_EQ(s.evictions, 5u); // bricks 0 1 2 3 0 each pushed out by the fourth after it
    EXPECT_EQ(s.refetches, 4u);
    EXPECT_EQ(s.bytesRefetched, 4 * kBrickBytes);
    EXPECT_EQ(s.budgetBytes, 3 * kBrickBytes);
    small.pin(keyOf(7)); // new: a miss and an eviction, not a re-fetch
    EXPECT_EQ(small.stats().refetches, 4u);

    BrickCache big(fake.loader(), budgetOf(4));
    for (int round = 0; round < 2; ++round)
        for (std::uint32_t i : {0u, 1u, 2u, 3u})
            big.pin(keyOf(i));
    s = big.stats();
    EXPECT_EQ(s.misses, 4u);
    EXPECT_EQ(s.hits, 4u);
    EXPECT_EQ(s.evictions, 0u);
    EXPECT_EQ(s.refetches, 0u);
    big.setBudgetBytes(kBrickBytes); // evicts 0 1 2; loading 0 again is a re-fetch
    big.pin(keyOf(0));
    EXPECT_EQ(big.stats().refetches, 1u);
    EXPECT_EQ(big.stats().bytesRefetched, kBrickBytes);
}

TEST(BrickCacheTest, NeverEvictsPinnedBricksAndEvictsDownOnceUnpinned) {
    FakeLoader fake;
    BrickCache cache(fake.loader(), budgetOf(2));
    std::vector<BrickPin> pins;
    for (std::uint32_t i = 0; i < 4; ++i)
        pins.push_back(cache.pin(keyOf(i)));
    BrickCacheStats s = cache.stats();
    EXPECT_EQ(s.evictions, 0u);
    EXPECT_EQ(s.residentBricks, 4u);
    EXPECT_EQ(s.residentBytes, 4 * kBrickBytes); // over budget rather than failing a frame
    EXPECT_EQ(s.pinnedBytes, 4 * kBrickBytes);
    for (std::uint32_t i = 0; i < 4; ++i)
        EXPECT_TRUE(holdsBytesOf(pins[i].data(), keyOf(i), kBrickBytes));

    pins.clear(); // unpins 0, 1, 2, 3 in order: 0 and 1 go as each is released
    s = cache.stats();
    EXPECT_EQ(s.evictions, 2u);
    EXPECT_EQ(s.residentBytes, 2 * kBrickBytes);
    EXPECT_EQ(s.pinnedBytes, 0u);
    EXPECT_FALSE(resident(cache, 0));
    EXPECT_FALSE(resident(cache, 1));
    EXPECT_TRUE(resident(cache, 2));
    EXPECT_TRUE(resident(cache, 3));
}

TEST(BrickCacheTest, CountsLoadedEvictedResidentAndPinnedBytes) {
    FakeLoader fake;
    fake.variableSize = true;
    const std::uint64_t b0 = fake.bytesOf(keyOf(0)), b1 = fake.bytesOf(keyOf(1)),
                        b2 = fake.bytesOf(keyOf(2));
    BrickCache cache(fake.loader(), BrickCacheConfig{b0 + b1 + b2 - 1});
    BrickPin p0 = cache.pin(keyOf(0));
    BrickPin p1 = cache.pin(keyOf(1));
    EXPECT_EQ(p1.data().size(), b1);
    BrickCacheStats s = cache.stats();
    EXPECT_EQ(s.bytesLoaded, b0 + b1);
    EXPECT_EQ(s.residentBytes, b0 + b1);
    EXPECT_EQ(s.pinnedBytes, b0 + b1);
    EXPECT_EQ(s.residentBricks, 2u);

    BrickPin again = cache.pin(keyOf(0)); // a second pin of one brick counts its bytes once
    EXPECT_EQ(cache.stats().pinnedBytes, b0 + b1);
    p0 = BrickPin();
    again = BrickPin();
    EXPECT_EQ(cache.stats().pinnedBytes, b1);

    BrickPin p2 = cache.pin(keyOf(2)); // over budget by one byte: brick 0 goes
    s = cache.stats();
    EXPECT_EQ(s.bytesLoaded, b0 + b1 + b2);
    EXPECT_EQ(s.bytesEvicted, b0);
    EXPECT_EQ(s.evictions, 1u);
    EXPECT_EQ(s.residentBytes, b1 + b2);
    EXPECT_EQ(s.pinnedBytes, b1 + b2);
    EXPECT_EQ(s.residentBricks, 2u);
}

// Resident bytes per pyramid level (how warm a level is, server/InteractiveBudget.h): loads add to
// their level's count, evictions take from it, and levels never loaded count nothing.
TEST(BrickCacheTest, CountsResidentBytesPerLevel) {
    FakeLoader fake;
    BrickCache cache(fake.loader(), budgetOf(3));
    const BrickKey coarse{2, {0, 0, 0}};
    cache.pin(keyOf(0));
    cache.pin(coarse);
    EXPECT_EQ(cache.residentBytes(0), kBrickBytes);
    EXPECT_EQ(cache.residentBytes(1), 0u);
    EXPECT_EQ(cache.residentBytes(2), kBrickBytes);
    EXPECT_EQ(cache.residentBytes(7), 0u) << "a level never loaded";
    cache.pin(keyOf(1));
    cache.pin(keyOf(2)); // over the budget: the least recently used, brick 0, goes
    EXPECT_EQ(cache.residentBytes(0), 2 * kBrickBytes);
    cache.pin(keyOf(3)); // and then the level-2 brick
    EXPECT_EQ(cache.residentBytes(0), 3 * kBrickBytes);
    EXPECT_EQ(cache.residentBytes(2), 0u);
    EXPECT_EQ(cache.stats().residentBytes, 3 * kBrickBytes);
}

TEST(BrickCacheTest, ConcurrentPinsOfOneKeyLoadItOnce) {
    FakeLoader fake;
    fake.delay = std::chrono::milliseconds(50);
    BrickCache cache(fake.loader(), budgetOf(8));
    constexpr int kThreads = 8;
    std::latch start(kThreads);
    std::atomic<int> correct{0};
    std::vector<std::jthread> threads;
    for (int t = 0; t < kThreads; ++t)
        threads.emplace_back([&] {
            start.arrive_and_wait();
            BrickPin pin = cache.pin(keyOf(5));
            correct += holdsBytesOf(pin.data(), keyOf(5), kBrickBytes) ? 1 : 0;
        });
    threads.clear();
    EXPECT_EQ(fake.calls, 1);
    EXPECT_EQ(correct, kThreads);
    // Requests that waited for the shared load count as hits.
    EXPECT_EQ(cache.stats().misses, 1u);
    EXPECT_EQ(cache.stats().hits, std::uint64_t(kThreads - 1));
}

TEST(BrickCacheTest, LoadsDifferentKeysInParallel) {
    FakeLoader fake;
    fake.delay = std::chrono::milliseconds(50);
    BrickCache cache(fake.loader(), budgetOf(8));
    constexpr int kThreads = 8;
    std::latch start(kThreads);
    std::atomic<int> correct{0};
    std::vector<std::jthread> threads;
    for (int t = 0; t < kThreads; ++t)
        threads.emplace_back([&, t] {
            start.arrive_and_wait();
            BrickPin pin = cache.pin(keyOf(std::uint32_t(t)));
            correct += holdsBytesOf(pin.data(), keyOf(std::uint32_t(t)), kBrickBytes) ? 1 : 0;
        });
    threads.clear();
    EXPECT_EQ(fake.calls, kThreads);
    EXPECT_EQ(correct, kThreads);
    EXPECT_GE(fake.maxInFlight, 2); // loads ran outside the cache's lock
}

TEST(BrickCacheTest, FailedLoadLeavesNothingCachedAndLaterPinRetries) {
    FakeLoader fake;
    fake.failKey = keyOf(3);
    fake.failures = 1;
    BrickCache cache(fake.loader(), budgetOf(8));
    EXPECT_THROW(cache.pin(keyOf(3)), StoreCorrupt);
    BrickCacheStats s = cache.stats();
    EXPECT_EQ(s.misses, 1u); // a failed load is still a miss
    EXPECT_EQ(s.bytesLoaded, 0u);
    EXPECT_EQ(s.residentBricks, 0u);
    EXPECT_EQ(s.residentBytes, 0u);
    EXPECT_EQ(s.pinnedBytes, 0u);
    EXPECT_FALSE(resident(cache, 3));

    BrickPin pin = cache.pin(keyOf(3));
    EXPECT_TRUE(holdsBytesOf(pin.data(), keyOf(3), kBrickBytes));
    EXPECT_EQ(fake.calls, 2);
    EXPECT_EQ(cache.stats().misses, 2u);
}

TEST(BrickCacheTest, WaitersOfFailedLoadRetryTheLoadThemselves) {
    FakeLoader fake;
    fake.delay = std::chrono::milliseconds(50);
    fake.failKey = keyOf(6);
    fake.failures = 1;
    BrickCache cache(fake.loader(), budgetOf(8));
    constexpr int kThreads = 4;
    std::latch start(kThreads);
    std::atomic<int> failed{0}, correct{0};
    std::vector<std::jthread> threads;
    for (int t = 0; t < kThreads; ++t)
        threads.emplace_back([&] {
            start.arrive_and_wait();
            try {
                BrickPin pin = cache.pin(keyOf(6));
                correct += holdsBytesOf(pin.data(), keyOf(6), kBrickBytes) ? 1 : 0;
            } catch (const StoreCorrupt&) {
                ++failed;
            }
        });
    threads.clear();
    // Only the request whose own load failed sees the error; one waiter loads again.
    EXPECT_EQ(failed, 1);
    EXPECT_EQ(correct, kThreads - 1);
    EXPECT_EQ(fake.calls, 2);
    EXPECT_EQ(cache.stats().residentBricks, 1u);
}

TEST(BrickCacheTest, SetBudgetBytesEvictsDownToNewBudget) {
    FakeLoader fake;
    BrickCache cache(fake.loader(), budgetOf(8));
    BrickPin held = cache.pin(keyOf(0));
    for (std::uint32_t i = 1; i < 6; ++i)
        cache.pin(keyOf(i));
    EXPECT_EQ(cache.stats().residentBricks, 6u);
    cache.setBudgetBytes(3 * kBrickBytes); // pinned 0 stays; 1 2 3 go, 4 5 stay
    EXPECT_EQ(cache.stats().evictions, 3u);
    EXPECT_EQ(cache.stats().residentBytes, 3 * kBrickBytes);
    EXPECT_FALSE(resident(cache, 1));
    EXPECT_FALSE(resident(cache, 3));
    EXPECT_TRUE(resident(cache, 4));
    EXPECT_TRUE(resident(cache, 5));

    cache.setBudgetBytes(0);
    EXPECT_EQ(cache.stats().residentBricks, 1u); // only the pinned one
    held = BrickPin();
    EXPECT_EQ(cache.stats().residentBricks, 0u);
    EXPECT_EQ(cache.stats().bytesEvicted, cache.stats().bytesLoaded);
}

TEST(BrickCacheTest, MovingBrickPinTransfersThePin) {
    FakeLoader fake;
    BrickCache cache(fake.loader(), budgetOf(0)); // every unpinned brick goes at once
    EXPECT_FALSE(BrickPin());

    BrickPin a = cache.pin(keyOf(1));
    BrickPin b = std::move(a);
    EXPECT_FALSE(a); // NOLINT(bugprone-use-after-move): moved-from pins are empty
    ASSERT_TRUE(b);
    EXPECT_EQ(b.key(), keyOf(1));
    EXPECT_EQ(cache.stats().pinnedBytes, kBrickBytes);

    BrickPin c = cache.pin(keyOf(2));
    c = std::move(b); // drops the pin on 2, takes the one on 1
    EXPECT_FALSE(b);  // NOLINT(bugprone-use-after-move)
    EXPECT_EQ(c.key(), keyOf(1));
    BrickCacheStats s = cache.stats();
    EXPECT_EQ(s.evictions, 1u);
    EXPECT_EQ(s.pinnedBytes, kBrickBytes);
    EXPECT_FALSE(resident(cache, 2));

    c = BrickPin();
    s = cache.stats();
    EXPECT_EQ(s.evictions, 2u); // unpinned exactly once
    EXPECT_EQ(s.pinnedBytes, 0u);
    EXPECT_EQ(s.residentBytes, 0u);
}

TEST(BrickCacheTest, StaysConsistentUnderConcurrentRandomPins) {
    constexpr int kThreads = 8, kPinsPerThread = 2000;
    constexpr std::uint32_t kKeys = 64;
    constexpr std::size_t kHeldPerThread = 2; // up to 8 x 3 pinned: over budget at times
    FakeLoader fake;
    BrickCache cache(fake.loader(), budgetOf(16));
    std::atomic<std::uint64_t> successes{0}, wrongBricks{0};
    std::latch start(kThreads);
    std::vector<std::jthread> threads;
    for (int t = 0; t < kThreads; ++t)
        threads.emplace_back([&, t] {
            std::mt19937 rng(1234u + unsigned(t));
            std::uniform_int_distribution<std::uint32_t> keyDist(0, kKeys - 1);
            std::deque<BrickPin> held;
            start.arrive_and_wait();
            for (int i = 0; i < kPinsPerThread; ++i) {
                const BrickKey key = keyOf(keyDist(rng));
                std::optional<BrickPin> pin;
                if (rng() % 4 == 0)
                    pin = cache.tryPin(key);
                else
                    pin = cache.pin(key);
                if (!pin) continue;
                ++successes;
                if (pin->key() != key || !holdsBytesOf(pin->data(), key, kBrickBytes))
                    ++wrongBricks;
                held.push_back(std::move(*pin));
                if (held.size() > kHeldPerThread) held.pop_front();
            }
        });
    threads.clear();

    const BrickCacheStats s = cache.stats();
    EXPECT_EQ(wrongBricks, 0u);
    EXPECT_EQ(s.hits + s.misses, successes.load());
    EXPECT_EQ(s.misses, std::uint64_t(fake.calls));
    EXPECT_EQ(s.pinnedBytes, 0u);
    EXPECT_LE(s.residentBytes, 16 * kBrickBytes);
    EXPECT_EQ(s.residentBytes, s.residentBricks * kBrickBytes);
    EXPECT_EQ(s.bytesLoaded, s.misses * kBrickBytes);
    EXPECT_EQ(s.bytesEvicted, s.evictions * kBrickBytes);
    EXPECT_EQ(s.bytesLoaded - s.bytesEvicted, s.residentBytes);
    EXPECT_GT(s.evictions, 0u); // the budget was actually exercised
}

TEST(BrickCacheTest, StoreBackedCacheServesBricksAsTheStoreReadsThem) {
    test::TempDir dir;
    IngestConfig config;
    config.geometry = BrickGeometry{16, 2, 8};
    config.threads = 2;
    auto source = makeSynthetic(SynthKind::Phantom, {40, 40, 40}, 7);
    ingest(*source, dir.file("phantom.bcs"), config);
    auto store = BrickStore::open(dir.file("phantom.bcs"));
    const std::uint64_t brickBytes = store->brickBytes();
    BrickCache cache(*store, BrickCacheConfig{4 * brickBytes});

    const std::uint64_t count = store->layout().brickCount();
    std::vector<std::byte> expected(static_cast<std::size_t>(brickBytes));
    for (std::uint64_t i = 0; i < count; ++i) {
        const BrickKey key = store->layout().keyOf(i);
        store->readBrick(key, expected);
        BrickPin pin = cache.pin(key);
        ASSERT_EQ(pin.data().size(), expected.size()) << key.toString();
        EXPECT_TRUE(std::equal(expected.begin(), expected.end(), pin.data().begin()))
            << key.toString();
    }
    const BrickCacheStats s = cache.stats();
    EXPECT_EQ(s.misses, count);
    EXPECT_EQ(s.bytesLoaded, count * brickBytes);
    EXPECT_EQ(s.residentBytes, std::min<std::uint64_t>(count, 4) * brickBytes);
}

} // namespace
} // namespace bc::brickstore
