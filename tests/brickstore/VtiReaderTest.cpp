// openVti: appended raw, appended base64 and inline base64 arrays, uncompressed and in
// vtkZLibDataCompressor blocks, UInt32 and UInt64 headers, both byte orders, extents not at 0,
// the Scalars array among several, uneven slice reads; the shared scans written by VTK's
// vtkXMLImageDataWriter ingest to the same voxels; and every bad input it refuses: two
// pieces, three components, block sizes past the file, a truncated block, XML that is not well
// formed or too long.
#include "brickstore/Error.h"
#include "brickstore/Readers.h"
#include "tests/TestSupport.h"
#include "tests/brickstore/FormatTestSupport.h"
#include "tests/brickstore/RawTestSupport.h"

#include <gtest/gtest.h>

#include <cstring>
#include <limits>
#include <map>
#include <string>
#include <vector>

#include <zlib.h>

namespace bc::brickstore {
namespace {

using test::Bytes;
using test::expectFormatError;
using test::patternVoxels;
using test::readAllBytes;
using test::swapped;

constexpr std::array<std::uint64_t, 3> kDims{6, 5, 4};
constexpr std::uint64_t kVoxels = kDims[0] * kDims[1] * kDims[2];
const std::string kExtent = "0 5 0 4 0 3";

/// `v` as a `bytes`-byte header number in the given byte order.
Bytes number(std::uint64_t v, int bytes, bool big = false) {
    Bytes out(std::size_t(bytes), 0);
    for (int i = 0; i < bytes; ++i)
        out[std::size_t(big ? bytes - 1 - i : i)] = std::uint8_t(v >> (8 * i));
    return out;
}

void append(Bytes& to, const Bytes& more) {
    to.insert(to.end(), more.begin(), more.end());
}

std::string base64(const Bytes& data) {
    static const char* kAlphabet =
        "ABCDEFGHIJKLMNOPQRSTUVWXYZabcdefghijklmnopqrstuvwxyz0123456789+/";
    std::string out;
    for (std::size_t i = 0; i < data.size(); i += 3) {
        std::uint32_t bits = std::uint32_t(data[i]) << 16;
        if (i + 1 < data.size()) bits |= std::uint32_t(data[i + 1]) << 8;
        if (i + 2 < data.size()) bits |= data[i + 2];
        out += kAlphabet[bits >> 18];
        out += kAlphabet[(bits >> 12) & 63];
        out += i + 1 < data.size() ? kAlphabet[(bits >> 6) & 63] : '=';
        out += i + 2 < data.size() ? kAlphabet[bits & 63] : '=';
    }
    return out;
}

/// vtkZLibDataCompressor's layout: the header numbers, then each block's zlib stream.
struct Blocks {
    std::vector<std::uint64_t> header; ///< count, block size, last size, compressed sizes
    std::vector<Bytes> data;
};

Blocks compressBlocks(const Bytes& bytes, std::size_t blockBytes) {
    Blocks b;
    const std::size_t count = (bytes.size() + blockBytes - 1) / blockBytes;
    b.header = {count, blockBytes, bytes.size() % blockBytes};
    for (std::size_t i = 0; i < count; ++i) {
        const std::size_t n = std::min(blockBytes, bytes.size() - i * blockBytes);
        uLongf size = compressBound(uLong(n));
        Bytes out(size);
        EXPECT_EQ(compress2(out.data(), &size, bytes.data() + i * blockBytes, uLong(n), 6), Z_OK);
        out.resize(size);
        b.header.push_back(size);
        b.data.push_back(out);
    }
    return b;
}

Bytes headerBytes(const std::vector<std::uint64_t>& numbers, int bytes, bool big) {
    Bytes out;
    for (std::uint64_t v : numbers)
        append(out, number(v, bytes, big));
    return out;
}

Bytes serialize(const Blocks& b, int bytes, bool big = false) {
    Bytes out = headerBytes(b.header, bytes, big);
    for (const Bytes& d : b.data)
        append(out, d);
    return out;
}

std::string dataArray(const std::string& attrs, const std::string& text = "") {
    const std::string tag = "        <DataArray type=\"UInt16\" Name=\"v\" " + attrs;
    return text.empty() ? tag + "/>\n" : tag + ">" + text + "</DataArray>\n";
}

std::string pointData(const std::string& arrays, const std::string& scalars = "v") {
    return "      <PointData Scalars=\"" + scalars + "\">\n" + arrays + "      </PointData>\n";
}

const std::string kAppended = "format=\"appended\" offset=\"0\"";

std::string piece(const std::string& body, const std::string& extent = kExtent) {
    return "    <Piece Extent=\"" + extent + "\">\n" + body + "    </Piece>\n";
}

/// A .vti: the VTKFile and ImageData start tags with extra attributes, `pieces`, and the
/// appended data (raw) when `appended` is not empty.
Bytes vti(const std::string& fileAttrs, const std::string& pieces, const Bytes& appended = {},
          const std::string& imageAttrs = "Origin=\"1 2 3\" Spacing=\"0.5 0.75 2\"",
          const std::string& extent = kExtent) {
    std::string text = "<?xml version=\"1.0\"?>\n<VTKFile type=\"ImageData\" version=\"1.0\" " +
                       fileAttrs + ">\n  <ImageData WholeExtent=\"" + extent + "\" " + imageAttrs +
                       ">\n" + pieces + "  </ImageData>\n";
    Bytes out(text.begin(), text.end());
    if (!appended.empty()) {
        const std::string open = "  <AppendedData encoding=\"raw\">\n   _";
        append(out, Bytes(open.begin(), open.end()));
        append(out, appended);
        text = "\n  </AppendedData>\n";
    } else {
        text.clear();
    }
    text += "</VTKFile>\n";
    append(out, Bytes(text.begin(), text.end()));
    return out;
}

const std::string kLittle32 = "byte_order=\"LittleEndian\" header_type=\"UInt32\"";
const std::string kZlib32 = kLittle32 + " compressor=\"vtkZLibDataCompressor\"";

void write(const std::string& path, const Bytes& bytes) {
    test::writeFile(path, bytes.data(), bytes.size());
}

Bytes readVti(const std::string& path, const std::vector<std::uint64_t>& counts = {1}) {
    auto source = openVti(path);
    return readAllBytes(*source, counts);
}

TEST(VtiReaderTest, ReadsEveryHandWrittenLayoutExactly) {
    test::TempDir dir;
    const Bytes host = patternVoxels(VoxelType::U16, kVoxels);
    for (const bool big : {false, true}) {
        const Bytes disk = big ? swapped(host, VoxelType::U16) : host;
        for (const int hb : {4, 8}) {
            const std::string attrs = std::string("byte_order=\"") +
                                      (big ? "BigEndian" : "LittleEndian") +
                                      "\" header_type=\"UInt" + (hb == 4 ? "32" : "64") + "\"";
            const std::string zattrs = attrs + " compressor=\"vtkZLibDataCompressor\"";
            Bytes plain = number(disk.size(), hb, big);
            append(plain, disk);
            const Blocks z64 = compressBlocks(disk, 64);
            Bytes z64data;
            for (const Bytes& d : z64.data)
                append(z64data, d);
            const std::map<std::string, Bytes> files = {
                {"raw", vti(attrs, piece(pointData(dataArray(kAppended))), plain)},
                // 48-byte blocks: the last is partial; 80: the last is full (size 0).
                {"zlib48", vti(zattrs, piece(pointData(dataArray(kAppended))),
                               serialize(compressBlocks(disk, 48), hb, big))},
                {"zlib80", vti(zattrs, piece(pointData(dataArray(kAppended))),
                               serialize(compressBlocks(disk, 80), hb, big))},
                {"inline", vti(attrs, piece(pointData(dataArray("format=\"binary\"",
                                                                "\n          " + base64(plain) +
                                                                    "\n        "))))},
                {"inlinezlib",
                 vti(zattrs, piece(pointData(dataArray("format=\"binary\"",
                                                       base64(headerBytes(z64.header, hb, big)) +
                                                           base64(z64data)))))}};
            for (const auto& [name, bytes] : files) {
                const std::string path = dir.file(name + ".vti");
                write(path, bytes);
                auto source = openVti(path);
                EXPECT_EQ(source->info().dims, kDims) << name;
                EXPECT_EQ(readAllBytes(*source, {3}), host) << name << " big " << big << " " << hb;
            }
        }
    }
}

TEST(VtiReaderTest, ReadsAppendedBase64) {
    test::TempDir dir;
    const Bytes host = patternVoxels(VoxelType::U16, kVoxels);
    Bytes plain = number(host.size(), 4);
    append(plain, host);
    const Blocks blocks = compressBlocks(host, 56);
    Bytes compressed;
    for (const Bytes& d : blocks.data)
        append(compressed, d);
    const std::string cases[2][2] = {
        {kLittle32, base64(plain)},
        {kZlib32, base64(headerBytes(blocks.header, 4, false)) + base64(compressed)}};
    for (const auto& [attrs, text] : cases) {
        std::string xml = "<VTKFile type=\"ImageData\" " + attrs + ">\n<ImageData WholeExtent=\"" +
                          kExtent + "\">\n" + piece(pointData(dataArray(kAppended))) +
                          "</ImageData>\n<AppendedData encoding=\"base64\">\n _" + text +
                          "\n</AppendedData>\n</VTKFile>\n";
        test::writeFile(dir.file("b64.vti"), xml);
        EXPECT_EQ(readVti(dir.file("b64.vti"), {2}), host) << attrs;
    }
}

TEST(VtiReaderTest, InfoHasExtentOriginSpacingAndDescription) {
    test::TempDir dir;
    const Bytes host = patternVoxels(VoxelType::F32, kVoxels);
    Bytes plain = number(host.size(), 4);
    append(plain, host);
    const std::string extent = "2 7 -1 3 10 13";
    write(dir.file("vol.vti"),
          vti(kLittle32,
              piece("      <PointData>\n        <DataArray type=\"Float32\" Name=\"rho\" "
                    "format=\"appended\" offset=\"0\"/>\n      </PointData>\n",
                    extent),
              plain, "Origin=\"1 2 3\" Spacing=\"0.5 0.75 2\" Direction=\"1 0 0 0 1 0 0 0 1\"",
              extent));
    auto source = openVti(dir.file("vol.vti"));
    const VolumeInfo& info = source->info();
    EXPECT_EQ(info.dims, kDims);
    EXPECT_EQ(info.type, VoxelType::F32);
    EXPECT_EQ(info.spacingMm, (std::array<double, 3>{0.5, 0.75, 2}));
    EXPECT_EQ(info.originMm, (std::array<double, 3>{2, 1.25, 23}));
    EXPECT_NE(info.description.find("VTK image data vol.vti, f32, array 'rho'"), std::string::npos)
        << info.description;
    EXPECT_EQ(readAllBytes(*source), host);
}

TEST(VtiReaderTest, UnevenSliceCountsGiveTheSameBytes) {
    test::TempDir dir;
    const Bytes host = patternVoxels(VoxelType::I16, 7 * 3 * 11);
    write(dir.file("z.vti"),
          vti(kZlib32,
              piece("<PointData><DataArray type=\"Int16\" Name=\"v\" format=\"appended\" "
                    "offset=\"0\"/></PointData>\n",
                    "0 6 0 2 0 10"),
              serialize(compressBlocks(host, 40), 4), "", "0 6 0 2 0 10"));
    EXPECT_EQ(readVti(dir.file("z.vti"), {1, 5, 2}), host);
}

TEST(VtiReaderTest, ReadsTheScalarsArrayAmongSeveral) {
    test::TempDir dir;
    const Bytes host = patternVoxels(VoxelType::U8, kVoxels);
    Bytes payload = number(2 * kVoxels, 4);
    append(payload, patternVoxels(VoxelType::U16, kVoxels));
    const std::size_t offset = payload.size();
    append(payload, number(kVoxels, 4));
    append(payload, host);
    write(dir.file("two.vti"),
          vti(kLittle32,
              piece("<PointData Scalars=\"b\">\n<DataArray type=\"UInt16\" Name=\"a\" "
                    "format=\"appended\" offset=\"0\"/>\n<DataArray type=\"UInt8\" Name=\"b\" "
                    "format=\"appended\" offset=\"" +
                    std::to_string(offset) + "\"/>\n</PointData>\n<CellData/>\n"),
              payload));
    EXPECT_EQ(readVti(dir.file("two.vti")), host);
}

TEST(VtiReaderTest, TwoPiecesThrow) {
    test::TempDir dir;
    const std::string arrays = pointData(dataArray(kAppended));
    write(
        dir.file("two.vti"),
        vti(kLittle32, piece(arrays, "0 5 0 4 0 1") + piece(arrays, "0 5 0 4 2 3"), Bytes(300, 0)));
    expectFormatError([&] { openVti(dir.file("two.vti")); }, dir.file("two.vti"), "Piece");
}

TEST(VtiReaderTest, PieceSmallerThanTheWholeExtentThrows) {
    test::TempDir dir;
    write(dir.file("part.vti"),
          vti(kLittle32, piece(pointData(dataArray(kAppended)), "0 5 0 4 0 1"), Bytes(300, 0)));
    expectFormatError([&] { openVti(dir.file("part.vti")); }, dir.file("part.vti"), "Extent");
}

TEST(VtiReaderTest, ThreeComponentsThrow) {
    test::TempDir dir;
    Bytes plain = number(kVoxels * 6, 4);
    append(plain, patternVoxels(VoxelType::U16, kVoxels * 3));
    write(dir.file("rgb.vti"),
          vti(kLittle32, piece(pointData(dataArray("NumberOfComponents=\"3\" " + kAppended))),
              plain));
    expectFormatError([&] { openVti(dir.file("rgb.vti")); }, dir.file("rgb.vti"),
                      "NumberOfComponents");
}

TEST(VtiReaderTest, UnsupportedTypeCompressorOrDirectionThrows) {
    test::TempDir dir;
    const std::string path = dir.file("bad.vti");
    const Bytes some(400, 0);
    for (const std::string type : {"Float64", "Quaternion"}) {
        write(path, vti(kLittle32,
                        piece("<PointData><DataArray type=\"" + type +
                              "\" Name=\"v\" format=\"appended\" offset=\"0\"/></PointData>"),
                        some));
        expectFormatError([&] { openVti(path); }, path, "type");
    }
    write(path, vti(kLittle32 + " compressor=\"vtkLZ4DataCompressor\"",
                    piece(pointData(dataArray(kAppended))), some));
    expectFormatError([&] { openVti(path); }, path, "compressor");
    write(path, vti(kLittle32, piece(pointData(dataArray(kAppended))), some,
                    "Direction=\"0 1 0 1 0 0 0 0 1\""));
    expectFormatError([&] { openVti(path); }, path, "Direction");
    write(path, vti(kLittle32, piece(pointData(dataArray("format=\"ascii\"", "1 2 3"))), {}));
    expectFormatError([&] { openVti(path); }, path, "format");
}

TEST(VtiReaderTest, BlockHeaderWhoseSizesExceedTheFileThrows) {
    test::TempDir dir;
    const std::string path = dir.file("big.vti");
    const std::string arrays = pointData(dataArray(kAppended));
    const Blocks good = compressBlocks(patternVoxels(VoxelType::U16, kVoxels), 64);
    Blocks b = good;
    b.header[4] += 1000000; // one compressed size past the file
    write(path, vti(kZlib32, piece(arrays), serialize(b, 4)));
    std::string what = expectFormatError([&] { openVti(path); }, path, "block header");
    EXPECT_NE(what.find("add up to"), std::string::npos) << what;
    b = good;
    b.header[0] = 1ull << 40; // a header of 2^40 sizes
    b.header[1] = 1;
    write(path, vti("byte_order=\"LittleEndian\" header_type=\"UInt64\" "
                    "compressor=\"vtkZLibDataCompressor\"",
                    piece(arrays), serialize(b, 8)));
    expectFormatError([&] { openVti(path); }, path, "block header");
    b = good;
    b.header[2] = 10; // blocks that do not hold the WholeExtent's bytes
    write(path, vti(kZlib32, piece(arrays), serialize(b, 4)));
    expectFormatError([&] { openVti(path); }, path, "block header");
}

TEST(VtiReaderTest, TruncatedCompressedBlockThrows) {
    test::TempDir dir;
    const std::string path = dir.file("cut.vti");
    Blocks b = compressBlocks(patternVoxels(VoxelType::U16, kVoxels), 64);
    b.data[1].resize(b.data[1].size() / 2);
    b.header[4] = b.data[1].size();
    write(path, vti(kZlib32, piece(pointData(dataArray(kAppended))), serialize(b, 4)));
    auto source = openVti(path);
    const std::string what = expectFormatError([&] { readAllBytes(*source); }, path, "data");
    EXPECT_NE(what.find("zlib block 1"), std::string::npos) << what;
}

TEST(VtiReaderTest, CompressedSizeLongerThanItsStreamThrows) {
    test::TempDir dir;
    const std::string path = dir.file("long.vti");
    Blocks b = compressBlocks(patternVoxels(VoxelType::U16, kVoxels), 64);
    b.data[0].push_back(0);
    b.header[3] += 1;
    write(path, vti(kZlib32, piece(pointData(dataArray(kAppended))), serialize(b, 4)));
    expectFormatError([&] { readVti(path); }, path, "data");
}

TEST(VtiReaderTest, UncompressedDataOfTheWrongSizeThrows) {
    test::TempDir dir;
    const std::string path = dir.file("size.vti");
    const std::string arrays = pointData(dataArray(kAppended));
    Bytes plain = number(kVoxels * 2 - 2, 4);
    append(plain, patternVoxels(VoxelType::U16, kVoxels - 1));
    write(path, vti(kLittle32, piece(arrays), plain));
    expectFormatError([&] { openVti(path); }, path, "header");
    Bytes cut = number(kVoxels * 2, 4);
    append(cut, patternVoxels(VoxelType::U16, kVoxels / 2));
    std::string xml = "<VTKFile type=\"ImageData\" " + kLittle32 + "><ImageData WholeExtent=\"" +
                      kExtent + "\">" + piece(arrays) +
                      "</ImageData><AppendedData encoding=\"raw\">_";
    Bytes file(xml.begin(), xml.end());
    append(file, cut); // the file ends inside the array
    write(path, file);
    expectFormatError([&] { openVti(path); }, path, "size");
}

TEST(VtiReaderTest, XmlThatIsNotWellFormedThrows) {
    test::TempDir dir;
    const std::string path = dir.file("bad.vti");
    test::writeFile(path, "<VTKFile type=\"ImageData\" " + kLittle32 +
                              ">\n<ImageData WholeExtent=\"" + kExtent + "\">\n<Piece Extent=\"" +
                              kExtent + "\">\n</ImageData>\n</VTKFile>\n");
    const std::string what = expectFormatError([&] { openVti(path); }, path, "XML");
    EXPECT_NE(what.find("line 4"), std::string::npos) << what;
    test::writeFile(path, std::string("\x89HDF\r\n\x1a\n\0\0", 10));
    expectFormatError([&] { openVti(path); }, path, "XML");
    test::writeFile(path, "<!DOCTYPE VTKFile [<!ENTITY a \"aaaa\">]><VTKFile/>");
    expectFormatError([&] { openVti(path); }, path, "XML");
}

TEST(VtiReaderTest, XmlHeaderPastTheCapThrows) {
    test::TempDir dir;
    const std::string path = dir.file("long.vti");
    test::writeFile(path, "<VTKFile type=\"ImageData\" " + kLittle32 + ">\n<!-- " +
                              std::string((std::size_t(1) << 20) + 10, 'x') + " -->\n</VTKFile>\n");
    expectFormatError([&] { openVti(path); }, path, "header");
}

TEST(VtiReaderTest, NotImageDataOrNoMarkerThrows) {
    test::TempDir dir;
    const std::string path = dir.file("poly.vti");
    test::writeFile(path, "<VTKFile type=\"PolyData\" " + kLittle32 + "><PolyData/></VTKFile>");
    expectFormatError([&] { openVti(path); }, path, "type");
    std::string text = "<VTKFile type=\"ImageData\" " + kLittle32 + "><ImageData WholeExtent=\"" +
                       kExtent + "\">" + piece(pointData(dataArray(kAppended))) +
                       "</ImageData><AppendedData encoding=\"raw\">\n  xyz";
    test::writeFile(path, text);
    expectFormatError([&] { openVti(path); }, path, "AppendedData");
}

TEST(VtiReaderTest, InlineDataThatIsNotBase64Throws) {
    test::TempDir dir;
    const std::string path = dir.file("inline.vti");
    write(path, vti(kLittle32, piece(pointData(dataArray("format=\"binary\"", "QUJD*EFG")))));
    expectFormatError([&] { openVti(path); }, path, "DataArray");
    write(path,
          vti(kLittle32, piece(pointData(dataArray("format=\"binary\"", "QUJD<!-- c -->REVG")))));
    expectFormatError([&] { openVti(path); }, path, "DataArray");
}

TEST(VtiReaderTest, NanVoxelThrows) {
    test::TempDir dir;
    Bytes host = patternVoxels(VoxelType::F32, kVoxels);
    const float nan = std::numeric_limits<float>::quiet_NaN();
    std::memcpy(host.data() + 4 * 33, &nan, 4);
    Bytes plain = number(host.size(), 4);
    append(plain, host);
    write(dir.file("nan.vti"),
          vti(kLittle32,
              piece("<PointData><DataArray type=\"Float32\" Name=\"v\" format=\"appended\" "
                    "offset=\"0\"/></PointData>"),
              plain));
    expectFormatError([&] { readVti(dir.file("nan.vti")); }, dir.file("nan.vti"), "data");
}

/// Which vtkXMLImageDataWriter layouts each shared scan is written in (see
/// writers/write_vtk_formats.py): appended raw, appended base64 and inline, each with and
/// without zlib, UInt32 and UInt64 headers, both byte orders, spread so every scan is written
/// once or a few times and the suite stays quick.
std::vector<std::string> vtiVariants(const std::string& scan) {
    static const std::map<std::string, std::vector<std::string>> kVariants = {
        {"cthead", {"vti-raw-zlib"}},
        {"headsq", {"vti-raw", "vti-inline-u64", "vti-b64-be"}},
        {"frog", {"vti-raw"}},
        {"ct_avm", {"vti-b64-zlib"}},
        {"iguana", {"vti-inline-zlib"}},
        {"pancreas", {"vti-raw-u64-be"}},
        {"hydrogen", {"vti-b64", "vti-raw-zlib-u64-be-blk4096", "vti-inline-zlib-u64"}},
        {"gaffer", {"vti-b64-zlib-u64", "vti-inline-be", "vti-b64-u64"}}};
    auto it = kVariants.find(scan);
    return it == kVariants.end() ? std::vector<std::string>{"vti-raw"} : it->second;
}

class VtiRoundTrip : public ::testing::TestWithParam<test::SharedScan> {};

TEST_P(VtiRoundTrip, VtkWrittenScanIngestsToTheSameVoxels) {
    test::expectVtkWrittenScanRoundTrips(
        GetParam(), vtiVariants(GetParam().name), [](const std::string& v) { return v + ".vti"; },
        openVti, "VTK image data");
}

INSTANTIATE_TEST_SUITE_P(VtiSharedScans, VtiRoundTrip, ::testing::ValuesIn(test::sharedScans()),
                         [](const ::testing::TestParamInfo<test::SharedScan>& info) {
                             return info.param.name;
                         });

} // namespace
} // namespace bc::brickstore
