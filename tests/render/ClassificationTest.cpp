// Classifications: one per (store, level, transfer function, octree config), shared, built
// incrementally from the last one of the same store and level, evicted LRU under a budget; a
// function that makes the same values visible shares the octrees and distance maps outright.
#include "render/Classification.h"
#include "RenderTestSupport.h"
#include "render/ImageMetrics.h"
#include "render/Renderer.h"
#include "render/RendererRegistry.h"

namespace bc::render {
namespace {

const OccupancyConfig kOctrees{};

test::TestStore* phantom() {
    static const auto v = [] {
        auto source = brickstore::makeSynthetic(brickstore::SynthKind::Phantom, {96, 96, 96}, 1);
        return test::ingestStore(*source, {32, 2, 8});
    }();
    return v.get();
}

TEST(ClassificationTest, OneFunctionIsBuiltOnceAndSharedWhateverTheRequestersName) {
    const auto t = phantom();
    const auto bone = TransferFunction::preset("ct-bone", t->stats);
    ClassificationCache cache;
    bool built = false;
    const auto a = cache.get(*t->store, 0, bone, &kOctrees, &built);
    EXPECT_TRUE(built);
    const auto b =
        cache.get(*t->store, 0, TransferFunction::preset("ct-bone", t->stats), &kOctrees, &built);
    EXPECT_FALSE(built);
    EXPECT_EQ(a.get(), b.get());
    // Tables only: the octree entry serves.
    EXPECT_EQ(cache.get(*t->store, 0, bone, nullptr, &built).get(), a.get());
    EXPECT_FALSE(built);
    // Another config or level is another classification.
    OccupancyConfig coarse;
    coarse.levelLimit = 1;
    EXPECT_NE(cache.get(*t->store, 0, bone, &coarse, &built).get(), a.get());
    EXPECT_TRUE(built);
    EXPECT_NE(cache.get(*t->store, 1, bone, &kOctrees, &built).get(), a.get());
    EXPECT_TRUE(built);
    EXPECT_EQ(cache.stats().builds, 3u);
    EXPECT_EQ(a->table(1.0).get(), a->table(1.0).get()); // kept, not made again
    EXPECT_EQ(a->table(0.5)->rgba, bone.table(0.5, kClassificationTableEntries).rgba);
}

TEST(ClassificationTest, ANewFunctionRebuildsOnlyWhatChangedAndEqualsAFreshBuild) {
    const auto t = phantom();
    const auto skin = TransferFunction::preset("ct-skin", t->stats);
    const auto bone = TransferFunction::preset("ct-bone", t->stats);
    ClassificationCache shared, fresh;
    const auto first = shared.get(*t->store, 0, skin, &kOctrees);
    const auto next = shared.get(*t->store, 0, bone, &kOctrees);
    const auto alone = fresh.get(*t->store, 0, bone, &kOctrees);
    ASSERT_TRUE(next->occupancy() && alone->occupancy());
    EXPECT_EQ(next->basedOn(), first->id());
    EXPECT_EQ(alone->basedOn(), 0u);
    EXPECT_EQ(next->occupancy()->words(), alone->occupancy()->words());
    EXPECT_LE(next->build().bricksRebuilt, alone->build().bricksRebuilt);
    EXPECT_FALSE(next->build().full);
    // The first is untouched by the second's build (it was copied, not updated in place).
    EXPECT_EQ(first->occupancy()->words(),
              fresh.get(*t->store, 0, skin, &kOctrees)->occupancy()->words());
}

TEST(ClassificationTest, EvictsLeastRecentlyUsedUnderItsBudgetButNeverOneInUse) {
    const auto t = phantom();
    ClassificationCache cache(ClassificationCacheConfig{1}); // a byte: nothing idle stays
    const auto held =
        cache.get(*t->store, 0, TransferFunction::preset("ct-bone", t->stats), &kOctrees);
    cache.get(*t->store, 0, TransferFunction::preset("ct-skin", t->stats), &kOctrees);
    cache.get(*t->store, 0, TransferFunction::preset("mr", t->stats), &kOctrees);
    const auto s = cache.stats();
    EXPECT_EQ(s.builds, 3u);
    EXPECT_EQ(s.entries, 2u); // the one held, and the newest until its caller let go
    EXPECT_EQ(s.evictions, 1u);
    bool built = true;
    EXPECT_EQ(
        cache.get(*t->store, 0, TransferFunction::preset("ct-bone", t->stats), &kOctrees, &built)
            .get(),
        held.get());
    EXPECT_FALSE(built);
    cache.setBudgetBytes(1ull << 30);
    cache.get(*t->store, 0, TransferFunction::preset("ct-skin", t->stats), &kOctrees, &built);
    EXPECT_TRUE(built); // it was evicted
}

TEST(ClassificationTest, RenderersSharingACacheBuildEachClassificationOnce) {
    const auto t = phantom();
    const auto tf = TransferFunction::preset("ct-bone", t->stats);
    ClassificationCache cache;
    const Scene scene{*t->store, *t->cache, tf, cache};
    RenderOptions o;
    o.width = o.height = 32;
    const View view = View::of(Camera::orbit(LevelGeometry::of(*t->store, 0).box, 30, 20), 32, 32);
    std::vector<FrameStats> stats(4);
    for (auto& s : stats) {
        auto r = RendererRegistry::builtin().create("cpu");
        r->render(scene, view, o, s);
    }
    EXPECT_GT(stats[0].octreeBricksRebuilt, 0u);
    for (std::size_t i = 1; i < stats.size(); ++i)
        EXPECT_EQ(stats[i].octreeBricksRebuilt, 0u);
    EXPECT_EQ(cache.stats().builds, 1u);
}

/// `tf` with its colours changed (channels rotated), its non-zero opacities times `alphaScale`
/// and, when `openZero`, its first zero opacity made 0.02: the same visible values unless it is.
TransferFunction edited(const TransferFunction& tf, const VolumeValueStats& stats, float alphaScale,
                        bool openZero = false) {
    std::vector<PointSpec> specs;
    bool opened = false;
    for (const ControlPoint& p : tf.points()) {
        PointSpec s{Placement::Value, p.value, {p.rgba[1], p.rgba[2], p.rgba[0], p.rgba[3]}};
        s.rgba[3] = std::min(1.0f, s.rgba[3] * alphaScale);
        if (openZero && !opened && p.rgba[3] == 0.0f) {
            s.rgba[3] = 0.02f;
            opened = true;
        }
        specs.push_back(s);
    }
    EXPECT_EQ(opened, openZero) << "the function has no zero opacity to open";
    return TransferFunction::fromPoints(specs, "edited", stats);
}

TEST(ClassificationTest, AnEditThatKeepsTheVisibleValuesSharesOctreesAndMaps) {
    const auto t = phantom();
    const auto bone = TransferFunction::preset("ct-bone", t->stats);
    ClassificationCache cache, fresh;
    const auto first = cache.get(*t->store, 0, bone, &kOctrees);
    ASSERT_TRUE(first->occupancy());
    const FineOccupancy* maps = first->fine(2);
    ASSERT_NE(maps, nullptr);
    bool built = false;
    for (const float alphaScale : {1.0f, 0.5f}) { // colours only; and non-zero opacities too
        SCOPED_TRACE(alphaScale);
        const auto next =
            cache.get(*t->store, 0, edited(bone, t->stats, alphaScale), &kOctrees, &built);
        EXPECT_TRUE(built) << "another function is another classification (its own tables)";
        EXPECT_TRUE(next->sharesOccupancy());
        EXPECT_EQ(next->occupancy(), first->occupancy()) << "the octrees were not shared";
        EXPECT_EQ(next->fine(2), maps) << "the distance maps were not shared";
        EXPECT_EQ(next->occupancyId(), first->occupancyId()); // GPU copies stay
        EXPECT_EQ(next->build().bricksRebuilt, 0u);
        EXPECT_NE(next->table(1.0)->rgba, first->table(1.0)->rgba);
        EXPECT_EQ(next->occupancy()->words(),
                  fresh.get(*t->store, 0, edited(bone, t->stats, alphaScale), &kOctrees)
                      ->occupancy()
                      ->words());
    }
    EXPECT_EQ(cache.stats().shared, 2u);
    // A value made visible: octrees of its own, brought up from the last ones.
    const auto opened = cache.get(*t->store, 0, edited(bone, t->stats, 1.0f, true), &kOctrees);
    EXPECT_FALSE(opened->sharesOccupancy());
    EXPECT_NE(opened->occupancy(), first->occupancy());
    EXPECT_NE(opened->visibility(), first->visibility());
    EXPECT_EQ(cache.stats().shared, 2u);
    // Another octree config shares nothing.
    OccupancyConfig coarse;
    coarse.levelLimit = 1;
    EXPECT_FALSE(cache.get(*t->store, 0, edited(bone, t->stats, 0.5f), &coarse)->sharesOccupancy());
}

TEST(ClassificationTest, FramesUnderAColourEditWithSharedMapsEqualAFreshBuilds) {
    const auto t = phantom();
    const auto bone = TransferFunction::preset("ct-bone", t->stats);
    const auto recoloured = edited(bone, t->stats, 0.5f);
    ClassificationCache shared, fresh;
    RenderOptions o;
    o.width = o.height = 64;
    ASSERT_GT(o.cellVoxels, 0u);
    const View view = View::of(Camera::orbit(LevelGeometry::of(*t->store, 0).box, 30, 20), 64, 64);
    auto frame = [&](ClassificationCache& cache, const TransferFunction& tf, FrameStats& stats) {
        auto r = RendererRegistry::builtin().create("cpu");
        return r->render(Scene{*t->store, *t->cache, tf, cache}, view, o, stats);
    };
    FrameStats boneStats, editStats, freshStats;
    frame(shared, bone, boneStats);
    ASSERT_GT(boneStats.cellBricksBuilt, 0u) << "no distance maps to share on this scan";
    const Image edit = frame(shared, recoloured, editStats);
    const Image alone = frame(fresh, recoloured, freshStats);
    EXPECT_EQ(editStats.cellBricksBuilt, 0u) << "the maps were built again";
    EXPECT_EQ(editStats.octreeBricksRebuilt, 0u);
    EXPECT_EQ(freshStats.cellBricksBuilt, boneStats.cellBricksBuilt);
    EXPECT_EQ(compareImages(edit, alone).maxAbs, 0.0);
    EXPECT_EQ(editStats.samples, freshStats.samples);
}

} // namespace
} // namespace bc::render
