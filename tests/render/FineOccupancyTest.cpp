// Leaps below the leaf: per-brick chessboard distance maps over cells of 1, 2 and 4
// voxels, from the drawn bricks' voxels (render/FineOccupancy.h). A cell at distance d > 0
// holds only transparent samples, wherever in it (and a rounding error outside it) a sample
// falls; the distances are exact (1-Lipschitz, one neighbour nearer); and the CPU raycaster's
// images with maps are those without, to max abs 0, on every real scan over an orbit and
// random jumps, on the SIMD march across rays and on the scalar loop, while sparse
// angiography takes far fewer samples.
#include "render/FineOccupancy.h"
#include "RenderTestSupport.h"
#include "render/CpuRaycaster.h"
#include "render/GpuRaycaster.h"
#include "render/Occupancy.h"
#include "render/detail/CpuSampling.h"

#include <optional>
#include <random>

namespace bc::render {
namespace {

using test::TestStore;

bool bitOf(const std::uint32_t* words, std::uint64_t bit) {
    return ((words[bit >> 5] >> (bit & 31)) & 1u) != 0u;
}

/// First bit of octree level l of a brick's words.
std::uint64_t levelFirst(std::uint32_t l) {
    return ((std::uint64_t(1) << (3 * l)) - 8) / 7;
}

template <class T> float valueAt(const void* voxels, int edge, glm::vec3 q) {
    return detail::fetch(static_cast<const T*>(voxels), edge, q);
}

float fetchValue(brickstore::VoxelType type, const void* voxels, int edge, glm::vec3 q) {
    switch (type) {
    case brickstore::VoxelType::U8:
        return valueAt<std::uint8_t>(voxels, edge, q);
    case brickstore::VoxelType::U16:
        return valueAt<std::uint16_t>(voxels, edge, q);
    case brickstore::VoxelType::I16:
        return valueAt<std::int16_t>(voxels, edge, q);
    case brickstore::VoxelType::F32:
        return valueAt<float>(voxels, edge, q);
    }
    return 0;
}

/// CT_AVM under its vessels preset, its octrees brought up to the step-1 table: what the maps
/// are built on. `t` is null when the scan is missing.
struct Angiography {
    std::unique_ptr<TestStore> t = test::ingestRealScan("CT_AVM");
    std::optional<TransferFunctionTable> table;
    std::unique_ptr<OccupancyTrees> trees;
    LevelGeometry g;

    Angiography() {
        if (!t) return;
        table.emplace(
            TransferFunction::preset("vessels", t->stats).table(1.0, kClassificationTableEntries));
        trees = std::make_unique<OccupancyTrees>(*t->store, 0);
        trees->update(*table, {});
        g = LevelGeometry::of(*t->store, 0);
    }
    /// Brick b of level 0 (x fastest).
    brickstore::BrickKey key(std::uint64_t b) const {
        return {0,
                {std::uint32_t(b % g.bricks[0]), std::uint32_t((b / g.bricks[0]) % g.bricks[1]),
                 std::uint32_t(b / (std::uint64_t(g.bricks[0]) * g.bricks[1]))}};
    }
};

TEST(FineOccupancy, AnEmptyCellHoldsOnlyTransparentSamplesAndDistancesAreChessboardExact) {
    const Angiography a;
    if (!a.t) return test::missingData("scan CT_AVM");
    const TestStore* t = a.t.get();
    const TransferFunctionTable& table = *a.table;
    const OccupancyTrees& trees = *a.trees;
    const LevelGeometry& g = a.g;
    const int brick = int(g.brickVoxels), apron = int(g.apronVoxels), edge = brick + 2 * apron;
    const brickstore::VoxelType type = t->store->info().volume.type;
    const std::uint32_t depth = trees.depth(), side = 1u << depth;
    std::mt19937 rng(21);
    std::uniform_real_distribution<float> unit(0.0f, 1.0f);
    for (const std::uint32_t cell : {1u, 2u, 4u}) {
        FineOccupancy fine(trees, table, cell);
        ASSERT_EQ(fine.cellVoxels(), cell);
        ASSERT_EQ(1u << fine.levels(), trees.leafVoxels() / cell);
        const int n = int(fine.cellsPerAxis());
        ASSERT_EQ(std::uint32_t(n), trees.leavesPerAxis() * (trees.leafVoxels() / cell) + 1);
        std::uint64_t kept = 0, emptyCells = 0, samplesTried = 0, far = 0;
        for (std::uint64_t b = 0; b < g.brickCount(); ++b) {
            const brickstore::BrickKey key = a.key(b);
            if (!t->store->record(key).stored()) continue;
            const brickstore::BrickPin pin = t->cache->pin(key);
            const void* voxels = pin.data().data();
            const std::uint32_t offset = fine.offsetOf(b, voxels, type, brick, apron);
            EXPECT_EQ(fine.offsetOf(b, voxels, type, brick, apron), offset) << "built twice";
            if (offset == 0) continue;
            ++kept;
            const auto* map = reinterpret_cast<const std::uint8_t*>(fine.pool() + offset);
            const std::uint32_t* words = trees.words().data() + b * trees.wordsPerBrick();
            auto at = [&](int x, int y, int z) {
                return int(map[(std::size_t(z) * n + std::size_t(y)) * n + std::size_t(x)]);
            };
            for (int z = 0; z < n; ++z)
                for (int y = 0; y < n; ++y)
                    for (int x = 0; x < n; ++x) {
                        const int d = at(x, y, z);
                        // 1-Lipschitz over the 26 neighbours, and (below the cap) one of them
                        // one nearer: the chessboard distance to the nearest cell sampled.
                        bool nearer = d == 0 || d == 255;
                        for (int o = 0; o < 27; ++o) {
                            const int X = x + o % 3 - 1, Y = y + o / 3 % 3 - 1, Z = z + o / 9 - 1;
                            if (o == 13 || X < 0 || Y < 0 || Z < 0 || X >= n || Y >= n || Z >= n)
                                continue;
                            ASSERT_LE(std::abs(at(X, Y, Z) - d), 1) << key.toString();
                            nearer = nearer || at(X, Y, Z) == d - 1;
                        }
                        ASSERT_TRUE(nearer) << key.toString() << " cell " << x << "," << y << ","
                                            << z << " at " << d << " has no neighbour nearer";
                        // Cell (x, y, z) holds positions [(c - 1) cell + 1/2, c cell + 1/2)
                        // per axis: a taken cell overlaps a sampled leaf.
                        const glm::vec3 from = (glm::vec3(x, y, z) - 1.0f) * float(cell) + 0.5f;
                        if (d == 0) {
                            bool leafSet = false;
                            const float leaf = float(trees.leafVoxels());
                            const int last = int(trees.leavesPerAxis()) - 1;
                            auto span = [&](float a) {
                                return std::pair{
                                    std::clamp(int(std::floor(a / leaf)), 0, last),
                                    std::clamp(int(std::floor((a + float(cell) - 1e-3f) / leaf)), 0,
                                               last)};
                            };
                            const auto [x0, x1] = span(from.x);
                            const auto [y0, y1] = span(from.y);
                            const auto [z0, z1] = span(from.z);
                            for (int lz = z0; lz <= z1; ++lz)
                                for (int ly = y0; ly <= y1; ++ly)
                                    for (int lx = x0; lx <= x1; ++lx)
                                        leafSet = leafSet ||
                                                  bitOf(words,
                                                        levelFirst(depth) +
                                                            (std::uint64_t(lz) * side + ly) * side +
                                                            std::uint64_t(lx));
                            EXPECT_TRUE(leafSet)
                                << key.toString() << ": a cell sampled in leapt leaves";
                            continue;
                        }
                        far += d == 255;
                        ++emptyCells;
                        // Samples anywhere in the cell, on its faces, and a rounding error
                        // beyond them.
                        for (int i = 0; i < 12; ++i) {
                            const glm::vec3 u(unit(rng), unit(rng), unit(rng));
                            const glm::vec3 corner(i & 1, (i >> 1) & 1, (i >> 2) & 1);
                            const glm::vec3 p =
                                from + (i < 8 ? corner + (u - 0.5f) * 2e-4f : u) * float(cell);
                            const float v =
                                fetchValue(type, voxels, edge, p + (float(apron) - 0.5f));
                            ++samplesTried;
                            ASSERT_EQ(table.lookup(v)[3], 0.0f)
                                << key.toString() << " cell (" << x << "," << y << "," << z
                                << ") of " << cell << " voxels is empty but value " << v << " at ("
                                << p.x << "," << p.y << "," << p.z << ") is visible";
                        }
                    }
        }
        std::printf("[cells] CT_AVM vessels, %u-voxel cells: %llu bricks with maps, %llu empty "
                    "cells in sampled leaves, %llu samples checked transparent, %llu cells at "
                    "the cap\n",
                    cell, (unsigned long long)kept, (unsigned long long)emptyCells,
                    (unsigned long long)samplesTried, (unsigned long long)far);
        EXPECT_GT(kept, 0u);
        EXPECT_GT(emptyCells, 0u) << "no cell below a sampled leaf is empty: proves nothing";
        const FineOccupancyStats s = fine.stats();
        EXPECT_EQ(s.bricksKept, kept);
        EXPECT_EQ(s.bytes, (kept + 1) * fine.wordsPerBrick() * 4ull);
    }
}

TEST(FineOccupancy, ASpentBudgetLeavesTheOtherBricksToTheOctree) {
    const Angiography a;
    if (!a.t) return test::missingData("scan CT_AVM");
    // Room for slot 0 and one brick.
    const FineOccupancy probe(*a.trees, *a.table, 2);
    FineOccupancy fine(*a.trees, *a.table, 2, 2ull * probe.wordsPerBrick() * 4);
    std::uint64_t given = 0;
    for (std::uint64_t b = 0; b < a.g.brickCount(); ++b) {
        if (!a.t->store->record(a.key(b)).stored()) continue;
        const brickstore::BrickPin pin = a.t->cache->pin(a.key(b));
        given += fine.offsetOf(b, pin.data().data(), a.t->store->info().volume.type,
                               int(a.g.brickVoxels), int(a.g.apronVoxels)) != 0;
    }
    EXPECT_EQ(given, 1u);
    EXPECT_EQ(fine.stats().bricksKept, 1u);
    EXPECT_GT(fine.stats().bricksBuilt, 1u);
    EXPECT_EQ(fine.stats().bytes, 2ull * fine.wordsPerBrick() * 4);
}

TEST(FineOccupancy, CellsThatAreNoPowerOfTwoBelowTheLeafAreRefused) {
    RenderOptions o;
    o.cellVoxels = 3;
    EXPECT_THROW(o.validate(), std::invalid_argument);
    o.cellVoxels = 0;
    EXPECT_NO_THROW(o.validate());
    const Angiography a;
    if (!a.t) return test::missingData("scan CT_AVM");
    EXPECT_THROW(FineOccupancy(*a.trees, *a.table, 8), std::invalid_argument); // the leaf itself
    EXPECT_THROW(FineOccupancy(*a.trees, *a.table, 3), std::invalid_argument);
}

// --- The images: cells change no pixel ----------------------------------------------------

class CellsInvariant : public ::testing::TestWithParam<test::ScanPreset> {};

TEST_P(CellsInvariant, CpuFramesWithCellsAreThoseWithoutOverAnOrbitAndJumps) {
    const test::ScanPreset c = GetParam();
    auto t = test::ingestRealScan(c.scan);
    if (!t) return test::missingData("scan " + c.scan);
    const auto tf = TransferFunction::preset(c.preset, t->stats);
    const Box box = LevelGeometry::of(*t->store, 0).box;
    std::vector<Camera> path;
    for (int f = 0; f < 24; ++f)
        path.push_back(Camera::orbit(box, 15.0 * f, 20.0 + 10.0 * std::sin(f * 0.3)));
    std::mt19937 rng(20261205);
    std::uniform_real_distribution<double> az(0, 360), el(-80, 80), dist(0.35, 1.6);
    for (int f = 0; f < 16; ++f) // distances below ~0.5 put the eye inside the volume
        path.push_back(Camera::orbit(box, az(rng), el(rng), dist(rng)));
    struct Config {
        const char* name;
        SkipMode skip;
        std::uint32_t cells;
        bool simd;
    };
    const Config configs[] = {
        {"plain", SkipMode::None, 0, true},  {"octree leaves", SkipMode::All, 0, true},
        {"cells 1", SkipMode::All, 1, true}, {"cells 2", SkipMode::All, 2, true},
        {"cells 4", SkipMode::All, 4, true}, {"cells 2, scalar", SkipMode::All, 2, false}};
    // One raycaster per configuration, kept over the path as a session keeps its own.
    std::vector<std::unique_ptr<CpuRaycaster>> raycasters;
    for (std::size_t i = 0; i < std::size(configs); ++i)
        raycasters.push_back(std::make_unique<CpuRaycaster>());
    std::vector<std::uint64_t> samples(std::size(configs), 0), cellBricks(std::size(configs), 0);
    for (std::size_t f = 0; f < path.size(); ++f) {
        Image plain;
        for (std::size_t i = 0; i < std::size(configs); ++i) {
            RenderOptions o;
            o.width = o.height = 64;
            o.earlyTermination = false;
            o.skip = configs[i].skip;
            o.cellVoxels = configs[i].cells;
            o.simd = configs[i].simd;
            FrameStats s;
            Image image = raycasters[i]->render(*t->store, *t->cache, tf, path[f], o, s);
            samples[i] += s.samples;
            cellBricks[i] += s.cellBricks;
            if (i == 0) {
                plain = std::move(image);
                continue;
            }
            ASSERT_EQ(compareImages(image, plain).maxAbs, 0.0)
                << c.scan << " " << c.preset << " frame " << f << ", " << configs[i].name;
        }
    }
    for (std::size_t i = 1; i < std::size(configs); ++i) {
        std::printf("[cells] %-12s %-8s %-16s samples %.3f of plain, %llu brick-frames with "
                    "cells\n",
                    c.scan.c_str(), c.preset.c_str(), configs[i].name,
                    double(samples[i]) / double(std::max<std::uint64_t>(samples[0], 1)),
                    (unsigned long long)cellBricks[i]);
        if (configs[i].cells > 0) {
            EXPECT_LE(samples[i], samples[1]) << configs[i].name;
        }
    }
    // The same samples, up to a leap's exit rounded to the other side of a sample (the march
    // across rays multiplies by reciprocals where the scalar loop divides).
    EXPECT_LE(std::abs(double(samples[3]) - double(samples[5])), 1e-5 * double(samples[5]) + 2)
        << "the scalar loop and the march across rays take different samples";
    if (c.scan == "CT_AVM") { // sparse vessels: cells must leap where leaves cannot
        EXPECT_LT(double(samples[3]), 0.8 * double(samples[1]));
        EXPECT_GT(cellBricks[3], 0u);
    }
}

std::string scanName(const ::testing::TestParamInfo<test::ScanPreset>& info) {
    std::string s = info.param.scan + "_" + info.param.preset;
    for (char& ch : s)
        if (ch == '-') ch = '_';
    return s;
}

INSTANTIATE_TEST_SUITE_P(RealScans, CellsInvariant, ::testing::ValuesIn(test::invariantScans()),
                         scanName);

// The GPU raycaster leaps by the same maps (a copy of the pool in a storage buffer): its frames
// with cells are its frames with the octree alone, bit for bit (the same sample positions; only
// transparent samples are left out), over an orbit and jumps; on sparse vessels it takes fewer
// samples. (Its frames against plain, with the default cells, are SkippingInvariant's.)
class GpuCellsInvariant : public ::testing::TestWithParam<test::ScanPreset> {};

TEST_P(GpuCellsInvariant, GpuFramesWithCellsAreThoseOfTheOctreeAloneOverAnOrbitAndJumps) {
    const test::ScanPreset c = GetParam();
    auto spec = test::realScan(c.scan);
    if (!spec) return test::missingData("scan " + c.scan);
    test::glContext();
    auto t = test::ingestSpec(*spec, {32, 2, 8});
    const auto tf = TransferFunction::preset(c.preset, t->stats);
    const Box box = LevelGeometry::of(*t->store, 0).box;
    std::vector<Camera> path;
    for (int f = 0; f < 12; ++f)
        path.push_back(Camera::orbit(box, 30.0 * f, 20.0 + 10.0 * std::sin(f * 0.5)));
    std::mt19937 rng(20261206);
    std::uniform_real_distribution<double> az(0, 360), el(-80, 80), dist(0.35, 1.6);
    for (int f = 0; f < 8; ++f)
        path.push_back(Camera::orbit(box, az(rng), el(rng), dist(rng)));
    constexpr std::uint32_t kCells[] = {0, 1, 2, 4}; // 0: the octree alone, the reference
    std::vector<std::unique_ptr<GpuRaycaster>> raycasters;
    for (std::size_t i = 0; i < std::size(kCells); ++i)
        raycasters.push_back(std::make_unique<GpuRaycaster>());
    std::vector<std::uint64_t> samples(std::size(kCells), 0), cellBricks(std::size(kCells), 0);
    for (std::size_t f = 0; f < path.size(); ++f) {
        Image octree;
        for (std::size_t i = 0; i < std::size(kCells); ++i) {
            RenderOptions o;
            o.width = o.height = 64;
            o.earlyTermination = false;
            o.occlusionFrustums = false;
            o.cellVoxels = kCells[i];
            FrameStats s;
            Image image = test::gpuFrame(*t, *raycasters[i], tf, path[f], o, &s);
            samples[i] += s.samples;
            cellBricks[i] += s.cellBricks;
            if (i == 0) {
                octree = std::move(image);
                continue;
            }
            ASSERT_EQ(compareImages(image, octree).maxAbs, 0.0)
                << c.scan << " " << c.preset << " frame " << f << ", cells " << kCells[i];
        }
    }
    for (std::size_t i = 1; i < std::size(kCells); ++i) {
        std::printf("[gpu cells] %-12s %-8s cells %u: samples %.3f of the octree's, %llu "
                    "brick-frames with maps\n",
                    c.scan.c_str(), c.preset.c_str(), kCells[i],
                    double(samples[i]) / double(std::max<std::uint64_t>(samples[0], 1)),
                    (unsigned long long)cellBricks[i]);
        EXPECT_LE(samples[i], samples[0]) << "cells " << kCells[i];
    }
    if (c.scan == "CT_AVM") { // sparse vessels: the maps must leap where leaves cannot
        EXPECT_LT(double(samples[2]), 0.8 * double(samples[0]));
        EXPECT_GT(cellBricks[2], 0u);
    }
}

INSTANTIATE_TEST_SUITE_P(RealScans, GpuCellsInvariant, ::testing::ValuesIn(test::invariantScans()),
                         scanName);

} // namespace
} // namespace bc::render
