// openRaw: every stored type in both byte orders, zstd input (one frame, several, no declared
// size), slice-by-slice reads, every bad layout or file it refuses, and a real scan.
#include "brickstore/Error.h"
#include "brickstore/Readers.h"
#include "tests/TestSupport.h"
#include "tests/brickstore/RawTestSupport.h"

#include <gtest/gtest.h>

#include <cmath>
#include <cstddef>
#include <cstdint>
#include <cstring>
#include <limits>
#include <numeric>
#include <string>
#include <vector>

#include <zstd.h>

namespace bc::brickstore {
namespace {

using test::Bytes;
using test::expectFormatError;
using test::patternVoxels;
using test::readAllBytes;
using test::swapped;

constexpr std::array<std::uint64_t, 3> kDims{5, 4, 6};

Bytes zstdCompress(const Bytes& data) {
    Bytes out(ZSTD_compressBound(data.size()));
    std::size_t n = ZSTD_compress(out.data(), out.size(), data.data(), data.size(), 3);
    EXPECT_FALSE(ZSTD_isError(n));
    out.resize(n);
    return out;
}

/// One zstd frame that does not declare its content size (as a pipe into `zstd` writes).
Bytes zstdCompressUnsized(const Bytes& data) {
    ZSTD_CCtx* cctx = ZSTD_createCCtx();
    ZSTD_CCtx_setParameter(cctx, ZSTD_c_contentSizeFlag, 0);
    Bytes out(ZSTD_compressBound(data.size()) + 64);
    ZSTD_inBuffer in{data.data(), data.size(), 0};
    ZSTD_outBuffer dst{out.data(), out.size(), 0};
    std::size_t left = ZSTD_compressStream2(cctx, &dst, &in, ZSTD_e_end);
    EXPECT_EQ(left, 0u);
    ZSTD_freeCCtx(cctx);
    out.resize(dst.pos);
    return out;
}

RawLayout layoutOf(VoxelType type, Endian endian, std::array<std::uint64_t, 3> dims = kDims) {
    RawLayout layout;
    layout.dims = dims;
    layout.type = type;
    layout.endian = endian;
    layout.spacingMm = {0.5, 0.75, 2.0};
    return layout;
}

Bytes readRaw(const std::string& path, const RawLayout& layout,
              const std::vector<std::uint64_t>& counts = {1}) {
    auto source = openRaw(path, layout);
    return readAllBytes(*source, counts);
}

class RawTypeTest : public ::testing::TestWithParam<std::tuple<VoxelType, Endian>> {};

TEST_P(RawTypeTest, ReadsVoxelsExactlyInHostByteOrder) {
    auto [type, endian] = GetParam();
    test::TempDir dir;
    Bytes host = patternVoxels(type, kDims[0] * kDims[1] * kDims[2]);
    Bytes file = endian == Endian::Big ? swapped(host, type) : host;
    test::writeFile(dir.file("vol.raw"), file.data(), file.size());
    auto source = openRaw(dir.file("vol.raw"), layoutOf(type, endian));
    EXPECT_EQ(source->info().dims, kDims);
    EXPECT_EQ(source->info().type, type);
    EXPECT_EQ(source->info().spacingMm, (std::array<double, 3>{0.5, 0.75, 2.0}));
    EXPECT_EQ(readAllBytes(*source), host);
}

TEST_P(RawTypeTest, ReadsZstdCompressedVoxelsExactly) {
    auto [type, endian] = GetParam();
    test::TempDir dir;
    Bytes host = patternVoxels(type, kDims[0] * kDims[1] * kDims[2]);
    Bytes packed = zstdCompress(endian == Endian::Big ? swapped(host, type) : host);
    test::writeFile(dir.file("vol.raw.zst"), packed.data(), packed.size());
    EXPECT_EQ(readRaw(dir.file("vol.raw.zst"), layoutOf(type, endian)), host);
}

INSTANTIATE_TEST_SUITE_P(AllTypes, RawTypeTest,
                         ::testing::Combine(::testing::Values(VoxelType::U8, VoxelType::U16,
                                                              VoxelType::I16, VoxelType::F32),
                                            ::testing::Values(Endian::Little, Endian::Big)));

TEST(RawReaderTest, SliceCountsDoNotChangeTheBytes) {
    test::TempDir dir;
    Bytes host = patternVoxels(VoxelType::U16, kDims[0] * kDims[1] * kDims[2]);
    test::writeFile(dir.file("vol.raw"), host.data(), host.size());
    Bytes packed = zstdCompress(host);
    test::writeFile(dir.file("vol.raw.zst"), packed.data(), packed.size());
    RawLayout layout = layoutOf(VoxelType::U16, Endian::Little);
    for (const std::string name : {"vol.raw", "vol.raw.zst"}) {
        EXPECT_EQ(readRaw(dir.file(name), layout, {6}), host) << name;
        EXPECT_EQ(readRaw(dir.file(name), layout, {1}), host) << name;
        EXPECT_EQ(readRaw(dir.file(name), layout, {2, 1, 3}), host) << name;
        EXPECT_EQ(readRaw(dir.file(name), layout, {0, 4, 2}), host) << name;
    }
}

TEST(RawReaderTest, ReadsVolumeLargerThanOneReadChunk) {
    test::TempDir dir;
    const std::array<std::uint64_t, 3> dims{128, 128, 40}; // 2.5 MiB of f32
    Bytes host = patternVoxels(VoxelType::F32, dims[0] * dims[1] * dims[2]);
    Bytes big = swapped(host, VoxelType::F32);
    test::writeFile(dir.file("big.raw"), big.data(), big.size());
    Bytes packed = zstdCompress(big);
    test::writeFile(dir.file("big.raw.zst"), packed.data(), packed.size());
    EXPECT_EQ(readRaw(dir.file("big.raw"), layoutOf(VoxelType::F32, Endian::Big, dims), {40}),
              host);
    EXPECT_EQ(
        readRaw(dir.file("big.raw.zst"), layoutOf(VoxelType::F32, Endian::Big, dims), {7, 33}),
        host);
}

TEST(RawReaderTest, ReadsZstdFrameWithoutDeclaredSize) {
    test::TempDir dir;
    Bytes host = patternVoxels(VoxelType::I16, kDims[0] * kDims[1] * kDims[2]);
    Bytes packed = zstdCompressUnsized(host);
    ASSERT_EQ(ZSTD_getFrameContentSize(packed.data(), packed.size()), ZSTD_CONTENTSIZE_UNKNOWN);
    test::writeFile(dir.file("vol.zst"), packed.data(), packed.size());
    EXPECT_EQ(readRaw(dir.file("vol.zst"), layoutOf(VoxelType::I16, Endian::Little), {4}), host);
}

TEST(RawReaderTest, ReadsZstdFileOfSeveralFrames) {
    test::TempDir dir;
    Bytes host = patternVoxels(VoxelType::U8, kDims[0] * kDims[1] * kDims[2]);
    Bytes half1(host.begin(), host.begin() + 50), half2(host.begin() + 50, host.end());
    Bytes packed = zstdCompress(half1), second = zstdCompress(half2);
    packed.insert(packed.end(), second.begin(), second.end());
    test::writeFile(dir.file("vol.zst"), packed.data(), packed.size());
    EXPECT_EQ(readRaw(dir.file("vol.zst"), layoutOf(VoxelType::U8, Endian::Little), {5}), host);
}

TEST(RawReaderTest, ReadsRealScanVoxelsAsStoredInTheFile) {
    const std::string name = "vtk_headsq_quarter_64x64x93_uint16.raw";
    if (!test::haveData(name)) return test::missingData(name);
    Bytes file = test::readFile(test::dataPath(name));
    ASSERT_EQ(file.size(), 64u * 64 * 93 * 2);
    RawLayout layout;
    layout.dims = {64, 64, 93};
    layout.type = VoxelType::U16;
    layout.spacingMm = {3.2, 3.2, 1.5};
    Bytes voxels = readRaw(test::dataPath(name), layout, {10, 3});
    ASSERT_EQ(voxels, file);
    auto voxelAt = [&](const Bytes& b, std::uint64_t x, std::uint64_t y, std::uint64_t z) {
        std::size_t i = 2 * (x + 64 * (y + 64 * z));
        return static_cast<std::uint16_t>(b[i] | (b[i + 1] << 8));
    };
    for (auto [x, y, z] :
         {std::array<std::uint64_t, 3>{0, 0, 0}, {32, 32, 46}, {63, 63, 92}, {10, 50, 20}})
        EXPECT_EQ(voxelAt(voxels, x, y, z), voxelAt(file, x, y, z));
    std::uint64_t sum = 0;
    for (std::size_t i = 0; i < voxels.size(); i += 2)
        sum += voxels[i] | (voxels[i + 1] << 8);
    EXPECT_GT(sum, 0u); // a head, not an empty box
}

TEST(RawReaderTest, ZeroDimsThrow) {
    test::TempDir dir;
    test::writeFile(dir.file("zero.raw"), "");
    expectFormatError(
        [&] {
            openRaw(dir.file("zero.raw"), layoutOf(VoxelType::U8, Endian::Little, {4, 0, 4}));
        },
        dir.file("zero.raw"), "dims");
}

TEST(RawReaderTest, DimsWhoseByteSizeOverflowsThrow) {
    test::TempDir dir;
    test::writeFile(dir.file("huge.raw"), "x");
    const std::uint64_t d = 1ull << 22; // 2^66 voxels
    expectFormatError(
        [&] {
            openRaw(dir.file("huge.raw"), layoutOf(VoxelType::U16, Endian::Little, {d, d, d}));
        },
        dir.file("huge.raw"), "dims");
}

TEST(RawReaderTest, FileSmallerThanDimsPromiseThrows) {
    test::TempDir dir;
    Bytes host = patternVoxels(VoxelType::U16, kDims[0] * kDims[1] * kDims[2] - 1);
    test::writeFile(dir.file("short.raw"), host.data(), host.size());
    expectFormatError(
        [&] { openRaw(dir.file("short.raw"), layoutOf(VoxelType::U16, Endian::Little)); },
        dir.file("short.raw"), "size");
}

TEST(RawReaderTest, FileLargerThanDimsPromiseThrows) {
    test::TempDir dir;
    Bytes host = patternVoxels(VoxelType::U8, kDims[0] * kDims[1] * kDims[2] + 1);
    test::writeFile(dir.file("long.raw"), host.data(), host.size());
    expectFormatError(
        [&] { openRaw(dir.file("long.raw"), layoutOf(VoxelType::U8, Endian::Little)); },
        dir.file("long.raw"), "size");
}

TEST(RawReaderTest, ZstdFrameDeclaringMoreBytesThrowsOnOpen) {
    test::TempDir dir;
    Bytes packed = zstdCompress(patternVoxels(VoxelType::U8, kDims[0] * kDims[1] * kDims[2] + 7));
    test::writeFile(dir.file("more.zst"), packed.data(), packed.size());
    expectFormatError(
        [&] { openRaw(dir.file("more.zst"), layoutOf(VoxelType::U8, Endian::Little)); },
        dir.file("more.zst"), "size");
}

TEST(RawReaderTest, ZstdStreamHoldingMoreBytesThrowsAtTheLastSlice) {
    test::TempDir dir;
    Bytes packed =
        zstdCompressUnsized(patternVoxels(VoxelType::U8, kDims[0] * kDims[1] * kDims[2] + 1));
    test::writeFile(dir.file("more.zst"), packed.data(), packed.size());
    auto source = openRaw(dir.file("more.zst"), layoutOf(VoxelType::U8, Endian::Little));
    expectFormatError([&] { readAllBytes(*source); }, dir.file("more.zst"), "size");
}

TEST(RawReaderTest, ZstdStreamHoldingFewerBytesThrows) {
    test::TempDir dir;
    Bytes packed = zstdCompress(patternVoxels(VoxelType::U16, kDims[0] * kDims[1] * kDims[2] - 3));
    test::writeFile(dir.file("less.zst"), packed.data(), packed.size());
    expectFormatError(
        [&] { readRaw(dir.file("less.zst"), layoutOf(VoxelType::U16, Endian::Little)); },
        dir.file("less.zst"), "size");
}

TEST(RawReaderTest, TruncatedZstdStreamThrows) {
    test::TempDir dir;
    Bytes packed = zstdCompress(patternVoxels(VoxelType::F32, kDims[0] * kDims[1] * kDims[2]));
    packed.resize(packed.size() - 5);
    test::writeFile(dir.file("cut.zst"), packed.data(), packed.size());
    expectFormatError(
        [&] { readRaw(dir.file("cut.zst"), layoutOf(VoxelType::F32, Endian::Little)); },
        dir.file("cut.zst"), "data");
}

TEST(RawReaderTest, FileThatIsNotZstdThrows) {
    test::TempDir dir;
    test::writeFile(dir.file("plain.zst"), "this is not zstd at all, just text");
    expectFormatError(
        [&] { readRaw(dir.file("plain.zst"), layoutOf(VoxelType::U8, Endian::Little)); },
        dir.file("plain.zst"), "data");
}

TEST(RawReaderTest, BadSpacingThrows) {
    test::TempDir dir;
    Bytes host = patternVoxels(VoxelType::U8, kDims[0] * kDims[1] * kDims[2]);
    test::writeFile(dir.file("vol.raw"), host.data(), host.size());
    for (double bad : {std::numeric_limits<double>::quiet_NaN(), 0.0, -1.0}) {
        RawLayout layout = layoutOf(VoxelType::U8, Endian::Little);
        layout.spacingMm[1] = bad;
        expectFormatError([&] { openRaw(dir.file("vol.raw"), layout); }, dir.file("vol.raw"),
                          "spacing");
    }
}

TEST(RawReaderTest, NanVoxelThrowsNamingItsPosition) {
    test::TempDir dir;
    const std::array<std::uint64_t, 3> dims{128, 128, 20}; // NaN lies past the first read chunk
    Bytes host = patternVoxels(VoxelType::F32, dims[0] * dims[1] * dims[2]);
    float nan = std::numeric_limits<float>::quiet_NaN();
    std::memcpy(host.data() + 4 * (5 + 128 * (7 + 128 * 18)), &nan, 4);
    test::writeFile(dir.file("nan.raw"), host.data(), host.size());
    auto source = openRaw(dir.file("nan.raw"), layoutOf(VoxelType::F32, Endian::Little, dims));
    try {
        readAllBytes(*source, {20});
        FAIL() << "NaN voxel accepted";
    } catch (const FormatError& e) {
        EXPECT_EQ(e.field(), "data");
        EXPECT_NE(std::string(e.what()).find("nan.raw"), std::string::npos) << e.what();
        EXPECT_NE(std::string(e.what()).find("(5,7,18)"), std::string::npos) << e.what();
    }
}

TEST(RawReaderTest, InfiniteBigEndianVoxelThrows) {
    test::TempDir dir;
    Bytes host = patternVoxels(VoxelType::F32, kDims[0] * kDims[1] * kDims[2]);
    float inf = -std::numeric_limits<float>::infinity();
    std::memcpy(host.data() + 4 * (1 + 5 * (2 + 4 * 3)), &inf, 4);
    Bytes big = swapped(host, VoxelType::F32);
    test::writeFile(dir.file("inf.raw"), big.data(), big.size());
    auto source = openRaw(dir.file("inf.raw"), layoutOf(VoxelType::F32, Endian::Big));
    expectFormatError([&] { readAllBytes(*source); }, dir.file("inf.raw"), "data");
}

TEST(RawReaderTest, MissingFileThrows) {
    test::TempDir dir;
    expectFormatError(
        [&] { openRaw(dir.file("absent.raw"), layoutOf(VoxelType::U8, Endian::Little)); },
        dir.file("absent.raw"), "path");
}

} // namespace
} // namespace bc::brickstore
