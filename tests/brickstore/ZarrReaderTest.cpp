// openZarr: every shared scan written by python3-zarr (writers/write_zarr.py: each compressor,
// both chunk key separators, both byte orders, edge chunks, sparse and deleted chunks, an
// OME-Zarr image's two levels) ingests to the same voxels; stores made here chunk by chunk
// check the reader's own paths (the slab, decoding straight into the caller's slices, fill
// values, OME-NGFF axes, units and transformations); and every bad input the reader refuses is a
// FormatError naming the file and the field.
#include "brickstore/Error.h"
#include "brickstore/Readers.h"
#include "tests/TestSupport.h"
#include "tests/brickstore/FormatTestSupport.h"
#include "tests/brickstore/RawTestSupport.h"

#include <gtest/gtest.h>

#include <algorithm>
#include <cmath>
#include <cstring>
#include <filesystem>
#include <functional>
#include <limits>
#include <map>
#include <optional>
#include <string>
#include <vector>

#include <zlib.h>
#include <zstd.h>

namespace bc::brickstore {
namespace {

namespace fs = std::filesystem;
using test::Bytes;
using test::expectFormatError;
using test::patternVoxels;
using test::readAllBytes;

// ---------------------------------------------------------------------------------------------
// Stores made here.

using Fields = std::map<std::string, std::string>;

/// A .zarray: a u16 array of 7 x 5 x 6 (z, y, x) in chunks of 4 x 2 x 4, uncompressed, but for
/// the fields (JSON values) in `changes`.
std::string zarray(const Fields& changes = {}) {
    Fields f = {{"zarr_format", "2"}, {"shape", "[7, 5, 6]"}, {"chunks", "[4, 2, 4]"},
                {"dtype", "\"<u2\""}, {"order", "\"C\""},     {"fill_value", "0"},
                {"filters", "null"},  {"compressor", "null"}};
    for (const auto& [key, value] : changes)
        f[key] = value;
    std::string text = "{";
    for (const auto& [key, value] : f)
        text += (text.size() > 1 ? ", \"" : "\"") + key + "\": " + value;
    return text + "}";
}

using Encode = std::function<Bytes(const Bytes&)>;

Bytes zlibEncode(const Bytes& data, int windowBits) {
    z_stream z{};
    EXPECT_EQ(deflateInit2(&z, 6, Z_DEFLATED, windowBits, 8, Z_DEFAULT_STRATEGY), Z_OK);
    Bytes out(deflateBound(&z, data.size()) + 64);
    z.next_in = const_cast<Bytef*>(data.data());
    z.avail_in = uInt(data.size());
    z.next_out = out.data();
    z.avail_out = uInt(out.size());
    EXPECT_EQ(deflate(&z, Z_FINISH), Z_STREAM_END);
    out.resize(z.total_out);
    deflateEnd(&z);
    return out;
}

const Encode kRaw = [](const Bytes& b) { return b; };
const Encode kZlib = [](const Bytes& b) { return zlibEncode(b, 15); };
const Encode kGzip = [](const Bytes& b) { return zlibEncode(b, 15 + 16); };
const Encode kZstd = [](const Bytes& b) {
    Bytes out(ZSTD_compressBound(b.size()));
    out.resize(ZSTD_compress(out.data(), out.size(), b.data(), b.size(), 3));
    return out;
};

/// How writeChunks lays a volume out.
struct ChunkLayout {
    std::array<std::uint64_t, 3> dims;  ///< x, y, z
    std::array<std::uint64_t, 3> chunk; ///< z, y, x, as .zarray lists them
    VoxelType type = VoxelType::U16;
    bool bigEndian = false;
    char separator = '.';
    int leadingAxes = 0; ///< extent-1 axes before z (OME's t and c)
};

/// Writes `host` (x fastest) into `folder` as Zarr chunks, each whole (edge chunks padded
/// with zeros), encoded by `encode`.
void writeChunks(const fs::path& folder, const Bytes& host, const ChunkLayout& l,
                 const Encode& encode) {
    const std::size_t vb = voxelBytes(l.type);
    const auto [cz, cy, cx] = l.chunk;
    std::string prefix;
    for (int i = 0; i < l.leadingAxes; ++i)
        prefix += std::string("0") + l.separator;
    for (std::uint64_t iz = 0; iz * cz < l.dims[2]; ++iz)
        for (std::uint64_t iy = 0; iy * cy < l.dims[1]; ++iy)
            for (std::uint64_t ix = 0; ix * cx < l.dims[0]; ++ix) {
                Bytes chunk(cz * cy * cx * vb, 0);
                for (std::uint64_t z = 0; z < cz; ++z)
                    for (std::uint64_t y = 0; y < cy; ++y)
                        for (std::uint64_t x = 0; x < cx; ++x) {
                            const std::uint64_t gx = ix * cx + x, gy = iy * cy + y,
                                                gz = iz * cz + z;
                            if (gx >= l.dims[0] || gy >= l.dims[1] || gz >= l.dims[2]) continue;
                            const std::uint8_t* src =
                                host.data() + ((gz * l.dims[1] + gy) * l.dims[0] + gx) * vb;
                            std::uint8_t* dst = chunk.data() + ((z * cy + y) * cx + x) * vb;
                            std::memcpy(dst, src, vb);
                            if (l.bigEndian) std::reverse(dst, dst + vb);
                        }
                const std::string key = prefix + std::to_string(iz) + l.separator +
                                        std::to_string(iy) + l.separator + std::to_string(ix);
                const fs::path file = folder / key;
                fs::create_directories(file.parent_path());
                const Bytes encoded = encode(chunk);
                test::writeFile(file.string(), encoded.data(), encoded.size());
            }
}

/// A 6 x 5 x 7 u16 array in `dir`/vol (the default .zarray), its voxels returned.
Bytes writeDefaultArray(const test::TempDir& dir, const Fields& changes = {},
                        const Encode& encode = kRaw) {
    fs::create_directories(dir.path() / "vol");
    test::writeFile(dir.file("vol/.zarray"), zarray(changes));
    const Bytes host = patternVoxels(VoxelType::U16, 6 * 5 * 7);
    writeChunks(dir.path() / "vol", host, {{6, 5, 7}, {4, 2, 4}}, encode);
    return host;
}

Bytes readZarr(const std::string& path, const std::vector<std::uint64_t>& counts = {1, 5, 2},
               std::uint32_t level = 0) {
    auto source = openZarr(path, level);
    return readAllBytes(*source, counts);
}

std::string contains(const std::string& what, const std::string& part) {
    EXPECT_NE(what.find(part), std::string::npos) << "'" << what << "' lacks '" << part << "'";
    return what;
}

// ---------------------------------------------------------------------------------------------
// The reader's paths.

TEST(ZarrReaderTest, ReadsEdgeChunksOfAnUncompressedArrayInUnevenSliceCounts) {
    test::TempDir dir;
    const Bytes host = writeDefaultArray(dir);
    auto source = openZarr(dir.file("vol"), 0);
    EXPECT_EQ(source->info().dims, (std::array<std::uint64_t, 3>{6, 5, 7}));
    EXPECT_EQ(source->info().type, VoxelType::U16);
    EXPECT_EQ(source->info().spacingMm, (std::array<double, 3>{1, 1, 1}));
    contains(source->info().description, "Zarr vol");
    EXPECT_EQ(readAllBytes(*source, {1, 5, 2}), host);
    EXPECT_EQ(readZarr(dir.file("vol"), {7}), host);
    EXPECT_EQ(readZarr(dir.file("vol"), {0, 3}), host);
}

TEST(ZarrReaderTest, ReadsEveryCodecInBothByteOrdersAndSeparators) {
    struct Case {
        std::string dtype, compressor;
        VoxelType type;
        Encode encode;
        char separator;
    };
    const std::vector<Case> cases = {
        {">i2", "{\"id\": \"zlib\", \"level\": 6}", VoxelType::I16, kZlib, '/'},
        {"<i2", "{\"id\": \"gzip\", \"level\": 6}", VoxelType::I16, kGzip, '.'},
        {">f4", "{\"id\": \"zstd\", \"level\": 3}", VoxelType::F32, kZstd, '/'},
        {"<f4", "{\"id\": \"gzip\", \"level\": 6}", VoxelType::F32, kGzip, '/'},
        {"|u1", "{\"id\": \"zstd\", \"level\": 3}", VoxelType::U8, kZstd, '.'},
        {">u2", "null", VoxelType::U16, kRaw, '.'}};
    for (const Case& c : cases) {
        test::TempDir dir;
        fs::create_directories(dir.path() / "vol");
        test::writeFile(dir.file("vol/.zarray"),
                        zarray({{"dtype", "\"" + c.dtype + "\""},
                                {"compressor", c.compressor},
                                {"dimension_separator", std::string("\"") + c.separator + "\""},
                                {"chunks", "[3, 4, 5]"}}));
        const Bytes host = patternVoxels(c.type, 6 * 5 * 7);
        writeChunks(dir.path() / "vol", host,
                    {{6, 5, 7}, {3, 4, 5}, c.type, c.dtype[0] == '>', c.separator}, c.encode);
        EXPECT_EQ(readZarr(dir.file("vol")), host) << c.dtype << " " << c.compressor;
    }
}

TEST(ZarrReaderTest, ChunksOfWholeSlicesDecodeStraightIntoTheSlicesOrTheSlab) {
    test::TempDir dir;
    fs::create_directories(dir.path() / "vol");
    test::writeFile(dir.file("vol/.zarray"),
                    zarray({{"dtype", "\"|u1\""}, {"chunks", "[3, 5, 6]"}, {"fill_value", "9"}}));
    Bytes host = patternVoxels(VoxelType::U8, 6 * 5 * 7);
    writeChunks(dir.path() / "vol", host, {{6, 5, 7}, {3, 5, 6}, VoxelType::U8}, kRaw);
    // {3}: whole rows, decoded into the caller's slices; the others go through the slab.
    for (const auto& counts : std::vector<std::vector<std::uint64_t>>{{3}, {1, 5, 2}, {2}, {7}})
        EXPECT_EQ(readZarr(dir.file("vol"), counts), host) << counts[0];
    fs::remove(dir.path() / "vol" / "1.0.0");
    std::fill(host.begin() + 3 * 30, host.begin() + 6 * 30, std::uint8_t{9});
    EXPECT_EQ(readZarr(dir.file("vol"), {3}), host);
    EXPECT_EQ(readZarr(dir.file("vol"), {2, 1}), host);
}

TEST(ZarrReaderTest, MissingChunkReadsAsTheFillValue) {
    test::TempDir dir;
    Bytes host = writeDefaultArray(dir, {{"fill_value", "777"}});
    fs::remove(dir.path() / "vol" / "1.2.1"); // z 4..6, y 4, x 4..5
    for (std::uint64_t z = 4; z < 7; ++z)
        for (std::uint64_t x = 4; x < 6; ++x) {
            const std::uint16_t fill = 777;
            std::memcpy(host.data() + ((z * 5 + 4) * 6 + x) * 2, &fill, 2);
        }
    EXPECT_EQ(readZarr(dir.file("vol")), host);
}

TEST(ZarrReaderTest, RowsDeeperThanTheSlabBoundAreDecodedAgainForEachRead) {
    // 4096 x 4096 u16 slices in rows of 9: 288 MiB a row, past the reader's 256 MiB slab. Two
    // chunks have files; the others read as the fill value.
    constexpr std::uint64_t kEdge = 4096, kDepth = 9, kChunk = 512;
    test::TempDir dir;
    fs::create_directories(dir.path() / "big");
    test::writeFile(dir.file("big/.zarray"), zarray({{"shape", "[9, 4096, 4096]"},
                                                     {"chunks", "[9, 512, 512]"},
                                                     {"fill_value", "7"},
                                                     {"compressor", "{\"id\": \"zstd\"}"}}));
    auto value = [](std::uint64_t x, std::uint64_t y, std::uint64_t z) {
        return std::uint16_t(x * 7 + y * 13 + z * 31 + 1);
    };
    const std::vector<std::pair<std::uint64_t, std::uint64_t>> present = {{0, 0}, {3, 5}};
    for (const auto& [cy, cx] : present) {
        std::vector<std::uint16_t> chunk(kDepth * kChunk * kChunk);
        for (std::uint64_t z = 0; z < kDepth; ++z)
            for (std::uint64_t y = 0; y < kChunk; ++y)
                for (std::uint64_t x = 0; x < kChunk; ++x)
                    chunk[(z * kChunk + y) * kChunk + x] =
                        value(cx * kChunk + x, cy * kChunk + y, z);
        const auto* first = reinterpret_cast<const std::uint8_t*>(chunk.data());
        const Bytes encoded = kZstd(Bytes(first, first + chunk.size() * 2));
        test::writeFile(dir.file("big/0." + std::to_string(cy) + "." + std::to_string(cx)),
                        encoded.data(), encoded.size());
    }
    auto isPresent = [&](std::uint64_t x, std::uint64_t y) {
        return std::find(present.begin(), present.end(), std::make_pair(y / kChunk, x / kChunk)) !=
               present.end();
    };
    auto source = openZarr(dir.file("big"), 0);
    std::vector<std::uint16_t> slices(5 * kEdge * kEdge);
    std::uint64_t wrong = 0;
    for (std::uint64_t z = 0, k = 0; z < kDepth; ++k) {
        const std::uint64_t n = std::min<std::uint64_t>(std::array{1, 3, 5}[k % 3], kDepth - z);
        source->readSlices(n, std::as_writable_bytes(std::span(slices).first(n * kEdge * kEdge)));
        for (std::uint64_t s = 0; s < n; ++s)
            for (std::uint64_t y = 0; y < kEdge; ++y)
                for (std::uint64_t x = 0; x < kEdge; ++x)
                    wrong += slices[(s * kEdge + y) * kEdge + x] !=
                             (isPresent(x, y) ? value(x, y, z + s) : 7);
        z += n;
    }
    EXPECT_EQ(wrong, 0u);
}

TEST(ZarrReaderTest, SymlinkedChunkInsideTheStoreIsRead) {
    test::TempDir dir;
    const Bytes host = writeDefaultArray(dir);
    fs::rename(dir.path() / "vol" / "0.0.0", dir.path() / "vol" / "real");
    fs::create_symlink("real", dir.path() / "vol" / "0.0.0");
    EXPECT_EQ(readZarr(dir.file("vol")), host);
}

/// An OME-Zarr image of two levels (arrays "s0", "s1", c z y x), written by hand.
void writeOmeImage(const test::TempDir& dir, const std::string& multiscale) {
    fs::create_directories(dir.path() / "img");
    test::writeFile(dir.file("img/.zgroup"), "{\"zarr_format\": 2}");
    test::writeFile(dir.file("img/.zattrs"), "{\"multiscales\": [" + multiscale + "]}");
    for (int level = 0; level < 2; ++level) {
        const std::uint64_t x = 6 >> level, y = 5 >> level, z = 7 >> level;
        const std::string name = "img/s" + std::to_string(level);
        fs::create_directories(dir.path() / name);
        const std::string shape =
            "[1, " + std::to_string(z) + ", " + std::to_string(y) + ", " + std::to_string(x) + "]";
        test::writeFile(dir.file(name + "/.zarray"),
                        zarray({{"shape", shape}, {"chunks", "[1, 4, 2, 4]"}}));
        writeChunks(dir.path() / name, patternVoxels(VoxelType::U16, x * y * z),
                    {{x, y, z}, {4, 2, 4}, VoxelType::U16, false, '.', 1}, kRaw);
    }
}

TEST(ZarrReaderTest, OmeLevelsTakeSpacingAndOriginInMillimetresFromTheirTransformations) {
    test::TempDir dir;
    writeOmeImage(dir, R"({"version": "0.4", "axes": [{"name": "c", "type": "channel"},
        {"name": "z", "type": "space", "unit": "millimeter"},
        {"name": "y", "type": "space", "unit": "micrometer"},
        {"name": "x", "type": "space", "unit": "nanometer"}],
      "datasets": [
        {"path": "s0", "coordinateTransformations": [{"type": "scale", "scale": [1, 2, 3, 4]},
            {"type": "translation", "translation": [0, 10, 20, 30]}]},
        {"path": "s1", "coordinateTransformations": [{"type": "scale", "scale": [1, 4, 6, 8]}]}],
      "coordinateTransformations": [{"type": "scale", "scale": [1, 0.5, 0.5, 0.5]}]})");
    auto level0 = openZarr(dir.file("img"), 0);
    EXPECT_EQ(level0->info().dims, (std::array<std::uint64_t, 3>{6, 5, 7}));
    EXPECT_DOUBLE_EQ(level0->info().spacingMm[0], 4 * 0.5 * 1e-6);
    EXPECT_DOUBLE_EQ(level0->info().spacingMm[1], 3 * 0.5 * 1e-3);
    EXPECT_DOUBLE_EQ(level0->info().spacingMm[2], 2 * 0.5);
    EXPECT_DOUBLE_EQ(level0->info().originMm[0], 30 * 0.5 * 1e-6);
    EXPECT_DOUBLE_EQ(level0->info().originMm[2], 10 * 0.5);
    contains(level0->info().description, "OME-Zarr img level 0 of 2");
    EXPECT_EQ(readAllBytes(*level0, {2}), patternVoxels(VoxelType::U16, 6 * 5 * 7));
    auto level1 = openZarr(dir.file("img"), 1);
    EXPECT_EQ(level1->info().dims, (std::array<std::uint64_t, 3>{3, 2, 3}));
    EXPECT_DOUBLE_EQ(level1->info().spacingMm[0], 8 * 0.5 * 1e-6);
    EXPECT_EQ(readAllBytes(*level1), patternVoxels(VoxelType::U16, 3 * 2 * 3));
}

TEST(ZarrReaderTest, OlderOmeMultiscalesWithoutUnitsOrAxesKeepTheirScale) {
    test::TempDir dir;
    writeOmeImage(dir, R"({"version": "0.3", "axes": ["c", "z", "y", "x"],
                           "datasets": [{"path": "s0"}, {"path": "s1"}]})");
    EXPECT_EQ(openZarr(dir.file("img"), 1)->info().spacingMm, (std::array<double, 3>{1, 1, 1}));
    test::TempDir old;
    writeOmeImage(old, R"({"version": "0.1", "datasets": [{"path": "s0"}, {"path": "s1"}]})");
    EXPECT_EQ(readZarr(old.file("img")), patternVoxels(VoxelType::U16, 6 * 5 * 7));
}

// ---------------------------------------------------------------------------------------------
// Bad inputs.

/// Writes the default array with `changes` and expects opening it to name .zarray and `field`.
std::string expectZarrayError(const Fields& changes, const std::string& field) {
    test::TempDir dir;
    writeDefaultArray(dir, changes);
    return expectFormatError([&] { openZarr(dir.file("vol"), 0); }, dir.file("vol/.zarray"), field);
}

TEST(ZarrReaderTest, TruncatedChunkThrowsNamingTheChunk) {
    for (const auto& [id, encode] : std::vector<std::pair<std::string, Encode>>{
             {"zlib", kZlib}, {"gzip", kGzip}, {"zstd", kZstd}}) {
        test::TempDir dir;
        writeDefaultArray(dir, {{"compressor", "{\"id\": \"" + id + "\"}"}}, encode);
        const fs::path chunk = dir.path() / "vol" / "1.1.0";
        Bytes bytes = test::readFile(chunk.string());
        bytes.resize(bytes.size() - 5);
        test::writeFile(chunk.string(), bytes.data(), bytes.size());
        contains(expectFormatError([&] { readZarr(dir.file("vol")); }, chunk.string(), "chunk"),
                 "vol/1.1.0");
    }
}

TEST(ZarrReaderTest, UncompressedChunkOfTheWrongSizeThrows) {
    test::TempDir dir;
    writeDefaultArray(dir);
    const std::string chunk = dir.file("vol/0.2.1");
    for (std::size_t size : {std::size_t(63), std::size_t(65)}) {
        const Bytes bytes(size, 1);
        test::writeFile(chunk, bytes.data(), bytes.size());
        contains(expectFormatError([&] { readZarr(dir.file("vol")); }, chunk, "chunk"),
                 "exactly 64");
    }
}

TEST(ZarrReaderTest, ChunkFileBiggerThanTheCodecsBoundThrowsBeforeDecoding) {
    test::TempDir dir;
    writeDefaultArray(dir, {{"compressor", "{\"id\": \"zlib\"}"}}, kZlib);
    const std::string chunk = dir.file("vol/1.0.0");
    const Bytes big(compressBound(64) + 1, 0x5a);
    test::writeFile(chunk, big.data(), big.size());
    contains(expectFormatError([&] { readZarr(dir.file("vol")); }, chunk, "chunk"), "more than");
}

TEST(ZarrReaderTest, CorruptOrOverlongCompressedChunkThrows) {
    test::TempDir dir;
    writeDefaultArray(dir, {{"compressor", "{\"id\": \"zstd\"}"}}, kZstd);
    const Bytes longer = kZstd(Bytes(65, 3)); // declares 65 bytes; a chunk holds 64
    test::writeFile(dir.file("vol/0.0.0"), longer.data(), longer.size());
    contains(expectFormatError([&] { readZarr(dir.file("vol")); }, dir.file("vol/0.0.0"), "chunk"),
             "declares 65");
    const Bytes garbage(20, 0x77);
    test::writeFile(dir.file("vol/0.0.0"), garbage.data(), garbage.size());
    expectFormatError([&] { readZarr(dir.file("vol")); }, dir.file("vol/0.0.0"), "chunk");
}

TEST(ZarrReaderTest, NanVoxelThrowsNamingTheChunk) {
    test::TempDir dir;
    fs::create_directories(dir.path() / "vol");
    test::writeFile(dir.file("vol/.zarray"), zarray({{"dtype", "\"<f4\""}}));
    Bytes host = patternVoxels(VoxelType::F32, 6 * 5 * 7);
    const float nan = std::numeric_limits<float>::quiet_NaN();
    std::memcpy(host.data() + ((5 * 5 + 3) * 6 + 2) * 4, &nan, 4);
    writeChunks(dir.path() / "vol", host, {{6, 5, 7}, {4, 2, 4}, VoxelType::F32}, kRaw);
    contains(expectFormatError([&] { readZarr(dir.file("vol")); }, dir.file("vol/1.1.0"), "chunk"),
             "voxel (2,3,5) is NaN");
}

TEST(ZarrReaderTest, WrongOrUnknownCompressorThrows) {
    contains(expectZarrayError({{"compressor", "{\"id\": \"lz4\"}"}}, "compressor"), "'lz4'");
    expectZarrayError({{"compressor", "{\"id\": \"blosc\", \"cname\": \"nope\"}"}}, "compressor");
    expectZarrayError({{"compressor", "\"zlib\""}}, "compressor");
}

TEST(ZarrReaderTest, TwoDimensionalArrayThrows) {
    contains(expectZarrayError({{"shape", "[5, 6]"}, {"chunks", "[5, 6]"}}, "shape"), "2 axes");
}

TEST(ZarrReaderTest, FortranOrderThrows) {
    expectZarrayError({{"order", "\"F\""}}, "order");
}

TEST(ZarrReaderTest, UnsupportedDtypeThrows) {
    for (const std::string dtype :
         {"\"<f8\"", "\"|i1\"", "\"<u4\"", "\"|b1\"", "\"u2\"", "[[\"a\", \"<u2\"]]"})
        expectZarrayError({{"dtype", dtype}}, "dtype");
}

TEST(ZarrReaderTest, ZeroOrOverflowingShapeThrows) {
    expectZarrayError({{"shape", "[7, 0, 6]"}}, "shape");
    expectZarrayError({{"shape", "[4294967296, 4294967296, 4294967296]"}}, "shape");
    expectZarrayError({{"shape", "[7, 5, 1e30]"}}, "shape");
    expectZarrayError({{"shape", "[7, -5, 6]"}}, "shape");
    contains(expectZarrayError({{"shape", "[2, 7, 5, 6]"}, {"chunks", "[1, 4, 2, 4]"}}, "shape"),
             "has 2 elements");
}

TEST(ZarrReaderTest, ZeroOrOverflowingChunksThrow) {
    expectZarrayError({{"chunks", "[4, 0, 4]"}}, "chunks");
    expectZarrayError({{"chunks", "[2097152, 2097152, 2097152]"}}, "chunks");
    expectZarrayError({{"chunks", "[18446744073709551615, 2, 4]"}}, "chunks");
    expectZarrayError({{"chunks", "[4, 2]"}}, "chunks");
}

TEST(ZarrReaderTest, NonFiniteOrOutOfRangeFillValueThrows) {
    expectZarrayError({{"dtype", "\"<f4\""}, {"fill_value", "\"NaN\""}}, "fill_value");
    expectZarrayError({{"dtype", "\"<f4\""}, {"fill_value", "\"-Infinity\""}}, "fill_value");
    expectZarrayError({{"dtype", "\"<f4\""}, {"fill_value", "1e300"}}, "fill_value");
    expectZarrayError({{"dtype", "\"|u1\""}, {"fill_value", "256"}}, "fill_value");
    expectZarrayError({{"dtype", "\"<i2\""}, {"fill_value", "1.5"}}, "fill_value");
}

TEST(ZarrReaderTest, FiltersFormatAndSeparatorOtherThanSupportedThrow) {
    expectZarrayError({{"filters", "[{\"id\": \"delta\", \"dtype\": \"<u2\"}]"}}, "filters");
    expectZarrayError({{"zarr_format", "3"}}, "zarr_format");
    expectZarrayError({{"dimension_separator", "\"-\""}}, "dimension_separator");
}

TEST(ZarrReaderTest, ZarrayThatIsNotJsonThrows) {
    test::TempDir dir;
    fs::create_directories(dir.path() / "vol");
    test::writeFile(dir.file("vol/.zarray"), "{\"zarr_format\": 2, \"shape\": [7, 5");
    expectFormatError([&] { openZarr(dir.file("vol"), 0); }, dir.file("vol/.zarray"), "json");
    test::writeFile(dir.file("vol/.zarray"), "[2, 3]");
    expectFormatError([&] { openZarr(dir.file("vol"), 0); }, dir.file("vol/.zarray"), "json");
    // Nested 400000 deep: neither parsing it nor freeing it may recurse that deep.
    test::writeFile(dir.file("vol/.zarray"), std::string(400000, '[') + std::string(400000, ']'));
    expectFormatError([&] { openZarr(dir.file("vol"), 0); }, dir.file("vol/.zarray"), "json");
    const std::string big(2 << 20, ' ');
    test::writeFile(dir.file("vol/.zarray"), zarray() + big);
    expectFormatError([&] { openZarr(dir.file("vol"), 0); }, dir.file("vol/.zarray"), "size");
}

TEST(ZarrReaderTest, FolderWithoutArrayOrMultiscalesThrows) {
    test::TempDir dir;
    fs::create_directories(dir.path() / "grp");
    test::writeFile(dir.file("grp/.zgroup"), "{\"zarr_format\": 2}");
    test::writeFile(dir.file("grp/.zattrs"), "{\"note\": 1}");
    expectFormatError([&] { openZarr(dir.file("grp"), 0); }, dir.file("grp"), ".zarray");
}

TEST(ZarrReaderTest, LevelPastTheLastThrowsSayingHowManyThereAre) {
    test::TempDir dir;
    writeOmeImage(dir, R"({"version": "0.4", "datasets": [{"path": "s0"}, {"path": "s1"}]})");
    contains(
        expectFormatError([&] { openZarr(dir.file("img"), 2); }, dir.file("img/.zattrs"), "level"),
        "has 2 levels");
    test::TempDir plain;
    writeDefaultArray(plain);
    expectFormatError([&] { openZarr(plain.file("vol"), 1); }, plain.file("vol/.zarray"), "level");
}

TEST(ZarrReaderTest, OmeAxesThatDoNotEndWithZyxOrLackALengthUnitThrow) {
    for (const std::string axes : {R"(["c", "y", "z", "x"])", R"(["z", "y", "x"])",
                                   R"([{"name": "c"}, {"name": "z"}, {"name": "y"},
                                       {"name": "x", "unit": "second"}])"}) {
        test::TempDir dir;
        writeOmeImage(dir, R"({"axes": )" + axes + R"(, "datasets": [{"path": "s0"}]})");
        expectFormatError([&] { openZarr(dir.file("img"), 0); }, dir.file("img/.zattrs"), "axes");
    }
}

TEST(ZarrReaderTest, ZeroScaleThrows) {
    test::TempDir dir;
    writeOmeImage(dir, R"({"datasets": [{"path": "s0", "coordinateTransformations":
                           [{"type": "scale", "scale": [1, 1, 0, 1]}]}]})");
    expectFormatError([&] { openZarr(dir.file("img"), 0); }, dir.file("img/.zattrs"),
                      "datasets[0].coordinateTransformations");
}

// A header that asks for far more work than the store's bytes back: refused when opened, in
// well under a second, naming the .zarray and the field (the ingest of each ran for minutes).

TEST(ZarrReaderTest, TerabyteShapeWithoutChunkFilesIsRefusedWhenOpened) {
    // In chunks of 64^3, over four million of them; in chunks of 32 MiB, 32768, but all of the
    // store's 8 kB would have to expand 2^27-fold.
    for (const auto& [chunks, field] : std::vector<std::pair<std::string, std::string>>{
             {"[64, 64, 64]", "chunks"}, {"[128, 512, 512]", "shape"}}) {
        test::TempDir dir;
        fs::create_directories(dir.path() / "vol");
        test::writeFile(dir.file("vol/.zarray"), zarray({{"shape", "[1048576, 1024, 1024]"},
                                                         {"chunks", chunks},
                                                         {"dtype", "\"|u1\""},
                                                         {"compressor", "{\"id\": \"zstd\"}"}}));
        test::writeFile(dir.file("vol/notes.txt"), std::string(8000, 'n'));
        const std::string what = test::expectRefusedAtOnce([&] { openZarr(dir.file("vol"), 0); },
                                                           dir.file("vol/.zarray"), field);
        contains(what, field == "chunks" ? "4194304 chunks" : "1024x1024x1048576 u8 (1.1 TB)");
        contains(what, field == "chunks" ? "--max-chunks" : "--max-expansion");
    }
}

TEST(ZarrReaderTest, ChunksOfOneVoxelAreRefusedByTheirCount) {
    test::TempDir dir;
    fs::create_directories(dir.path() / "vol");
    test::writeFile(
        dir.file("vol/.zarray"),
        zarray({{"shape", "[512, 512, 512]"}, {"chunks", "[1, 1, 1]"}, {"dtype", "\"|u1\""}}));
    ASSERT_LT(fs::file_size(dir.file("vol/.zarray")), 300u);
    const std::string what = test::expectRefusedAtOnce([&] { openZarr(dir.file("vol"), 0); },
                                                       dir.file("vol/.zarray"), "chunks");
    contains(what, "134217728 chunks");
    contains(what, "--max-chunks");
}

TEST(ZarrReaderTest, RaisedLimitsLetATinyStoreDeclareMore) {
    test::TempDir dir;
    fs::create_directories(dir.path() / "vol");
    test::writeFile(
        dir.file("vol/.zarray"),
        zarray({{"shape", "[512, 512, 512]"}, {"chunks", "[1, 1, 1]"}, {"dtype", "\"|u1\""}}));
    InputLimits limits;
    limits.maxChunks = 1ull << 27;
    {
        const test::InputLimitsGuard guard(limits);
        contains(test::expectRefusedAtOnce([&] { openZarr(dir.file("vol"), 0); },
                                           dir.file("vol/.zarray"), "shape"),
                 "512x512x512 u8 (134.2 MB) declared");
    }
    limits.maxExpansion = 1ull << 30;
    const test::InputLimitsGuard guard(limits);
    EXPECT_EQ(openZarr(dir.file("vol"), 0)->info().dims,
              (std::array<std::uint64_t, 3>{512, 512, 512}));
}

TEST(ZarrReaderTest, SparseStoreWhoseChunksHoldDataOpens) {
    // 1 GiB declared, four uncompressed 64^3 chunks present: 1/1024 of it, a sparse label map.
    test::TempDir dir;
    fs::create_directories(dir.path() / "vol");
    test::writeFile(dir.file("vol/.zarray"), zarray({{"shape", "[1024, 1024, 1024]"},
                                                     {"chunks", "[64, 64, 64]"},
                                                     {"dtype", "\"|u1\""},
                                                     {"fill_value", "3"}}));
    const Bytes chunk = patternVoxels(VoxelType::U8, 64 * 64 * 64);
    for (const std::string key : {"0.0.0", "0.0.1", "5.9.2", "15.15.15"})
        test::writeFile(dir.file("vol/" + key), chunk.data(), chunk.size());
    auto source = openZarr(dir.file("vol"), 0);
    std::vector<std::byte> slice(1024 * 1024);
    source->readSlices(1, slice);
    EXPECT_EQ(std::memcmp(slice.data(), chunk.data(), 64), 0);
    EXPECT_EQ(slice[200], std::byte{3}); // x 200: chunk 0.0.3, not stored
}

/// A store beside a folder it must not reach into.
class ZarrEscapeTest : public ::testing::Test {
  protected:
    void SetUp() override {
        writeDefaultArray(mOutside);
        writeOmeImage(mDir, R"({"datasets": [{"path": "s0"}]})");
    }
    void expectPathRejected(const std::string& path) {
        test::writeFile(mDir.file("img/.zattrs"),
                        R"({"multiscales": [{"datasets": [{"path": ")" + path + R"("}]}]})");
        expectFormatError([&] { openZarr(mDir.file("img"), 0); }, mDir.file("img/.zattrs"),
                          "datasets[0].path");
    }
    test::TempDir mOutside;
    test::TempDir mDir;
};

TEST_F(ZarrEscapeTest, MultiscalesPathWithDotDotThrows) {
    fs::copy(mOutside.path() / "vol", mDir.path() / "vol");
    expectPathRejected("../vol");
    expectPathRejected("s0/../../vol");
}

TEST_F(ZarrEscapeTest, AbsoluteMultiscalesPathThrows) {
    expectPathRejected(mOutside.file("vol"));
}

TEST_F(ZarrEscapeTest, MultiscalesPathSymlinkedOutsideThrows) {
    fs::create_directory_symlink(mOutside.path() / "vol", mDir.path() / "img" / "linked");
    expectPathRejected("linked");
}

TEST_F(ZarrEscapeTest, ChunkSymlinkedOutsideThrows) {
    const fs::path chunk = mDir.path() / "img" / "s0" / "0.1.0.1";
    fs::remove(chunk);
    fs::create_symlink(mOutside.path() / "vol" / "0.0.0", chunk);
    expectFormatError([&] { readZarr(mDir.file("img")); }, chunk.string(), "chunk");
}

TEST_F(ZarrEscapeTest, ZarraySymlinkedOutsideThrows) {
    const fs::path meta = mDir.path() / "img" / "s0" / ".zarray";
    fs::remove(meta);
    fs::create_symlink(mOutside.path() / "vol" / ".zarray", meta);
    expectFormatError([&] { openZarr(mDir.file("img"), 0); }, meta.string(), "path");
}

// ---------------------------------------------------------------------------------------------
// Round trips of the shared scans through python3-zarr.

/// What write_zarr.py writes of one scan: VARIANT strings (see the script). Every scan's
/// first variant is ingested; all of them are read against the raw voxels.
std::vector<std::string> variantsOf(const std::string& scan) {
    static const std::map<std::string, std::vector<std::string>> kVariants = {
        {"cthead",
         {"zlib:array:zlib:.:40,64,100:<", "blosc:array:blosc-lz4-shuffle:/:32,100,128:>"}},
        {"headsq", {"gzip:array:gzip:/:10,30,50:<:1234", "whole:array:none:.:93,64,64:<"}},
        {"frog",
         {"blosclz:array:blosc-blosclz-noshuffle:.:50,200,300:<",
          "zstd:array:zstd:.:16,470,500:<"}},
        {"ct_avm", {"sparse:array:zstd:.:64,64,64:<:0:sparse"}},
        {"iguana", {"none:array:none:/:50,100,70:<"}},
        {"pancreas", {"bitshuffle:array:blosc-zstd-bitshuffle:.:20,256,256:>"}},
        {"hydrogen", {"ome:ome:blosc-lz4-shuffle:.:16,32,20:>"}},
        {"gaffer", {"zstd:array:zstd:/:30,64,50:<", "gzip:array:gzip:.:112,100,111:>"}},
    };
    return kVariants.at(scan);
}

class ZarrRoundTripTest : public ::testing::TestWithParam<test::SharedScan> {
  protected:
    /// Reads the store at `path` (level `level`) slice by slice and compares it with `raw`.
    void expectSameAsRaw(const std::string& path, const Bytes& raw, std::uint32_t level = 0) {
        EXPECT_EQ(readZarr(path, {7, 1, 16}, level), raw) << path;
    }
    test::TempDir mDir;
};

std::string dimsArg(const VolumeInfo& info) {
    return std::to_string(info.dims[0]) + "," + std::to_string(info.dims[1]) + "," +
           std::to_string(info.dims[2]);
}

TEST_P(ZarrRoundTripTest, WrittenByPythonZarrIngestsToTheSameVoxels) {
    if (!test::pythonHas("zarr, numcodecs, numpy")) return;
    const test::SharedScan& s = GetParam();
    if (!test::haveData(s.file)) return test::missingData(s.file);
    const std::string raw = mDir.file(s.name + ".raw");
    const VolumeInfo info = test::dumpRaw(test::sharedSpec(s), raw);
    const std::vector<std::string> variants = variantsOf(s.name);
    std::vector<std::string> args = {raw, dimsArg(info), s.dataType, mDir.path().string()};
    args.insert(args.end(), variants.begin(), variants.end());
    ASSERT_TRUE(test::runPython("brickstore/writers/write_zarr.py", args));
    const Bytes voxels = test::readFile(raw);
    for (const std::string& v : variants)
        expectSameAsRaw(mDir.file(v.substr(0, v.find(':'))), voxels);
    SourceSpec written;
    written.input = mDir.file(variants[0].substr(0, variants[0].find(':')));
    test::expectIngestsToSameVoxels(test::sharedSpec(s), written, s.name);
}

INSTANTIATE_TEST_SUITE_P(ZarrScans, ZarrRoundTripTest, ::testing::ValuesIn(test::sharedScans()),
                         [](const ::testing::TestParamInfo<test::SharedScan>& info) {
                             return info.param.name;
                         });

/// The scan at `name`, dumped raw and written by write_zarr.py as `variant`.
struct WrittenScan {
    VolumeInfo info;
    Bytes voxels;
};

std::optional<WrittenScan> writeScan(const test::TempDir& dir, const std::string& name,
                                     const std::string& variant) {
    for (const test::SharedScan& s : test::sharedScans()) {
        if (s.name != name) continue;
        if (!test::haveData(s.file)) {
            test::missingData(s.file);
            return std::nullopt;
        }
        const std::string raw = dir.file(s.name + ".raw");
        WrittenScan out{test::dumpRaw(test::sharedSpec(s), raw), {}};
        if (!test::runPython("brickstore/writers/write_zarr.py",
                             {raw, dimsArg(out.info), s.dataType, dir.path().string(), variant}))
            return std::nullopt;
        out.voxels = test::readFile(raw);
        return out;
    }
    ADD_FAILURE() << "no shared scan " << name;
    return std::nullopt;
}

TEST(ZarrReaderTest, OmeZarrLevelsOfHydrogenMatchTheVolumeAndItsStridedCopy) {
    if (!test::pythonHas("zarr, numcodecs, numpy")) return;
    test::TempDir dir;
    const auto scan = writeScan(dir, "hydrogen", "ome:ome:zstd:/:16,20,64:<");
    if (!scan) return;
    auto level0 = openZarr(dir.file("ome"), 0);
    EXPECT_EQ(level0->info().dims, scan->info.dims);
    EXPECT_EQ(level0->info().type, VoxelType::F32);
    // write_zarr.py's OME_SCALE_UM: z 2, y 0.5, x 0.25 micrometres at level 0, twice at level 1.
    const std::array<double, 3> spacing0{0.25e-3, 0.5e-3, 2e-3};
    for (int a = 0; a < 3; ++a) {
        EXPECT_DOUBLE_EQ(level0->info().spacingMm[a], spacing0[a]);
        EXPECT_DOUBLE_EQ(openZarr(dir.file("ome"), 1)->info().spacingMm[a], 2 * spacing0[a]);
    }
    SourceSpec zarr0, zarr1, strided;
    zarr0.input = zarr1.input = dir.file("ome");
    zarr1.level = 1;
    strided.input = dir.file("ome.level1.raw");
    strided.dims = {(scan->info.dims[0] + 1) / 2, (scan->info.dims[1] + 1) / 2,
                    (scan->info.dims[2] + 1) / 2};
    strided.type = VoxelType::F32;
    SourceSpec original;
    original.input = dir.file("hydrogen.raw");
    original.dims = scan->info.dims;
    original.type = VoxelType::F32;
    test::expectIngestsToSameVoxels(original, zarr0, "hydrogen level 0");
    test::expectIngestsToSameVoxels(strided, zarr1, "hydrogen level 1");
}

TEST(ZarrReaderTest, DeletedChunkOfAScanReadsAsTheFillValueAndTheRestAsBefore) {
    if (!test::pythonHas("zarr, numcodecs, numpy")) return;
    test::TempDir dir;
    const auto scan = writeScan(dir, "headsq", "cut:array:blosc-zstd-shuffle:/:10,30,50:<:4321");
    if (!scan) return;
    fs::remove(dir.path() / "cut" / "2" / "1" / "0"); // z 20..29, y 30..59, x 0..49
    Bytes expected = scan->voxels;
    const std::uint16_t fill = 4321;
    for (std::uint64_t z = 20; z < 30; ++z)
        for (std::uint64_t y = 30; y < 60; ++y)
            for (std::uint64_t x = 0; x < 50; ++x)
                std::memcpy(expected.data() + ((z * 64 + y) * 64 + x) * 2, &fill, 2);
    EXPECT_EQ(readZarr(dir.file("cut")), expected);
}

TEST(ZarrReaderTest, TruncatedBloscChunkOfAScanThrowsNamingTheChunk) {
    if (!test::pythonHas("zarr, numcodecs, numpy")) return;
    test::TempDir dir;
    if (!writeScan(dir, "headsq", "b:array:blosc-lz4-shuffle:.:10,30,50:<")) return;
    const std::string chunk = dir.file("b/3.0.1");
    Bytes bytes = test::readFile(chunk);
    bytes.resize(bytes.size() - 1);
    test::writeFile(chunk, bytes.data(), bytes.size());
    contains(expectFormatError([&] { readZarr(dir.file("b")); }, chunk, "chunk"), "blosc");
}

} // namespace
} // namespace bc::brickstore
