#include "render/Classification.h"

#include "brickstore/BrickStore.h"

#include <atomic>
#include <bit>
#include <chrono>
#include <optional>

namespace bc::render {

namespace {

/// Tables kept per classification: a session's steps (interactive and refined) and a few more.
constexpr std::size_t kTablesKept = 4;

std::uint64_t nextClassificationId() {
    static std::atomic<std::uint64_t> next{1};
    return next.fetch_add(1);
}

/// Bytes of one table: its RGBA and the range-maximum levels built over it.
std::uint64_t tableBytes(const TransferFunctionTable& t) {
    const auto levels = std::uint64_t(std::bit_width(t.entries));
    return t.rgba.capacity() * sizeof(float) + levels * t.entries * sizeof(float);
}

} // namespace

// ---- Classification ---------------------------------------------------------------------

SkipRule SkipRule::of(const RenderOptions& options) {
    return {options.mode, options.mode == BlendMode::Isosurface ? options.isoValue : 0.0};
}

TransferFunctionTable skipTableOf(const TransferFunctionTable& unit, const SkipRule& rule) {
    if (rule.mode == BlendMode::Composite) return unit;
    const std::uint32_t n = unit.entries;
    auto visible = [&](std::uint32_t i) { return unit.rgba[4 * std::size_t(i) + 3] > 0.0f; };
    // Entries [first, last] keep their samples; the others are skipped.
    std::uint32_t first = 0, last = n - 1;
    switch (rule.mode) {
    case BlendMode::Maximum:
        while (first < n && !visible(first))
            ++first;
        break;
    case BlendMode::Minimum: {
        std::uint32_t end = n; // one past the highest visible entry
        while (end > 0 && !visible(end - 1))
            --end;
        if (end == 0)
            first = n; // none visible: nothing kept
        else
            last = end - 1;
        break;
    }
    case BlendMode::Isosurface: {
        // A value at or above the iso value reads entries from floor(u(iso)) on (the lookup
        // mixes floor(u) and the next one).
        const double u =
            (rule.iso - unit.domainMin) / (unit.domainMax - unit.domainMin) * double(n - 1);
        first = std::uint32_t(std::clamp(std::floor(u), 0.0, double(n - 1)));
        break;
    }
    case BlendMode::Average:
    case BlendMode::Composite:
        break;
    }
    std::vector<float> rgba = unit.rgba;
    for (std::uint32_t i = 0; i < n; ++i)
        rgba[4 * std::size_t(i) + 3] = i >= first && i <= last && first <= last ? 1.0f : 0.0f;
    return TransferFunctionTable(unit.domainMin, unit.domainMax, std::move(rgba));
}

Visibility Visibility::of(const TransferFunctionTable& table) {
    // Which entries are visible does not depend on the step (a' > 0 exactly when a > 0), so
    // the table at step 1 says it for every step.
    Visibility v{table.domainMin, table.domainMax, {}};
    v.bits.assign((table.entries + 63) / 64, 0);
    for (std::uint32_t i = 0; i < table.entries; ++i)
        if (table.rgba[4 * std::size_t(i) + 3] > 0.0f) v.bits[i / 64] |= 1ull << (i % 64);
    return v;
}

/// The distance maps, one per cell size asked for; shared with the octrees they are made from.
struct Classification::FineMaps {
    std::mutex mutex;
    std::vector<std::unique_ptr<FineOccupancy>> maps;
};

Classification::Classification(const brickstore::BrickStore& store, std::uint32_t level,
                               const TransferFunction& tf, const OccupancyConfig* octree,
                               const Classification* donor, const SkipRule& rule)
    : mKey{store.instance(),  level,
           tf.contentHash(),  rule,
           octree != nullptr, octree ? *octree : OccupancyConfig{}},
      mTf(tf), mSkipTable(std::make_shared<const TransferFunctionTable>(
                   skipTableOf(tf.table(1.0, kClassificationTableEntries), rule))),
      mVisibility(Visibility::of(*mSkipTable)), mId(nextClassificationId()), mOccupancyId(mId),
      mFine(std::make_shared<FineMaps>()) {
    if (!octree) return;
    octree->validate();
    if (store.layout().geometry().apronVoxels == 0) return;
    if (donor && donor->mOccupancy && donor->mKey.octree == *octree &&
        donor->mVisibility == mVisibility) {
        mOccupancy = donor->mOccupancy; // the same octrees and maps, word for word
        mFine = donor->mFine;
        mOccupancyId = donor->mOccupancyId;
        mBasedOn = donor->mBasedOn;
        mBuild.bricksStored = donor->mBuild.bricksStored;
        return;
    }
    std::unique_ptr<OccupancyTrees> trees;
    if (donor && donor->mOccupancy) {
        trees = std::make_unique<OccupancyTrees>(*donor->mOccupancy);
        mBasedOn = donor->mOccupancyId;
    } else {
        trees = std::make_unique<OccupancyTrees>(store, level);
    }
    mBuild = trees->update(*mSkipTable, *octree);
    mOccupancy = std::move(trees);
}

std::shared_ptr<const TransferFunctionTable> Classification::table(double stepVoxels) const {
    std::lock_guard lock(mTablesMutex);
    for (auto it = mTables.begin(); it != mTables.end(); ++it)
        if (it->first == stepVoxels) {
            mTables.splice(mTables.begin(), mTables, it);
            return it->second;
        }
    auto made = std::make_shared<const TransferFunctionTable>(
        mTf.table(stepVoxels, kClassificationTableEntries));
    mTables.emplace_front(stepVoxels, made);
    if (mTables.size() > kTablesKept) mTables.pop_back();
    return made;
}

std::shared_ptr<const PreintegratedTable> Classification::preintegrated() const {
    std::lock_guard lock(mTablesMutex);
    if (!mPreintegrated)
        mPreintegrated = std::make_shared<const PreintegratedTable>(
            mTf.preintegrated(kClassificationTableEntries));
    return mPreintegrated;
}

FineOccupancy* Classification::fine(std::uint32_t cellVoxels) const {
    // Only under the exact octree: a node drawn whole (ratio threshold or level limit) must
    // keep its samples, which a map would leap.
    if (!mOccupancy || mOccupancy->depth() == 0 || cellVoxels == 0 ||
        mKey.octree.ratioThreshold < 1.0 || mKey.octree.levelLimit < mOccupancy->depth())
        return nullptr;
    const std::uint32_t leaf = mOccupancy->leafVoxels();
    if (!std::has_single_bit(leaf) || !std::has_single_bit(cellVoxels) || cellVoxels >= leaf)
        return nullptr;
    std::lock_guard lock(mFine->mutex);
    for (const auto& f : mFine->maps)
        if (f->cellVoxels() == cellVoxels) return f.get();
    mFine->maps.push_back(std::make_unique<FineOccupancy>(*mOccupancy, *mSkipTable, cellVoxels));
    return mFine->maps.back().get();
}

std::uint64_t Classification::bytes() const {
    std::uint64_t n = sizeof(*this) + (mOccupancy ? mOccupancy->bytes() : 0) +
                      mVisibility.bits.size() * sizeof(std::uint64_t);
    {
        std::lock_guard lock(mFine->mutex);
        for (const auto& f : mFine->maps)
            n += f->bytes();
    }
    std::lock_guard lock(mTablesMutex);
    if (mPreintegrated) n += mPreintegrated->table.size() * sizeof(PreintegratedTable::Entry);
    for (const auto& [step, table] : mTables)
        n += tableBytes(*table);
    return n;
}

// ---- ClassificationCache ----------------------------------------------------------------

ClassificationCache::ClassificationCache(const ClassificationCacheConfig& config)
    : mConfig(config) {}

std::shared_ptr<const Classification> ClassificationCache::get(const brickstore::BrickStore& store,
                                                               std::uint32_t level,
                                                               const TransferFunction& tf,
                                                               const OccupancyConfig* octree,
                                                               bool* built, const SkipRule& rule) {
    const ClassificationKey key{store.instance(),  level,
                                tf.contentHash(),  rule,
                                octree != nullptr, octree ? *octree : OccupancyConfig{}};
    std::lock_guard lock(mMutex);
    const Classification *latest = nullptr, *sharer = nullptr;
    std::optional<Visibility> visible; // computed when an entry could share its octrees
    for (auto it = mEntries.begin(); it != mEntries.end(); ++it) {
        const Classification& c = **it;
        const ClassificationKey& k = c.key();
        const bool serves = octree ? k == key
                                   : k.storeInstance == key.storeInstance && k.level == level &&
                                         k.tfHash == key.tfHash && k.rule == rule;
        if (serves && c.transferFunction().sameFunction(tf)) {
            mEntries.splice(mEntries.begin(), mEntries, it);
            ++mStats.hits;
            if (built) *built = false;
            return mEntries.front();
        }
        if (!c.occupancy() || k.storeInstance != key.storeInstance || k.level != level) continue;
        if (!latest) latest = &c; // the most recent octrees of this store and level
        if (!sharer && octree && k.octree == *octree) { // or octrees to share outright
            if (!visible)
                visible =
                    Visibility::of(skipTableOf(tf.table(1.0, kClassificationTableEntries), rule));
            if (c.visibility() == *visible) sharer = &c;
        }
    }
    const Classification* donor = sharer ? sharer : latest;
    // Built under the lock: a second request for this key waits and then finds it.
    const auto start = std::chrono::steady_clock::now();
    auto made = std::make_shared<const Classification>(store, level, tf, octree, donor, rule);
    mStats.builds += 1;
    mStats.shared += made->sharesOccupancy();
    mStats.bricksRebuilt += made->build().bricksRebuilt;
    mStats.buildMs +=
        std::chrono::duration<double, std::milli>(std::chrono::steady_clock::now() - start).count();
    mEntries.push_front(made);
    evict();
    if (built) *built = true;
    return made;
}

void ClassificationCache::evict() {
    std::uint64_t total = 0;
    for (const auto& c : mEntries)
        total += c->bytes();
    // Least recently used first; one a renderer still holds stays (freeing it saves nothing).
    for (auto it = mEntries.end(); total > mConfig.budgetBytes && it != mEntries.begin();) {
        --it;
        if (it->use_count() > 1) continue;
        total -= (*it)->bytes();
        it = mEntries.erase(it);
        ++mStats.evictions;
    }
}

ClassificationStats ClassificationCache::stats() const {
    std::lock_guard lock(mMutex);
    ClassificationStats s = mStats;
    s.entries = mEntries.size();
    for (const auto& c : mEntries)
        s.residentBytes += c->bytes();
    return s;
}

void ClassificationCache::setBudgetBytes(std::uint64_t budgetBytes) {
    std::lock_guard lock(mMutex);
    mConfig.budgetBytes = budgetBytes;
    evict();
}

} // namespace bc::render
