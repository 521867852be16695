// Per-brick octrees, without a GPU: emptiness decided from the stored leaf ranges
// alone and never missing a visible value, the ratio threshold and level limit of the
// traversal, incremental rebuilds equal to full ones, and a corrupt leaf table named.
#include "render/Occupancy.h"
#include "RenderTestSupport.h"

#include <fstream>

namespace bc::render {
namespace {

using test::TestStore;

TransferFunction peakTf(double centre, double halfWidth, const VolumeValueStats& stats,
                        const char* rgb = "1,0.8,0.6") {
    auto point = [&](double v, double a) {
        return R"({"value":)" + std::to_string(v) + R"(,"rgba":[)" + rgb + "," + std::to_string(a) +
               "]}";
    };
    const std::string json = R"({"name":"peak","points":[)" + point(centre - halfWidth, 0) + "," +
                             point(centre, 0.9) + "," + point(centre + halfWidth, 0) + "]}";
    return TransferFunction::parse(json, "<peak>", stats);
}

std::unique_ptr<TestStore> angiography() {
    auto spec = test::realScan("CT_AVM");
    return spec ? test::ingestSpec(*spec, {32, 2, 8}) : nullptr;
}

std::array<std::uint32_t, 3> coords(std::uint32_t index, std::uint32_t perAxis) {
    return {index % perAxis, (index / perAxis) % perAxis, index / (perAxis * perAxis)};
}

std::uint64_t levelBrickIndex(const brickstore::BrickKey& key, const LevelGeometry& g) {
    return (std::uint64_t(key.pos[2]) * g.bricks[1] + key.pos[1]) * g.bricks[0] + key.pos[0];
}

brickstore::BrickKey levelBrickKey(std::uint64_t index, const LevelGeometry& g) {
    return {g.level,
            {std::uint32_t(index % g.bricks[0]), std::uint32_t((index / g.bricks[0]) % g.bricks[1]),
             std::uint32_t(index / (std::uint64_t(g.bricks[0]) * g.bricks[1]))}};
}

TEST(OccupancyTest, LeafIsLeptOnlyWhenTheTableIsTransparentOverEverythingItsSamplesRead) {
    auto t = angiography();
    if (!t) return test::missingData("scan CT_AVM");
    const auto tf = TransferFunction::preset("vessels", t->stats);
    const auto table = tf.table(1.0, 4096);
    OccupancyTrees trees(*t->store, 0);
    const auto rebuild = trees.update(table, {});
    EXPECT_TRUE(rebuild.full);
    EXPECT_EQ(rebuild.bricksRebuilt, rebuild.bricksStored);
    ASSERT_EQ(trees.depth(), 2u); // 32-voxel bricks of 8-voxel leaves: 4^3 leaves
    const LevelGeometry g = LevelGeometry::of(*t->store, 0);
    std::uint64_t empty = 0, visible = 0;
    for (std::uint32_t z = 0; z < g.bricks[2]; ++z)
        for (std::uint32_t y = 0; y < g.bricks[1]; ++y)
            for (std::uint32_t x = 0; x < g.bricks[0]; ++x) {
                const brickstore::BrickKey key{0, {x, y, z}};
                if (!t->store->record(key).stored()) continue;
                const auto leaves = t->store->leafRanges(key);
                const std::uint64_t b = levelBrickIndex(key, g);
                for (std::uint32_t i = 0; i < leaves.size(); ++i) {
                    const auto node = coords(i, trees.leavesPerAxis());
                    const bool lit = !table.transparent(leaves[i].min, leaves[i].max);
                    visible += lit;
                    if (!trees.occupied(b, trees.depth(), node)) {
                        ++empty;
                        EXPECT_FALSE(lit) << key.toString() << " leaf " << i << " is visible";
                        EXPECT_EQ(trees.ratio(b, trees.depth(), node), 0.0);
                    }
                }
            }
    EXPECT_GT(empty, 0u) << "nothing leapt: the test proves nothing";
    EXPECT_GT(visible, 0u);
}

TEST(OccupancyTest, PeakStrictlyBetweenALeafsVoxelValuesKeepsTheLeaf) {
    // Voxels are 0 or 255 only; the one opaque value is 127.75.
    auto source = brickstore::makeSynthetic(brickstore::SynthKind::Checker, {64, 64, 64}, 1);
    auto t = test::ingestStore(*source, {32, 2, 8});
    const double lo = t->store->info().valueMin, hi = t->store->info().valueMax;
    const auto table = peakTf(0.5 * (lo + hi) + 0.25, 0.5, t->stats).table(1.0, 4096);
    OccupancyTrees trees(*t->store, 0);
    trees.update(table, {});
    const LevelGeometry g = LevelGeometry::of(*t->store, 0);
    std::uint64_t straddling = 0;
    for (std::uint64_t b = 0; b < g.brickCount(); ++b) {
        const brickstore::BrickKey key = levelBrickKey(b, g);
        if (!t->store->record(key).stored()) continue;
        const auto leaves = t->store->leafRanges(key);
        for (std::uint32_t i = 0; i < leaves.size(); ++i) {
            if (!(leaves[i].min < 127.75 && leaves[i].max > 127.75)) continue;
            ++straddling;
            EXPECT_TRUE(trees.occupied(b, trees.depth(), coords(i, trees.leavesPerAxis())))
                << key.toString() << " leaf " << i;
        }
        EXPECT_TRUE(trees.occupied(b, 0, {}));
    }
    EXPECT_GT(straddling, 0u);
}

TEST(OccupancyTest, RatioThresholdAndLevelLimitDrawNodesWhole) {
    auto t = angiography();
    if (!t) return test::missingData("scan CT_AVM");
    const auto table = TransferFunction::preset("vessels", t->stats).table(1.0, 4096);
    OccupancyTrees exact(*t->store, 0), anyLeaf(*t->store, 0), limit0(*t->store, 0),
        limit1(*t->store, 0);
    exact.update(table, {});
    anyLeaf.update(table, {0.0, 32}); // every non-empty node drawn whole
    limit0.update(table, {1.0, 0});   // the brick drawn whole
    limit1.update(table, {1.0, 1});   // level-1 nodes drawn whole
    const std::uint32_t d = exact.depth(), n = exact.leavesPerAxis();
    std::uint64_t partial = 0;
    for (std::uint64_t b = 0; b < LevelGeometry::of(*t->store, 0).brickCount(); ++b) {
        const bool root = exact.occupied(b, 0, {});
        for (std::uint32_t i = 0; i < n * n * n; ++i) {
            const auto leaf = coords(i, n);
            const std::array<std::uint32_t, 3> parent{leaf[0] >> (d - 1), leaf[1] >> (d - 1),
                                                      leaf[2] >> (d - 1)};
            EXPECT_EQ(limit0.occupied(b, d, leaf), root);
            EXPECT_EQ(limit1.occupied(b, d, leaf), exact.occupied(b, 1, parent));
            EXPECT_EQ(anyLeaf.occupied(b, d, leaf), root); // the root is non-empty: drawn whole
            // A node is sampled exactly when it holds a non-empty leaf (threshold 1).
            EXPECT_EQ(exact.occupied(b, d, leaf), exact.ratio(b, d, leaf) > 0.0);
            EXPECT_EQ(exact.occupied(b, 1, parent), exact.ratio(b, 1, parent) > 0.0);
        }
        const double r = exact.ratio(b, 0, {});
        partial += r > 0.0 && r < 1.0;
    }
    EXPECT_GT(partial, 0u) << "no brick is partly empty: the test proves nothing";
    EXPECT_THROW(exact.update(table, {1.5, 32}), std::invalid_argument);
}

TEST(OccupancyTest, SampledBoxIsTheBoundsOfTheLeavesWhoseBitIsSet) {
    auto t = angiography();
    if (!t) return test::missingData("scan CT_AVM");
    const auto table = TransferFunction::preset("vessels", t->stats).table(1.0, 4096);
    for (const OccupancyConfig config : {OccupancyConfig{}, OccupancyConfig{1.0, 1}}) {
        OccupancyTrees trees(*t->store, 0);
        trees.update(table, config);
        const std::uint32_t d = trees.depth(), n = trees.leavesPerAxis();
        std::uint64_t narrowed = 0, none = 0;
        for (std::uint64_t b = 0; b < LevelGeometry::of(*t->store, 0).brickCount(); ++b) {
            SampledBox want{{n, n, n}, {0, 0, 0}};
            for (std::uint32_t i = 0; i < n * n * n; ++i) {
                const auto leaf = coords(i, n);
                if (!trees.occupied(b, d, leaf)) continue;
                for (int a = 0; a < 3; ++a) {
                    want.lo[a] = std::min(want.lo[a], leaf[a]);
                    want.hi[a] = std::max(want.hi[a], leaf[a]);
                }
            }
            const SampledBox& got = trees.sampledBoxes()[b];
            EXPECT_EQ(got, want) << "brick " << b;
            none += got.none();
            narrowed += !got.none() && got != SampledBox{{0, 0, 0}, {n - 1, n - 1, n - 1}};
        }
        EXPECT_GT(narrowed, 0u) << "no box is smaller than its brick: the test proves nothing";
        EXPECT_GT(none, 0u) << "no stored brick is all empty: the test proves nothing";
    }
}

TEST(OccupancyTest, IncrementalRebuildTouchesOnlyBricksMeetingTheChangeAndEqualsAFullOne) {
    auto t = angiography();
    if (!t) return test::missingData("scan CT_AVM");
    const double top = t->store->info().valueMax;
    const auto vessels = TransferFunction::preset("vessels", t->stats);
    const auto moved = peakTf(top - 3.0, 1.0, t->stats);
    OccupancyTrees incremental(*t->store, 0), fresh(*t->store, 0);
    incremental.update(vessels.table(1.0, 4096), {});
    // The same opacities at another step, and another colour: nothing to rebuild.
    EXPECT_EQ(incremental.update(vessels.table(0.5, 4096), {}).bricksRebuilt, 0u);
    const auto recoloured = peakTf(top - 3.0, 1.0, t->stats, "0.1,0.2,0.3");
    incremental.update(moved.table(1.0, 4096), {});
    EXPECT_EQ(incremental.update(recoloured.table(1.0, 4096), {}).bricksRebuilt, 0u);
    // Back to the preset: only bricks reaching the top values or the preset's range change.
    incremental.update(vessels.table(1.0, 4096), {});
    const auto peakOnly = incremental.update(moved.table(1.0, 4096), {});
    EXPECT_FALSE(peakOnly.full);
    fresh.update(moved.table(1.0, 4096), {});
    EXPECT_EQ(incremental.words(), fresh.words());
    EXPECT_EQ(incremental.sampledBoxes(), fresh.sampledBoxes());
    EXPECT_GT(peakOnly.ms, 0.0);
    // A change confined to values above every brick but the brightest touches few bricks.
    const auto nearTop = peakTf(top - 1.0, 0.5, t->stats);
    OccupancyTrees a(*t->store, 0), b(*t->store, 0);
    a.update(moved.table(1.0, 4096), {});
    const auto small = a.update(nearTop.table(1.0, 4096), {});
    b.update(nearTop.table(1.0, 4096), {});
    EXPECT_EQ(a.words(), b.words());
    EXPECT_LT(small.bricksRebuilt, small.bricksStored);
}

TEST(OccupancyTest, CorruptLeafTableIsNamedAndItsBrickIsNeverLeapt) {
    auto t = angiography();
    if (!t) return test::missingData("scan CT_AVM");
    const LevelGeometry g = LevelGeometry::of(*t->store, 0);
    // The first stored brick: flip a byte of its leaf table on disk.
    std::uint64_t victim = 0;
    brickstore::BrickKey key;
    for (; victim < g.brickCount(); ++victim) {
        key = levelBrickKey(victim, g);
        if (t->store->record(key).stored()) break;
    }
    ASSERT_LT(victim, g.brickCount());
    const brickstore::BrickRecord record = t->store->record(key);
    const std::string path = t->store->path();
    t->cache.reset();
    t->store.reset();
    {
        std::fstream f(path, std::ios::in | std::ios::out | std::ios::binary);
        f.seekg(std::streamoff(record.offset + record.compressedBytes + 3));
        char c = 0;
        f.read(&c, 1);
        c = char(c ^ 0x5a);
        f.seekp(std::streamoff(record.offset + record.compressedBytes + 3));
        f.write(&c, 1);
    }
    auto store = brickstore::BrickStore::open(path);
    OccupancyTrees trees(*store, 0);
    ASSERT_EQ(trees.faults().size(), 1u);
    EXPECT_NE(trees.faults()[0].find(key.toString()), std::string::npos) << trees.faults()[0];
    // A TF that shows nothing: every other stored brick is leapt, the corrupt one never.
    trees.update(peakTf(-1e6, 1.0, t->stats).table(1.0, 4096), {});
    const std::uint32_t n = trees.leavesPerAxis();
    for (std::uint32_t i = 0; i < n * n * n; ++i)
        EXPECT_TRUE(trees.occupied(victim, trees.depth(), coords(i, n)));
}

} // namespace
} // namespace bc::render
