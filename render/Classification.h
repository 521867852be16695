#pragma once
// A transfer function committed for one pyramid level of one store: its tables (one per step
// size, opacity-corrected) and the per-brick occupancy octrees of the second skipping stage.
// Derived state is built once, when it is first asked for after the transfer function is set,
// and shared by every session and renderer asking for the same key (DESIGN.md "Derived state
// is committed once"); the ClassificationCache holds them under a byte budget (LRU).
//
// A new transfer function starts from the octrees of the most recent classification of the
// same store and level (copied, then brought up to the new function), so only bricks whose
// value range meets the table entries whose emptiness changed are rebuilt, and leaf tables
// are read from the store once. A function that makes the same values visible as one held (an
// edit of colours or of non-zero opacities: the octrees and distance maps depend on nothing
// else) shares that one's octrees and distance maps outright: nothing is copied or rebuilt.
#include "render/FineOccupancy.h"
#include "render/Occupancy.h"
#include "render/RenderTypes.h"
#include "render/TransferFunction.h"

#include <cstdint>
#include <list>
#include <map>
#include <memory>
#include <mutex>
#include <vector>

namespace bc::brickstore {
class BrickStore;
}

namespace bc::render {

/// Entries of every table a classification makes (the raycasters', the splatters' and the
/// reference's).
inline constexpr std::uint32_t kClassificationTableEntries = TransferFunction::kDefaultTableEntries;

/// Which samples a frame's mode may leave out (render/MODES.md), as a visibility over the
/// transfer function's table: what its octrees, distance maps and brick plan are built from.
/// Composite: the function's own (a transparent sample adds nothing). Maximum: every value at
/// or above the lowest visible one (samples below it can only make a ray's maximum one that
/// maps to transparency). Minimum: at or below the highest visible one. Isosurface: at or
/// above the iso value (a ray below it everywhere meets no surface). Average: every value.
struct SkipRule {
    BlendMode mode = BlendMode::Composite;
    double iso = 0.0; ///< Isosurface only (0 for the others, so equal rules compare equal)
    static SkipRule of(const RenderOptions& options);
    bool operator==(const SkipRule&) const = default;
};

/// The table whose transparency says what `rule` may skip: `unit` (the function's table at
/// step 1) itself for composite, else its entries' opacities replaced by 1 where the rule
/// keeps samples and 0 where it skips them (colours kept). Conservative by one entry where
/// the rule's boundary falls between entries, so that no kept value is ever skipped.
TransferFunctionTable skipTableOf(const TransferFunctionTable& unit, const SkipRule& rule);

/// Which values a table makes visible (opacity above 0), over its domain: all that the
/// octrees and distance maps depend on (besides the store, level and config).
struct Visibility {
    double domainMin = 0, domainMax = 0;
    std::vector<std::uint64_t> bits; ///< entry i of kClassificationTableEntries at bit i
    static Visibility of(const TransferFunctionTable& table);
    bool operator==(const Visibility&) const = default;
};

/// What a classification is made for.
struct ClassificationKey {
    std::uint64_t storeInstance = 0; ///< BrickStore::instance()
    std::uint32_t level = 0;
    std::uint64_t tfHash = 0; ///< TransferFunction::contentHash(); sameFunction() decides
    SkipRule rule;            ///< the mode's (octrees and the skip table follow it)
    bool octrees = true;      ///< false: tables only (a frame that does not leap inside bricks)
    OccupancyConfig octree;   ///< when octrees
    bool operator==(const ClassificationKey&) const = default;
};

/// Immutable once built; every member function is thread-safe.
class Classification {
  public:
    /// Builds the octrees of `level` for `tf` and `rule` under `octree` (none when `octree`
    /// is null or the store has no apron: without one, leaf ranges do not cover what border
    /// samples read), starting from `donor`'s when given (same store and level); shares
    /// `donor`'s octrees and distance maps when it has the same config and Visibility.
    /// @throw std::invalid_argument on a bad config; what OccupancyTrees throws.
    Classification(const brickstore::BrickStore& store, std::uint32_t level,
                   const TransferFunction& tf, const OccupancyConfig* octree,
                   const Classification* donor, const SkipRule& rule = {});

    const ClassificationKey& key() const { return mKey; }
    const TransferFunction& transferFunction() const { return mTf; }
    std::uint32_t level() const { return mKey.level; }
    /// Unique per classification built in this process: GPU copies of its octrees key on it.
    std::uint64_t id() const { return mId; }
    /// Names the octrees: id() of the classification that built them (another's when shared).
    /// GPU copies of the octrees key on it.
    std::uint64_t occupancyId() const { return mOccupancyId; }
    /// occupancyId() of the octrees these were updated from (0: built from the store):
    /// OccupancyTrees::changedBricks() lists the bricks whose words differ from those.
    std::uint64_t basedOn() const { return mBasedOn; }
    /// Whether the octrees and distance maps are another classification's (same Visibility).
    bool sharesOccupancy() const { return mOccupancyId != mId; }
    const Visibility& visibility() const { return mVisibility; }
    /// skipTableOf(the function at step 1, the key's rule): the table a brick plan decides
    /// transparency by, and the octrees were built from.
    const std::shared_ptr<const TransferFunctionTable>& skipTable() const { return mSkipTable; }
    /// The octrees, or nullptr when the store has no apron.
    const OccupancyTrees* occupancy() const { return mOccupancy.get(); }
    /// What building the octrees took (zero when there are none).
    const OccupancyRebuild& build() const { return mBuild; }
    /// The table at `stepVoxels` (kClassificationTableEntries entries), made on first use and
    /// kept for the most recent steps. @throw std::invalid_argument on a bad step.
    std::shared_ptr<const TransferFunctionTable> table(double stepVoxels) const;
    /// The pre-integration table (kClassificationTableEntries entries; one serves every
    /// step), made on first use.
    std::shared_ptr<const PreintegratedTable> preintegrated() const;
    /// The per-brick distance maps over cells of `cellVoxels` (FineOccupancy.h), made on first
    /// use and filled brick by brick as frames draw them; null without octrees (or with a
    /// depth of 0), under an octree that draws nodes whole (ratio threshold below 1, a level
    /// limit), for 0, or for a cell size they cannot take (not a power of two below the leaf).
    FineOccupancy* fine(std::uint32_t cellVoxels) const;
    /// Host memory held: octrees, distance maps and tables (shared octrees and maps count in
    /// each holder: an upper bound).
    std::uint64_t bytes() const;

  private:
    struct FineMaps;
    ClassificationKey mKey;
    TransferFunction mTf;
    std::shared_ptr<const TransferFunctionTable> mSkipTable;
    Visibility mVisibility;
    std::uint64_t mId = 0, mOccupancyId = 0, mBasedOn = 0;
    std::shared_ptr<const OccupancyTrees> mOccupancy;
    std::shared_ptr<FineMaps> mFine; ///< with the octrees: shared with them
    OccupancyRebuild mBuild;
    mutable std::mutex mTablesMutex;
    mutable std::list<std::pair<double, std::shared_ptr<const TransferFunctionTable>>> mTables;
    mutable std::shared_ptr<const PreintegratedTable> mPreintegrated;
};

struct ClassificationCacheConfig {
    /// Host bytes of classifications kept after their last user lets go (LRU beyond it). One
    /// in use is never freed, so the cache may exceed this while sessions hold more.
    std::uint64_t budgetBytes = 256ull << 20;
};

/// Counters since the cache was made.
struct ClassificationStats {
    std::uint64_t builds = 0;    ///< classifications built (octrees made, updated or shared)
    std::uint64_t shared = 0;    ///< of those, with another's octrees and maps (same Visibility)
    std::uint64_t hits = 0;      ///< requests answered with one already built
    std::uint64_t evictions = 0; ///< dropped by the budget
    std::uint64_t bricksRebuilt = 0; ///< octrees rebuilt over all builds
    std::uint64_t residentBytes = 0; ///< held now
    std::uint64_t entries = 0;       ///< held now
    double buildMs = 0;              ///< spent building
};

/// The classifications of every store a process renders, by key. Thread-safe: a request for a
/// key being built waits for that build rather than starting a second one.
class ClassificationCache {
  public:
    explicit ClassificationCache(const ClassificationCacheConfig& config = {});

    /// The classification of `tf` and `rule` for `level` of `store` with octrees under
    /// `octree` (null: tables only, and any held classification of that function and rule
    /// serves): the one held for an equal key and function, else one built now (from the
    /// latest of that store and level). `built` (optional) is set to whether this call built it.
    /// @throw std::invalid_argument on a bad octree config; StoreCorrupt from the store.
    std::shared_ptr<const Classification> get(const brickstore::BrickStore& store,
                                              std::uint32_t level, const TransferFunction& tf,
                                              const OccupancyConfig* octree, bool* built = nullptr,
                                              const SkipRule& rule = {});
    ClassificationStats stats() const;
    void setBudgetBytes(std::uint64_t budgetBytes);

  private:
    void evict(); ///< with mMutex held

    ClassificationCacheConfig mConfig;
    mutable std::mutex mMutex;
    /// Most recently used first.
    std::list<std::shared_ptr<const Classification>> mEntries;
    ClassificationStats mStats;
};

} // namespace bc::render
