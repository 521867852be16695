#pragma once
// The shared state behind BrickCache and its pins: one map of entries, one LRU of the
// unpinned resident ones, one mutex over both. Loads run outside the mutex.
#include "brickstore/BrickCache.h"

#include <condition_variable>
#include <cstddef>
#include <cstdint>
#include <mutex>
#include <unordered_map>
#include <unordered_set>
#include <vector>

namespace bc::brickstore::detail {

/// Mixes level and position so that neighbouring bricks spread over the buckets.
struct BrickKeyHash {
    std::size_t operator()(const BrickKey& key) const noexcept;
};

enum class EntryState { Loading, Ready };

/// One brick known to the cache. Lives in CacheCore::mEntries (node-based, so its address
/// is stable) from the start of its load until it is evicted or its load fails.
struct CacheEntry {
    BrickKey key;
    std::vector<std::byte> data; ///< written once, under the mutex, before the first pin
    std::uint32_t pinCount = 0;
    EntryState state = EntryState::Loading;
    bool inLru = false;            ///< ready and unpinned
    CacheEntry* lruPrev = nullptr; ///< intrusive, so that unpinning never allocates
    CacheEntry* lruNext = nullptr;
};

class CacheCore {
  public:
    CacheCore(BrickCache::Loader loader, BrickCacheConfig config);

    /// A ready entry for `key` with one more pin, loading it on a miss.
    /// @throw what the loader throws.
    CacheEntry& pin(const BrickKey& key);
    /// A ready entry with one more pin, or nullptr when `key` is not resident.
    CacheEntry* tryPin(const BrickKey& key);
    bool resident(const BrickKey& key) const;
    std::uint64_t residentBytes(std::uint32_t level) const;
    /// Drops one pin; an entry left unpinned becomes the most recently used, or with `cold`
    /// the least.
    void unpin(CacheEntry& entry, bool cold = false);
    void setBudgetBytes(std::uint64_t budgetBytes);
    BrickCacheStats stats() const;
    void resetPinnedPeak();

  private:
    CacheEntry& load(std::unique_lock<std::mutex>& lock, const BrickKey& key);
    void addPin(CacheEntry& entry);
    void lruPushBack(CacheEntry& entry);
    void lruPushFront(CacheEntry& entry);
    void lruRemove(CacheEntry& entry);
    /// Evicts unpinned entries, least recently used first, until resident <= budget.
    void evictToBudget();

    BrickCache::Loader mLoader;
    std::uint64_t mBudgetBytes;
    mutable std::mutex mMutex;
    std::condition_variable mLoadDone; ///< a load finished or failed (any key)
    std::unordered_map<BrickKey, CacheEntry, BrickKeyHash> mEntries;
    CacheEntry* mLruHead = nullptr; ///< least recently used unpinned entry
    CacheEntry* mLruTail = nullptr; ///< most recently used
    /// Keys evicted and not loaded since: a miss on one is a re-fetch. At most one key per
    /// brick of the store.
    std::unordered_set<BrickKey, BrickKeyHash> mEvicted;
    /// Buffers of evicted bricks, reused by the next loads. Freed bricks would otherwise stay
    /// in the malloc arena of the thread that loaded them (glibc raises its mmap threshold to
    /// a brick's size after the first free): measured 77-133 MiB over a 256 MiB budget while
    /// a frame streams bricks through the cache. A few suffice: a streaming load evicts one.
    static constexpr std::size_t kSpareBuffers = 8;
    std::vector<std::vector<std::byte>> mSpare;
    BrickCacheStats mStats;
    std::vector<std::uint64_t> mLevelBytes; ///< residentBytes per level
};

} // namespace bc::brickstore::detail
