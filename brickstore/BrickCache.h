#pragma once
// Host brick cache: decompressed bricks under LRU with a byte budget. Thread-safe. A brick
// in use is held by a BrickPin and is never evicted while pinned; when every resident brick
// is pinned the cache may exceed its budget (counted in stats) rather than fail a frame.
#include "brickstore/StoreLayout.h"

#include <cstddef>
#include <cstdint>
#include <functional>
#include <memory>
#include <optional>
#include <span>
#include <vector>

namespace bc::brickstore {

class BrickStore;

struct BrickCacheConfig {
    std::uint64_t budgetBytes = 1ull << 30; ///< bytes of decompressed bricks kept resident
};

/// A request that waits for another thread's load of the same brick counts as a hit; a
/// failed load counts as a miss.
struct BrickCacheStats {
    std::uint64_t hits = 0;
    std::uint64_t misses = 0;
    std::uint64_t evictions = 0;
    std::uint64_t bytesLoaded = 0; ///< bytes brought in by misses
    std::uint64_t bytesEvicted = 0;
    /// Misses of bricks this cache held before and evicted: the traffic a larger budget
    /// (or a better eviction order) would have saved.
    std::uint64_t refetches = 0;
    std::uint64_t bytesRefetched = 0;
    /// Budget at the time of the snapshot.
    std::uint64_t budgetBytes = 0;
    std::uint64_t residentBytes = 0;  ///< now
    std::uint64_t pinnedBytes = 0;    ///< now
    std::uint64_t residentBricks = 0; ///< now
    /// Most bytes pinned at once since construction or the last resetPinnedPeak(): what a
    /// renderer that bounds its pins by the budget is checked against.
    std::uint64_t pinnedPeakBytes = 0;
};

namespace detail {
struct CacheEntry;
class CacheCore;
} // namespace detail

/// A pinned, decompressed brick. Move-only; unpins in its destructor. The cache must outlive it.
class BrickPin {
  public:
    BrickPin() = default;
    BrickPin(BrickPin&& other) noexcept;
    BrickPin& operator=(BrickPin&& other) noexcept;
    BrickPin(const BrickPin&) = delete;
    BrickPin& operator=(const BrickPin&) = delete;
    ~BrickPin();

    const BrickKey& key() const;
    /// The brick's stored voxels ((B+2A)^3, native type, x fastest).
    std::span<const std::byte> data() const;
    explicit operator bool() const { return mEntry != nullptr; }
    /// Unpins now, the brick going to the front of the eviction order rather than the back
    /// (once no other pin holds it): the first to go when the cache needs room. How a reader
    /// streaming more bricks than the budget holds keeps the ones it read first, which its
    /// next pass reads first, instead of evicting each just before it is wanted again.
    void releaseCold();

  private:
    friend class BrickCache;
    BrickPin(detail::CacheCore* core, detail::CacheEntry* entry) : mCore(core), mEntry(entry) {}
    void release(bool cold = false);
    detail::CacheCore* mCore = nullptr;
    detail::CacheEntry* mEntry = nullptr;
};

class BrickCache {
  public:
    /// Sizes `out` and fills it with brick `key`; may throw (StoreCorrupt). `out` may be an
    /// evicted brick's buffer, sized and holding its bytes: the loader writes every byte (not
    /// clearing it first spares a memset of each brick loaded).
    using Loader = std::function<void(const BrickKey& key, std::vector<std::byte>& out)>;

    BrickCache(Loader loader, BrickCacheConfig config);
    /// A cache over a store's bricks (store.readBrick); the store must outlive the cache.
    BrickCache(const BrickStore& store, BrickCacheConfig config);
    ~BrickCache();
    BrickCache(const BrickCache&) = delete;
    BrickCache& operator=(const BrickCache&) = delete;

    /// The brick, loaded on a miss. Concurrent requests for one key share a single load.
    /// @throw what the loader throws; a failed load leaves nothing cached.
    BrickPin pin(const BrickKey& key);
    /// The brick only if resident (counts a hit), else nullopt (counts nothing).
    std::optional<BrickPin> tryPin(const BrickKey& key);
    /// Whether the brick is loaded now (pinning it would not load it). Counts nothing and
    /// leaves its place in the LRU order; another thread may evict it right after.
    bool resident(const BrickKey& key) const;
    /// Bytes of `level`'s bricks loaded now (how warm a pyramid level is).
    std::uint64_t residentBytes(std::uint32_t level) const;
    /// Changes the budget; evicts unpinned bricks down to it.
    void setBudgetBytes(std::uint64_t budgetBytes);
    BrickCacheStats stats() const;
    /// Restarts stats().pinnedPeakBytes from the bytes pinned now.
    void resetPinnedPeak();

  private:
    std::unique_ptr<detail::CacheCore> mCore;
};

} // namespace bc::brickstore
