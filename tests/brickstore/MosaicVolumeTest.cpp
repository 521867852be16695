// makeMosaic over generated volumes and over a real scan served from memory.
#include "brickstore/Error.h"
#include "brickstore/Readers.h"
#include "tests/TestSupport.h"
#include "tests/brickstore/VolumeTestSupport.h"

#include <gtest/gtest.h>

#include <cstring>

namespace bc::brickstore {
namespace {

using Dims = std::array<std::uint64_t, 3>;
using test::readAllSlices;

/// Every output voxel (x,y,z) equals source voxel (x%dx, y%dy, z%dz).
void expectTiled(const std::vector<std::byte>& tiled, const std::vector<std::byte>& source,
                 const Dims& d, const Dims& tiles, std::size_t voxelSize) {
    const Dims out{d[0] * tiles[0], d[1] * tiles[1], d[2] * tiles[2]};
    ASSERT_EQ(tiled.size(), out[0] * out[1] * out[2] * voxelSize);
    for (std::uint64_t z = 0; z < out[2]; ++z)
        for (std::uint64_t y = 0; y < out[1]; ++y)
            for (std::uint64_t x = 0; x < out[0]; ++x) {
                const std::uint64_t o = ((z * out[1] + y) * out[0] + x) * voxelSize;
                const std::uint64_t s =
                    (((z % d[2]) * d[1] + y % d[1]) * d[0] + x % d[0]) * voxelSize;
                ASSERT_EQ(std::memcmp(tiled.data() + o, source.data() + s, voxelSize), 0)
                    << "voxel (" << x << "," << y << "," << z << ")";
            }
}

TEST(MosaicVolumeTest, TilesAGeneratedVolumeAndOpensOneSourcePerZRepetition) {
    const Dims dims{13, 11, 7}, tiles{2, 3, 2};
    const auto source = readAllSlices(*makeSynthetic(SynthKind::Vessels, dims, 5), 7);
    int opens = 0;
    auto mosaic = makeMosaic(
        [&] {
            ++opens;
            return makeSynthetic(SynthKind::Vessels, dims, 5);
        },
        tiles);
    EXPECT_EQ(mosaic->info().dims, (Dims{26, 33, 14}));
    EXPECT_EQ(mosaic->info().type, VoxelType::U8);
    EXPECT_NE(mosaic->info().description.find("mosaic 2x3x2 of synthetic vessels"),
              std::string::npos)
        << mosaic->info().description;
    const auto tiled = readAllSlices(*mosaic, 3); // chunks that straddle the z seam
    expectTiled(tiled, source, dims, tiles, 1);
    EXPECT_EQ(opens, 2);
}

TEST(MosaicVolumeTest, TilesARealScanServedFromMemory) {
    const std::string name = "vtk_headsq_quarter_64x64x93_uint16.raw";
    if (!test::haveData(name)) return test::missingData(name);
    const auto raw = test::readFile(test::dataPath(name));
    std::vector<std::byte> bytes(raw.size());
    std::memcpy(bytes.data(), raw.data(), raw.size());
    VolumeInfo info;
    info.dims = {64, 64, 93};
    info.type = VoxelType::U16;
    info.spacingMm = {3.2, 3.2, 1.5};
    info.description = "headsq quarter";
    ASSERT_EQ(bytes.size(), info.voxelCount() * 2);

    const Dims tiles{2, 3, 2};
    auto mosaic =
        makeMosaic([&] { return std::make_unique<test::VectorSource>(info, bytes); }, tiles);
    EXPECT_EQ(mosaic->info().dims, (Dims{128, 192, 186}));
    EXPECT_EQ(mosaic->info().type, VoxelType::U16);
    EXPECT_EQ(mosaic->info().spacingMm, info.spacingMm);
    expectTiled(readAllSlices(*mosaic, 10), bytes, info.dims, tiles, 2);
}

TEST(MosaicVolumeTest, OneByOneByOneIsTheSourceItself) {
    const Dims dims{9, 10, 11};
    auto mosaic = makeMosaic([&] { return makeSynthetic(SynthKind::Phantom, dims, 2); }, {1, 1, 1});
    EXPECT_EQ(readAllSlices(*mosaic, 4),
              readAllSlices(*makeSynthetic(SynthKind::Phantom, dims, 2), 11));
}

TEST(MosaicVolumeTest, RejectsZeroTilesAndOverflowingDims) {
    auto open = [] { return makeSynthetic(SynthKind::Checker, {64, 64, 64}, 1); };
    EXPECT_THROW(makeMosaic(open, {0, 1, 1}), FormatError);
    try {
        makeMosaic(open, {1, 1ull << 60, 1});
        FAIL() << "no error for an overflowing mosaic";
    } catch (const FormatError& e) {
        EXPECT_EQ(e.field(), "dims");
    }
    EXPECT_THROW(makeMosaic(open, {1ull << 15, 1, 1}), FormatError); // x beyond kMaxDimVoxels
    EXPECT_THROW(makeMosaic(open, {1ull << 14, 1ull << 14, 1ull << 14}),
                 FormatError); // beyond kMaxVolumeBytes
}

TEST(MosaicVolumeTest, ReopenedSourceThatChangesShapeThrows) {
    int opens = 0;
    auto mosaic = makeMosaic(
        [&] {
            return makeSynthetic(SynthKind::Checker, {8, 8, opens++ == 0 ? 4u : 5u}, 1);
        },
        {1, 1, 2});
    std::vector<std::byte> slab(4 * 64);
    mosaic->readSlices(4, slab);
    EXPECT_THROW(mosaic->readSlices(1, std::span(slab).first(64)), FormatError);
}

} // namespace
} // namespace bc::brickstore
