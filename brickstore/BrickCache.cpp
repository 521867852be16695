#include "brickstore/BrickCache.h"

#include "brickstore/BrickStore.h"
#include "brickstore/detail/CacheCore.h"

#include <algorithm>
#include <cassert>
#include <utility>

namespace bc::brickstore {
namespace detail {

namespace {

/// splitmix64's finaliser: every input bit reaches every output bit.
std::uint64_t mix(std::uint64_t x) {
    x ^= x >> 30;
    x *= 0xbf58476d1ce4e5b9ull;
    x ^= x >> 27;
    x *= 0x94d049bb133111ebull;
    x ^= x >> 31;
    return x;
}

} // namespace

std::size_t BrickKeyHash::operator()(const BrickKey& key) const noexcept {
    std::uint64_t h = mix(key.level);
    for (std::uint32_t p : key.pos)
        h = mix(h ^ p);
    return static_cast<std::size_t>(h);
}

CacheCore::CacheCore(BrickCache::Loader loader, BrickCacheConfig config)
    : mLoader(std::move(loader)), mBudgetBytes(config.budgetBytes) {}

CacheEntry& CacheCore::pin(const BrickKey& key) {
    std::unique_lock lock(mMutex);
    for (;;) {
        auto it = mEntries.find(key);
        if (it == mEntries.end()) return load(lock, key);
        CacheEntry& entry = it->second;
        if (entry.state == EntryState::Ready) {
            // Also reached by a request that waited for another thread's load: it did not
            // load anything itself, so it counts as a hit.
            ++mStats.hits;
            addPin(entry);
            return entry;
        }
        // Another thread is loading this brick. Wait and look again: if that load failed
        // the entry is gone and this request loads the brick itself.
        mLoadDone.wait(lock);
    }
}

CacheEntry& CacheCore::load(std::unique_lock<std::mutex>& lock, const BrickKey& key) {
    // The node stays where it is until erased, and a loading entry is never evicted.
    CacheEntry& entry = mEntries.try_emplace(key).first->second;
    entry.key = key;
    ++mStats.misses; // a load that then fails was still a miss
    std::vector<std::byte> data;
    if (!mSpare.empty()) { // an evicted brick's buffer: no allocation, no allocator growth
        data = std::move(mSpare.back()); // its old bytes: the loader overwrites them
        mSpare.pop_back();
    }
    lock.unlock();
    try {
        mLoader(key, data);
    } catch (...) {
        lock.lock();
        mEntries.erase(key);
        mLoadDone.notify_all();
        throw;
    }
    lock.lock();
    entry.data = std::move(data);
    entry.state = EntryState::Ready;
    mStats.bytesLoaded += entry.data.size();
    if (mEvicted.erase(key) != 0) {
        ++mStats.refetches;
        mStats.bytesRefetched += entry.data.size();
    }
    mStats.residentBytes += entry.data.size();
    ++mStats.residentBricks;
    if (key.level >= mLevelBytes.size()) mLevelBytes.resize(key.level + 1, 0);
    mLevelBytes[key.level] += entry.data.size();
    addPin(entry);
    evictToBudget();
    mLoadDone.notify_all();
    return entry;
}

CacheEntry* CacheCore::tryPin(const BrickKey& key) {
    std::lock_guard lock(mMutex);
    auto it = mEntries.find(key);
    if (it == mEntries.end() || it->second.state != EntryState::Ready) return nullptr;
    ++mStats.hits;
    addPin(it->second);
    return &it->second;
}

bool CacheCore::resident(const BrickKey& key) const {
    std::lock_guard lock(mMutex);
    auto it = mEntries.find(key);
    return it != mEntries.end() && it->second.state == EntryState::Ready;
}

std::uint64_t CacheCore::residentBytes(std::uint32_t level) const {
    std::lock_guard lock(mMutex);
    return level < mLevelBytes.size() ? mLevelBytes[level] : 0;
}

void CacheCore::unpin(CacheEntry& entry, bool cold) {
    std::lock_guard lock(mMutex);
    assert(entry.pinCount > 0);
    if (--entry.pinCount > 0) return;
    mStats.pinnedBytes -= entry.data.size();
    if (cold)
        lruPushFront(entry);
    else
        lruPushBack(entry);
    evictToBudget();
}

void CacheCore::setBudgetBytes(std::uint64_t budgetBytes) {
    std::lock_guard lock(mMutex);
    mBudgetBytes = budgetBytes;
    evictToBudget();
}

BrickCacheStats CacheCore::stats() const {
    std::lock_guard lock(mMutex);
    BrickCacheStats s = mStats;
    s.budgetBytes = mBudgetBytes;
    return s;
}

void CacheCore::resetPinnedPeak() {
    std::lock_guard lock(mMutex);
    mStats.pinnedPeakBytes = mStats.pinnedBytes;
}

void CacheCore::addPin(CacheEntry& entry) {
    if (entry.inLru) lruRemove(entry);
    if (entry.pinCount++ == 0) mStats.pinnedBytes += entry.data.size();
    mStats.pinnedPeakBytes = std::max(mStats.pinnedPeakBytes, mStats.pinnedBytes);
}

void CacheCore::lruPushBack(CacheEntry& entry) {
    entry.lruPrev = mLruTail;
    entry.lruNext = nullptr;
    (mLruTail ? mLruTail->lruNext : mLruHead) = &entry;
    mLruTail = &entry;
    entry.inLru = true;
}

void CacheCore::lruPushFront(CacheEntry& entry) {
    entry.lruPrev = nullptr;
    entry.lruNext = mLruHead;
    (mLruHead ? mLruHead->lruPrev : mLruTail) = &entry;
    mLruHead = &entry;
    entry.inLru = true;
}

void CacheCore::lruRemove(CacheEntry& entry) {
    (entry.lruPrev ? entry.lruPrev->lruNext : mLruHead) = entry.lruNext;
    (entry.lruNext ? entry.lruNext->lruPrev : mLruTail) = entry.lruPrev;
    entry.lruPrev = nullptr;
    entry.lruNext = nullptr;
    entry.inLru = false;
}

void CacheCore::evictToBudget() {
    // Only the LRU is searched: pinned and loading entries are not in it, so when they alone
    // exceed the budget the cache stays over it until they are unpinned.
    while (mStats.residentBytes > mBudgetBytes && mLruHead != nullptr) {
        CacheEntry& victim = *mLruHead;
        lruRemove(victim);
        const std::uint64_t bytes = victim.data.size();
        mStats.residentBytes -= bytes;
        mLevelBytes[victim.key.level] -= bytes;
        mStats.bytesEvicted += bytes;
        --mStats.residentBricks;
        ++mStats.evictions;
        const BrickKey key = victim.key; // not a reference into the node being erased
        if (mSpare.size() < kSpareBuffers) mSpare.push_back(std::move(victim.data));
        mEntries.erase(key);
        mEvicted.insert(key);
    }
}

} // namespace detail

// --- BrickPin ---

BrickPin::BrickPin(BrickPin&& other) noexcept
    : mCore(std::exchange(other.mCore, nullptr)), mEntry(std::exchange(other.mEntry, nullptr)) {}

BrickPin& BrickPin::operator=(BrickPin&& other) noexcept {
    if (this != &other) {
        release();
        mCore = std::exchange(other.mCore, nullptr);
        mEntry = std::exchange(other.mEntry, nullptr);
    }
    return *this;
}

BrickPin::~BrickPin() {
    release();
}

const BrickKey& BrickPin::key() const {
    assert(mEntry != nullptr);
    return mEntry->key;
}

std::span<const std::byte> BrickPin::data() const {
    assert(mEntry != nullptr);
    // Read without the lock: the bytes were written under it before this pin was handed
    // out and stay unchanged while any pin holds the entry.
    return mEntry->data;
}

void BrickPin::release(bool cold) {
    if (mEntry == nullptr) return;
    mCore->unpin(*mEntry, cold);
    mCore = nullptr;
    mEntry = nullptr;
}

void BrickPin::releaseCold() {
    release(true);
}

// --- BrickCache ---

BrickCache::BrickCache(Loader loader, BrickCacheConfig config)
    : mCore(std::make_unique<detail::CacheCore>(std::move(loader), config)) {}

BrickCache::BrickCache(const BrickStore& store, BrickCacheConfig config)
    : BrickCache(
          [&store](const BrickKey& key, std::vector<std::byte>& out) {
              out.resize(static_cast<std::size_t>(store.brickBytes()));
              store.readBrick(key, out);
          },
          config) {}

BrickCache::~BrickCache() = default;

BrickPin BrickCache::pin(const BrickKey& key) {
    return BrickPin(mCore.get(), &mCore->pin(key));
}

std::optional<BrickPin> BrickCache::tryPin(const BrickKey& key) {
    detail::CacheEntry* entry = mCore->tryPin(key);
    if (entry == nullptr) return std::nullopt;
    return BrickPin(mCore.get(), entry);
}

bool BrickCache::resident(const BrickKey& key) const {
    return mCore->resident(key);
}

std::uint64_t BrickCache::residentBytes(std::uint32_t level) const {
    return mCore->residentBytes(level);
}

void BrickCache::setBudgetBytes(std::uint64_t budgetBytes) {
    mCore->setBudgetBytes(budgetBytes);
}

BrickCacheStats BrickCache::stats() const {
    return mCore->stats();
}

void BrickCache::resetPinnedPeak() {
    mCore->resetPinnedPeak();
}

} // namespace bc::brickstore
