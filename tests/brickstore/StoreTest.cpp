// Store round trips, summaries, pyramid and corruption handling on in-memory volumes.
#include "brickstore/BrickStore.h"
#include "brickstore/Error.h"
#include "brickstore/Ingest.h"
#include "brickstore/StoreVolume.h"
#include "brickstore/detail/BrickSummary.h"
#include "tests/TestSupport.h"
#include "tests/brickstore/VolumeTestSupport.h"

#include <algorithm>
#include <cmath>
#include <cstring>
#include <filesystem>
#include <limits>
#include <random>
#include <sys/wait.h>
#include <unistd.h>

namespace bc::brickstore {
namespace {

using test::VectorSource;

template <typename T>
std::vector<std::byte> randomVolume(const std::array<std::uint64_t, 3>& d, std::uint32_t seed,
                                    double lo, double hi) {
    std::mt19937 rng(seed);
    std::uniform_real_distribution<double> dist(lo, hi);
    std::vector<T> v(d[0] * d[1] * d[2]);
    // Smooth-ish field plus noise and an empty (zero) corner region so constant bricks occur.
    for (std::uint64_t z = 0; z < d[2]; ++z)
        for (std::uint64_t y = 0; y < d[1]; ++y)
            for (std::uint64_t x = 0; x < d[0]; ++x) {
                double r = double(x + y + z) / double(d[0] + d[1] + d[2]);
                double val = r < 0.3
                                 ? 0.0
                                 : lo + (hi - lo) * 0.5 * (1 + std::sin(0.3 * x + 0.2 * y)) * 0.8 +
                                       0.2 * dist(rng);
                v[(z * d[1] + y) * d[0] + x] = static_cast<T>(std::clamp(val, lo, hi));
            }
    std::vector<std::byte> bytes(v.size() * sizeof(T));
    std::memcpy(bytes.data(), v.data(), bytes.size());
    return bytes;
}

/// The voxels of `bytes` (native `type`) as doubles.
std::vector<double> valuesOf(VoxelType type, const std::vector<std::byte>& bytes) {
    const auto read = [&](auto sample) {
        using T = decltype(sample);
        std::vector<double> out(bytes.size() / sizeof(T));
        for (std::size_t i = 0; i < out.size(); ++i) {
            T value;
            std::memcpy(&value, bytes.data() + i * sizeof(T), sizeof(T));
            out[i] = double(value);
        }
        return out;
    };
    switch (type) {
    case VoxelType::U8:
        return read(std::uint8_t{});
    case VoxelType::U16:
        return read(std::uint16_t{});
    case VoxelType::I16:
        return read(std::int16_t{});
    case VoxelType::F32:
        return read(float{});
    }
    return {};
}

VolumeInfo makeInfo(const std::array<std::uint64_t, 3>& dims, VoxelType type) {
    VolumeInfo info;
    info.dims = dims;
    info.type = type;
    info.spacingMm = {0.5, 0.75, 2.0};
    info.description = "test volume";
    return info;
}

std::vector<std::byte> readLevel(const BrickStore& store, std::uint32_t level) {
    auto src = openStoreLevel(store, level);
    return test::readAllSlices(*src, {1, 2, 3, 4, 5}); // uneven chunks on purpose
}

struct Ingested {
    test::TempDir dir;
    std::string path;
    std::vector<std::byte> voxels;
    VolumeInfo info;
};

std::unique_ptr<Ingested> ingestVector(VolumeInfo info, std::vector<std::byte> voxels,
                                       BrickGeometry g) {
    auto r = std::make_unique<Ingested>();
    r->path = r->dir.file("v.bcs");
    r->voxels = voxels;
    r->info = info;
    VectorSource src(info, std::move(voxels));
    IngestConfig config;
    config.geometry = g;
    config.threads = 2;
    ingest(src, r->path, config);
    return r;
}

struct RoundTripCase {
    VoxelType type;
    std::array<std::uint64_t, 3> dims;
    BrickGeometry geometry;
};

class StoreRoundTrip : public ::testing::TestWithParam<RoundTripCase> {};

TEST_P(StoreRoundTrip, ExtractGivesBackTheSourceVoxelsExactly) {
    const auto& c = GetParam();
    std::vector<std::byte> v;
    switch (c.type) {
    case VoxelType::U8:
        v = randomVolume<std::uint8_t>(c.dims, 1, 0, 255);
        break;
    case VoxelType::U16:
        v = randomVolume<std::uint16_t>(c.dims, 2, 0, 4000);
        break;
    case VoxelType::I16:
        v = randomVolume<std::int16_t>(c.dims, 3, -1000, 2000);
        break;
    case VoxelType::F32:
        v = randomVolume<float>(c.dims, 4, -1.5, 3.25);
        break;
    }
    auto in = ingestVector(makeInfo(c.dims, c.type), v, c.geometry);
    auto store = BrickStore::open(in->path);
    EXPECT_EQ(store->info().volume.dims, c.dims);
    EXPECT_EQ(store->info().volume.type, c.type);
    EXPECT_EQ(store->info().volume.spacingMm, (std::array<double, 3>{0.5, 0.75, 2.0}));
    EXPECT_TRUE(readLevel(*store, 0) == v);
    EXPECT_TRUE(store->verify(2).empty());
    // The histogram is every source voxel binned over [min, max]: counted per value as the
    // bricks are compressed (8- and 16-bit integers) or read back afterwards (f32).
    const auto values = valuesOf(c.type, v);
    const auto [lo, hi] = std::minmax_element(values.begin(), values.end());
    EXPECT_EQ(store->info().valueMin, *lo);
    EXPECT_EQ(store->info().valueMax, *hi);
    std::vector<std::uint64_t> expected(store->info().histogram.size());
    for (double value : values)
        ++expected[detail::histogramBin(value, *lo, *hi, expected.size())];
    EXPECT_EQ(store->info().histogram, expected);
}

INSTANTIATE_TEST_SUITE_P(TypesAndBrickSizes, StoreRoundTrip,
                         ::testing::Values(RoundTripCase{VoxelType::U8, {70, 45, 33}, {16, 2, 4}},
                                           RoundTripCase{VoxelType::U8, {70, 45, 33}, {32, 1, 8}},
                                           RoundTripCase{VoxelType::U16, {40, 64, 17}, {16, 2, 8}},
                                           RoundTripCase{VoxelType::I16, {33, 20, 50}, {8, 2, 3}},
                                           RoundTripCase{VoxelType::F32, {25, 31, 29}, {16, 2, 8}},
                                           RoundTripCase{VoxelType::U8, {5, 3, 2}, {8, 2, 8}},
                                           RoundTripCase{VoxelType::U8, {1, 1, 1}, {4, 0, 1}}),
                         [](const auto& info) {
                             const auto& c = info.param;
                             return std::string(voxelTypeName(c.type)) + "_" +
                                    std::to_string(c.dims[0]) + "x" + std::to_string(c.dims[1]) +
                                    "x" + std::to_string(c.dims[2]) + "_brick" +
                                    std::to_string(c.geometry.brickVoxels) + "_apron" +
                                    std::to_string(c.geometry.apronVoxels);
                         });

TEST(StoreTest, PipelinedAndLeanRingsWriteTheSameStoreAndATightBudgetGetsTheLean) {
    // Deep enough that level 0's ring wraps many times (B = 8: rings of 20 and 12 slices).
    const std::array<std::uint64_t, 3> dims{40, 36, 150};
    const BrickGeometry g{8, 2, 4};
    const auto v = randomVolume<std::uint16_t>(dims, 7, 0, 3000);
    const VolumeInfo info = makeInfo(dims, VoxelType::U16);
    IngestConfig config;
    config.geometry = g;
    config.threads = 2;
    const std::uint64_t pipelined = ingestMemoryBytes(info, config, true);
    const std::uint64_t lean = ingestMemoryBytes(info, config, false);
    ASSERT_LT(lean, pipelined);
    test::TempDir dir;
    std::vector<std::unique_ptr<BrickStore>> stores;
    for (const std::uint64_t budget : {std::uint64_t(0), lean}) {
        IngestConfig c = config;
        c.memoryBudgetBytes = budget; // 0: the default, which the pipelined rings fit
        VectorSource src(info, v);
        const std::string path = dir.file(budget ? "lean.bcs" : "pipelined.bcs");
        const IngestReport report = ingest(src, path, c);
        EXPECT_EQ(report.memoryBytes, budget ? lean : pipelined);
        stores.push_back(BrickStore::open(path));
    }
    EXPECT_THROW(
        {
            IngestConfig c = config;
            c.memoryBudgetBytes = lean - 1;
            VectorSource src(info, v);
            ingest(src, dir.file("refused.bcs"), c);
        },
        FormatError);
    ASSERT_EQ(stores[0]->layout().levels().size(), stores[1]->layout().levels().size());
    EXPECT_TRUE(readLevel(*stores[0], 0) == v);
    for (std::uint32_t l = 0; l < stores[0]->layout().levels().size(); ++l)
        EXPECT_TRUE(readLevel(*stores[0], l) == readLevel(*stores[1], l)) << "level " << l;
    EXPECT_EQ(stores[0]->info().histogram, stores[1]->info().histogram);
    EXPECT_TRUE(stores[0]->verify(2).empty());
    EXPECT_TRUE(stores[1]->verify(2).empty());
}

TEST(StoreTest, ApronsHoldNeighbourVoxelsAndClampedCopiesAtTheBorder) {
    std::array<std::uint64_t, 3> d{37, 29, 23};
    auto v = randomVolume<std::uint16_t>(d, 7, 100, 4000);
    BrickGeometry g{8, 2, 4};
    auto in = ingestVector(makeInfo(d, VoxelType::U16), v, g);
    auto store = BrickStore::open(in->path);
    const auto& layout = store->layout();
    const auto& l0 = layout.levels()[0];
    const std::int64_t e = layout.storedEdge(), b = g.brickVoxels, a = g.apronVoxels;
    std::vector<std::byte> brick(store->brickBytes());
    auto at = [&](std::int64_t x, std::int64_t y, std::int64_t z) {
        x = std::clamp<std::int64_t>(x, 0, d[0] - 1);
        y = std::clamp<std::int64_t>(y, 0, d[1] - 1);
        z = std::clamp<std::int64_t>(z, 0, d[2] - 1);
        std::uint16_t s;
        std::memcpy(&s, v.data() + 2 * ((z * d[1] + y) * d[0] + x), 2);
        return s;
    };
    for (std::uint32_t bz = 0; bz < l0.bricks[2]; ++bz)
        for (std::uint32_t by = 0; by < l0.bricks[1]; ++by)
            for (std::uint32_t bx = 0; bx < l0.bricks[0]; ++bx) {
                store->readBrick({0, {bx, by, bz}}, brick);
                for (std::int64_t k = 0; k < e; ++k)
                    for (std::int64_t j = 0; j < e; ++j)
                        for (std::int64_t i = 0; i < e; ++i) {
                            std::uint16_t s;
                            std::memcpy(&s, brick.data() + 2 * ((k * e + j) * e + i), 2);
                            ASSERT_EQ(s, at(bx * b - a + i, by * b - a + j, bz * b - a + k))
                                << "brick " << bx << "," << by << "," << bz << " voxel " << i << ","
                                << j << "," << k;
                        }
            }
}

TEST(StoreTest, LeafRangesCoverExactlyTheVoxelsTheirSamplesRead) {
    std::array<std::uint64_t, 3> d{40, 40, 40};
    auto v = randomVolume<std::uint8_t>(d, 9, 0, 255);
    BrickGeometry g{16, 2, 4};
    auto in = ingestVector(makeInfo(d, VoxelType::U8), v, g);
    auto store = BrickStore::open(in->path);
    const auto& layout = store->layout();
    std::vector<std::byte> brick(store->brickBytes());
    const std::int64_t e = layout.storedEdge(), n = layout.leavesPerAxis(), L = g.leafVoxels,
                       A = g.apronVoxels;
    for (std::uint64_t idx = 0; idx < layout.levels()[0].brickCount(); ++idx) {
        BrickKey key = layout.keyOf(idx);
        store->readBrick(key, brick);
        auto leaves = store->leafRanges(key);
        ASSERT_EQ(leaves.size(), std::size_t(n * n * n));
        // 40 = 2·16 + 8: the far border bricks hold 2 of 4 leaves along that axis. The leaves
        // past the volume are not stored: they read as the nearest leaf inside (whose window
        // reads every value theirs does, so their range contains the exact one).
        const auto inside = layout.leavesInside(key);
        float bmin = 1e9f, bmax = -1e9f;
        for (std::size_t i = 0; i < brick.size(); ++i) {
            bmin = std::min(bmin, float(std::uint8_t(brick[i])));
            bmax = std::max(bmax, float(std::uint8_t(brick[i])));
        }
        EXPECT_EQ(store->record(key).range.min, bmin);
        EXPECT_EQ(store->record(key).range.max, bmax);
        for (std::int64_t lz = 0; lz < n; ++lz)
            for (std::int64_t ly = 0; ly < n; ++ly)
                for (std::int64_t lx = 0; lx < n; ++lx) {
                    // Payload voxels of the leaf, widened by the apron reach, in stored coords.
                    float mn = 1e9f, mx = -1e9f;
                    for (std::int64_t z = lz * L;
                         z < std::min<std::int64_t>((lz + 1) * L, g.brickVoxels) + 2 * A; ++z)
                        for (std::int64_t y = ly * L;
                             y < std::min<std::int64_t>((ly + 1) * L, g.brickVoxels) + 2 * A; ++y)
                            for (std::int64_t x = lx * L;
                                 x < std::min<std::int64_t>((lx + 1) * L, g.brickVoxels) + 2 * A;
                                 ++x) {
                                float s = float(std::uint8_t(brick[(z * e + y) * e + x]));
                                mn = std::min(mn, s);
                                mx = std::max(mx, s);
                            }
                    const auto& leaf = leaves[(lz * n + ly) * n + lx];
                    if (lx < inside[0] && ly < inside[1] && lz < inside[2]) {
                        ASSERT_EQ(leaf.min, mn);
                        ASSERT_EQ(leaf.max, mx);
                        continue;
                    }
                    const auto& near = leaves[(std::min<std::int64_t>(lz, inside[2] - 1) * n +
                                               std::min<std::int64_t>(ly, inside[1] - 1)) *
                                                  n +
                                              std::min<std::int64_t>(lx, inside[0] - 1)];
                    ASSERT_EQ(leaf.min, near.min);
                    ASSERT_EQ(leaf.max, near.max);
                    ASSERT_LE(leaf.min, mn);
                    ASSERT_GE(leaf.max, mx);
                }
    }
}

TEST(StoreTest, PyramidLevelsAreRoundedTwoByTwoByTwoMeans) {
    std::array<std::uint64_t, 3> d{21, 18, 11};
    auto v = randomVolume<std::uint16_t>(d, 11, 0, 60000);
    auto in = ingestVector(makeInfo(d, VoxelType::U16), v, {8, 1, 4});
    auto store = BrickStore::open(in->path);
    ASSERT_EQ(store->layout().levels().size(), 3u); // 21 -> 11 -> 6 (fits in 8)
    auto l1 = readLevel(*store, 1);
    const std::array<std::uint64_t, 3> d1{11, 9, 6};
    ASSERT_EQ(store->layout().levels()[1].dims, d1);
    auto src = [&](std::uint64_t x, std::uint64_t y, std::uint64_t z) {
        x = std::min(x, d[0] - 1), y = std::min(y, d[1] - 1), z = std::min(z, d[2] - 1);
        std::uint16_t s;
        std::memcpy(&s, v.data() + 2 * ((z * d[1] + y) * d[0] + x), 2);
        return std::uint64_t(s);
    };
    for (std::uint64_t z = 0; z < d1[2]; ++z)
        for (std::uint64_t y = 0; y < d1[1]; ++y)
            for (std::uint64_t x = 0; x < d1[0]; ++x) {
                std::uint64_t sum = 0;
                for (int k = 0; k < 8; ++k)
                    sum += src(2 * x + (k & 1), 2 * y + ((k >> 1) & 1), 2 * z + (k >> 2));
                std::uint16_t got;
                std::memcpy(&got, l1.data() + 2 * ((z * d1[1] + y) * d1[0] + x), 2);
                ASSERT_EQ(got, (sum + 4) / 8) << x << "," << y << "," << z;
            }
    auto l2 = openStoreLevel(*store, 2);
    EXPECT_EQ(l2->info().spacingMm[2], 8.0);
}

TEST(StoreTest, ConstantBricksAreNotStoredAndReadBackAsTheirValue) {
    std::array<std::uint64_t, 3> d{64, 64, 64};
    std::vector<std::byte> v(d[0] * d[1] * d[2], std::byte{0});
    for (std::uint64_t z = 36; z < 44; ++z)
        v[(z * d[1] + 40) * d[0] + 40] = std::byte{200};
    auto in = ingestVector(makeInfo(d, VoxelType::U8), v, {16, 2, 8});
    auto store = BrickStore::open(in->path);
    std::uint64_t stored = 0;
    for (std::uint64_t i = 0; i < store->layout().levels()[0].brickCount(); ++i)
        stored += store->record(store->layout().keyOf(i)).stored();
    // The spike at (40, 40, 36..43) lies in brick (2,2,2), beyond the 2-voxel apron reach
    // of every neighbour (which read 30..33 and 46..49 of this brick's range).
    EXPECT_EQ(stored, 1u);
    EXPECT_EQ(store->storedBricks(0), 1u);
    std::uint64_t total = 0; // the pyramid's levels: what each stores is counted apart
    for (std::uint32_t l = 0; l < store->layout().levels().size(); ++l) {
        std::uint64_t inLevel = 0;
        for (std::uint64_t i = 0; i < store->layout().brickCount(); ++i)
            inLevel += store->layout().keyOf(i).level == l &&
                       store->record(store->layout().keyOf(i)).stored();
        EXPECT_EQ(store->storedBricks(l), inLevel) << "level " << l;
        total += inLevel;
    }
    EXPECT_EQ(total, store->info().storedBricks);
    EXPECT_EQ(store->storedBricks(std::uint32_t(store->layout().levels().size())), 0u);
    EXPECT_TRUE(readLevel(*store, 0) == v);
    EXPECT_EQ(store->info().valueMin, 0.0);
    EXPECT_EQ(store->info().valueMax, 200.0);
}

/// Offset of the first stored level-0 brick's frame.
std::pair<BrickKey, std::uint64_t> firstStoredBrick(const BrickStore& store) {
    for (std::uint64_t i = 0; i < store.layout().brickCount(); ++i) {
        BrickKey k = store.layout().keyOf(i);
        if (store.record(k).stored()) return {k, store.record(k).offset};
    }
    return {{}, 0};
}

TEST(StoreTest, OneFlippedBitIsNamedAndEveryOtherBrickStillReads) {
    std::array<std::uint64_t, 3> d{48, 48, 48};
    auto in = ingestVector(makeInfo(d, VoxelType::U8), randomVolume<std::uint8_t>(d, 5, 0, 255),
                           {16, 2, 8});
    auto [victim, offset] = firstStoredBrick(*BrickStore::open(in->path));
    {
        std::fstream f(in->path, std::ios::in | std::ios::out | std::ios::binary);
        f.seekg(std::streamoff(offset + 10));
        char c;
        f.read(&c, 1);
        c ^= 0x08;
        f.seekp(std::streamoff(offset + 10));
        f.write(&c, 1);
    }
    auto store = BrickStore::open(in->path); // the index is intact: opening succeeds
    std::vector<std::byte> buf(store->brickBytes());
    try {
        store->readBrick(victim, buf);
        FAIL() << "corruption not detected";
    } catch (const StoreCorrupt& e) {
        EXPECT_NE(std::string(e.what()).find(victim.toString()), std::string::npos) << e.what();
        EXPECT_NE(std::string(e.what()).find(in->path), std::string::npos);
    }
    std::uint64_t readable = 0;
    for (std::uint64_t i = 0; i < store->layout().brickCount(); ++i) {
        BrickKey k = store->layout().keyOf(i);
        if (k == victim) continue;
        store->readBrick(k, buf);
        ++readable;
    }
    EXPECT_EQ(readable, store->layout().brickCount() - 1);
    auto faults = store->verify(2);
    ASSERT_EQ(faults.size(), 1u);
    EXPECT_NE(faults[0].find(victim.toString()), std::string::npos);
}

TEST(StoreTest, TruncatedStoreIsRejectedOnOpen) {
    std::array<std::uint64_t, 3> d{32, 32, 32};
    auto in = ingestVector(makeInfo(d, VoxelType::U8), randomVolume<std::uint8_t>(d, 6, 0, 255),
                           {16, 2, 8});
    auto full = std::filesystem::file_size(in->path);
    for (std::uint64_t keep :
         {full - 1, full / 2, std::uint64_t(5000), std::uint64_t(100), std::uint64_t(0)}) {
        std::string cut = in->dir.file("cut.bcs");
        std::filesystem::copy_file(in->path, cut,
                                   std::filesystem::copy_options::overwrite_existing);
        std::filesystem::resize_file(cut, keep);
        try {
            BrickStore::open(cut);
            FAIL() << "truncation to " << keep << " bytes not detected";
        } catch (const StoreCorrupt& e) {
            EXPECT_NE(std::string(e.what()).find(cut), std::string::npos) << e.what();
        }
    }
}

TEST(StoreTest, CorruptIndexFieldsAreRejectedOnOpen) {
    std::array<std::uint64_t, 3> d{32, 32, 32};
    auto in = ingestVector(makeInfo(d, VoxelType::U8), randomVolume<std::uint8_t>(d, 6, 0, 255),
                           {16, 2, 8});
    auto bytes = test::readFile(in->path);
    for (std::size_t at :
         {std::size_t(20), std::size_t(4090), bytes.size() - 30, bytes.size() - 200}) {
        auto copy = bytes;
        copy[at] ^= 0x40;
        std::string bad = in->dir.file("bad.bcs");
        test::writeFile(bad, copy.data(), copy.size());
        EXPECT_THROW(BrickStore::open(bad), StoreCorrupt) << "flip at byte " << at;
    }
}

TEST(StoreTest, FailedIngestLeavesTheExistingStoreUntouched) {
    std::array<std::uint64_t, 3> d{32, 32, 32};
    auto in = ingestVector(makeInfo(d, VoxelType::U8), randomVolume<std::uint8_t>(d, 6, 0, 255),
                           {16, 2, 8});
    auto before = test::readFile(in->path);
    // A source whose data runs out halfway fails the ingest.
    class FailingSource final : public VolumeSource {
      public:
        FailingSource() { mInfo.dims = {32, 32, 32}; }
        const VolumeInfo& info() const override { return mInfo; }
        void readNextSlices(std::uint64_t count, std::span<std::byte> out) override {
            if (nextSlice() + count > 16)
                throw FormatError("failing.raw", "size", "file ends early");
            std::fill(out.begin(), out.end(), std::byte{7});
        }
        VolumeInfo mInfo;
    } failing;
    IngestConfig config;
    config.geometry = {16, 2, 8};
    EXPECT_THROW(ingest(failing, in->path, config), FormatError);
    EXPECT_TRUE(test::readFile(in->path) == before);
    for (const auto& e : std::filesystem::directory_iterator(in->dir.path()))
        EXPECT_EQ(e.path().filename().string().find(".partial."), std::string::npos) << e.path();
}

TEST(StoreTest, IngestKilledMidwayLeavesNoValidLookingStore) {
    test::TempDir dir;
    std::string path = dir.file("killed.bcs");
    // A slow endless source in a child process, killed while it writes bricks.
    pid_t child = ::fork();
    ASSERT_GE(child, 0);
    if (child == 0) {
        class SlowSource final : public VolumeSource {
          public:
            SlowSource() { mInfo.dims = {128, 128, 4096}; }
            const VolumeInfo& info() const override { return mInfo; }
            void readNextSlices(std::uint64_t, std::span<std::byte> out) override {
                for (auto& b : out)
                    b = std::byte(mBytesPainted++ * 2654435761u >> 24);
                ::usleep(2000);
            }
            VolumeInfo mInfo;
            std::uint32_t mBytesPainted = 0; ///< a byte counter: the pattern runs across slices
        } slow;
        IngestConfig config;
        config.geometry = {32, 2, 8};
        try {
            ingest(slow, path, config);
        } catch (...) {
        }
        ::_exit(0);
    }
    // Wait until the partial file has grown past its header, then kill.
    std::string partial = path + ".partial." + std::to_string(child);
    for (int i = 0; i < 500; ++i) {
        std::error_code ec;
        auto size = std::filesystem::file_size(partial, ec);
        if (!ec && size > 200000) break;
        ::usleep(10000);
    }
    ::kill(child, SIGKILL);
    int status = 0;
    ::waitpid(child, &status, 0);
    EXPECT_FALSE(std::filesystem::exists(path));
    ASSERT_TRUE(std::filesystem::exists(partial)) << "the ingest never started writing";
    EXPECT_THROW(BrickStore::open(partial), StoreCorrupt);
    // The next ingest to the same name clears the dead ingest's partial file.
    std::array<std::uint64_t, 3> d{8, 8, 8};
    VectorSource small(makeInfo(d, VoxelType::U8), std::vector<std::byte>(512, std::byte{1}));
    ingest(small, path, {});
    EXPECT_FALSE(std::filesystem::exists(partial));
    EXPECT_NO_THROW(BrickStore::open(path));
}

TEST(StoreTest, BadGeometryAndVolumeInfoAreRejectedBeforeAnythingIsWritten) {
    test::TempDir dir;
    std::array<std::uint64_t, 3> d{8, 8, 8};
    VectorSource src(makeInfo(d, VoxelType::U8), std::vector<std::byte>(512));
    IngestConfig config;
    config.geometry = {64, 64, 8}; // apron as large as the brick
    EXPECT_THROW(ingest(src, dir.file("a.bcs"), config), std::invalid_argument);
    auto info = makeInfo({8, 0, 8}, VoxelType::U8);
    VectorSource zero(info, {});
    EXPECT_THROW(ingest(zero, dir.file("b.bcs"), {}), FormatError);
    EXPECT_TRUE(std::filesystem::is_empty(dir.path()));
}

} // namespace
} // namespace bc::brickstore

// Found by fuzzing the store (fuzz_brick_store): a damaged record's constant outside its type's
// range was cast to the type (undefined behaviour); it is clamped, NaN read as 0.
TEST(StoreConstantBrick, AConstantOutsideTheTypeIsClampedNotCast) {
    std::array<std::byte, 4> out{};
    bc::brickstore::detail::fillConstant(bc::brickstore::VoxelType::U8, 3.7e19, out);
    EXPECT_EQ(std::to_integer<int>(out[0]), 255);
    bc::brickstore::detail::fillConstant(bc::brickstore::VoxelType::U8, -5.0, out);
    EXPECT_EQ(std::to_integer<int>(out[3]), 0);
    bc::brickstore::detail::fillConstant(bc::brickstore::VoxelType::U8, std::nan(""), out);
    EXPECT_EQ(std::to_integer<int>(out[1]), 0);
    std::array<std::byte, 4> words{};
    bc::brickstore::detail::fillConstant(bc::brickstore::VoxelType::I16, -1e9, words);
    std::int16_t v = 0;
    std::memcpy(&v, words.data(), 2);
    EXPECT_EQ(v, std::numeric_limits<std::int16_t>::lowest());
}
