// Store format version 2 (FORMAT.md "Leaf table"): only the leaves inside the volume are
// stored, so a thin volume costs about its voxels; version 1 stores are still read.
#include "brickstore/BrickStore.h"
#include "brickstore/Error.h"
#include "brickstore/Ingest.h"
#include "brickstore/StoreVolume.h"
#include "brickstore/detail/StoreFormat.h"
#include "tests/TestSupport.h"
#include "tests/brickstore/VolumeTestSupport.h"

#include <cstring>
#include <filesystem>
#include <random>

namespace bc::brickstore {
namespace {

std::vector<std::byte> noise(std::uint64_t count, std::uint32_t seed) {
    std::mt19937 rng(seed);
    std::vector<std::byte> v(count * 2);
    for (std::uint64_t i = 0; i < count; ++i) {
        const auto value = static_cast<std::uint16_t>(1000 + rng() % 3000);
        std::memcpy(v.data() + 2 * i, &value, 2);
    }
    return v;
}

struct Ingested {
    test::TempDir dir;
    std::string path;
    std::vector<std::byte> voxels;
    IngestReport report;
};

std::unique_ptr<Ingested> ingestNoise(const std::array<std::uint64_t, 3>& dims, BrickGeometry g) {
    auto r = std::make_unique<Ingested>();
    r->path = r->dir.file("v.bcs");
    r->voxels = noise(dims[0] * dims[1] * dims[2], 11);
    VolumeInfo info;
    info.dims = dims;
    info.type = VoxelType::U16;
    test::VectorSource src(info, r->voxels);
    IngestConfig config;
    config.geometry = g;
    config.threads = 2;
    r->report = ingest(src, r->path, config);
    return r;
}

/// The store's bytes with the header's version field set to `version` and the header
/// checksum recomputed: what a writer of that version would have made when every brick's
/// table is the same in both versions.
std::vector<std::uint8_t> withVersion(const std::string& path, std::uint32_t version) {
    auto bytes = test::readFile(path);
    std::memcpy(bytes.data() + 8, &version, 4);
    const std::uint64_t sum = detail::checksum(bytes.data(), detail::kHeaderBytes - 8);
    std::memcpy(bytes.data() + detail::kHeaderBytes - 8, &sum, 8);
    return bytes;
}

TEST(StoreVersion, AThinVolumeStoresOnlyTheLeavesInsideIt) {
    // 1 x 1 x 20000: every brick of every level is 1 x 1 x 64 voxels of its 64³ payload,
    // 8 of its 512 leaves. Version 1 stored all 512 (4 KiB) per brick: 1.3 MB of tables
    // for 40 kB of voxels.
    const std::array<std::uint64_t, 3> dims{1, 1, 20000};
    auto in = ingestNoise(dims, {64, 2, 8});
    auto store = BrickStore::open(in->path);
    EXPECT_EQ(store->info().formatVersion, 2u);
    const auto& layout = store->layout();
    std::uint64_t expectLeafBytes = 0;
    for (std::uint64_t i = 0; i < layout.brickCount(); ++i) {
        const BrickKey key = layout.keyOf(i);
        const auto inside = layout.leavesInside(key);
        EXPECT_EQ(inside[0], 1u);
        EXPECT_EQ(inside[1], 1u);
        if (store->record(key).stored()) {
            EXPECT_EQ(store->record(key).leafBytes, 8u * inside[2]) << key.toString();
            expectLeafBytes += 8u * inside[2];
        }
        EXPECT_EQ(store->leafRanges(key).size(), layout.leafCount());
    }
    EXPECT_EQ(in->report.leafTableBytes, expectLeafBytes);
    EXPECT_LE(in->report.leafTableBytes, 8 * in->report.sourceBytes);
    // Header, 48-byte records and zstd frames of mostly repeated voxels: a few times the
    // voxels, where version 1 took 1.3 MB of leaf tables alone.
    EXPECT_LT(in->report.fileBytes, 400'000u);
    EXPECT_TRUE(store->verify(2).empty());
    auto level0 = openStoreLevel(*store, 0);
    EXPECT_TRUE(test::readAllSlices(*level0, 777) == in->voxels);
}

TEST(StoreVersion, AVersionOneStoreIsStillRead) {
    // 32³ in bricks of 16: every brick of both levels is full, so its leaf table is the same
    // in both versions and the file differs only in the header's version field.
    auto in = ingestNoise({32, 32, 32}, {16, 2, 4});
    auto v1 = withVersion(in->path, 1);
    const std::string oldPath = in->dir.file("v1.bcs");
    test::writeFile(oldPath, v1.data(), v1.size());
    auto current = BrickStore::open(in->path);
    auto old = BrickStore::open(oldPath);
    EXPECT_EQ(old->info().formatVersion, 1u);
    EXPECT_TRUE(old->verify(2).empty());
    std::vector<std::byte> a(current->brickBytes()), b(old->brickBytes());
    for (std::uint64_t i = 0; i < current->layout().brickCount(); ++i) {
        const BrickKey key = current->layout().keyOf(i);
        current->readBrick(key, a);
        old->readBrick(key, b);
        EXPECT_TRUE(a == b) << key.toString();
        const auto la = current->leafRanges(key), lb = old->leafRanges(key);
        ASSERT_EQ(la.size(), lb.size());
        for (std::size_t l = 0; l < la.size(); ++l) {
            EXPECT_EQ(la[l].min, lb[l].min);
            EXPECT_EQ(la[l].max, lb[l].max);
        }
    }
}

TEST(StoreVersion, EachVersionChecksItsOwnLeafTableSize) {
    // 40³ in bricks of 16: the far border bricks keep 2 of 4 leaves along that axis. Read
    // as version 1 their tables are short, and opening names the first such brick.
    auto in = ingestNoise({40, 40, 40}, {16, 2, 4});
    auto v1 = withVersion(in->path, 1);
    const std::string oldPath = in->dir.file("v1.bcs");
    test::writeFile(oldPath, v1.data(), v1.size());
    try {
        BrickStore::open(oldPath);
        FAIL() << "a version-2 table read as version 1 was accepted";
    } catch (const StoreCorrupt& e) {
        const std::string what = e.what();
        EXPECT_NE(what.find("brick L0 (2,0,0): leaf table of 256 bytes, expected 512"),
                  std::string::npos)
            << what;
    }
    auto v3 = withVersion(in->path, 3);
    test::writeFile(oldPath, v3.data(), v3.size());
    try {
        BrickStore::open(oldPath);
        FAIL() << "version 3 was accepted";
    } catch (const StoreCorrupt& e) {
        EXPECT_NE(std::string(e.what()).find("format version 3 is not supported"),
                  std::string::npos)
            << e.what();
    }
}

} // namespace
} // namespace bc::brickstore
