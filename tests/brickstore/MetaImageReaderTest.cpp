// openMetaImage: .mha (LOCAL data) and .mhd (a data file beside it), raw and zlib, every stored
// type in both byte orders, spacing and origin, HeaderSize, uneven slice reads; the shared
// scans written by VTK's vtkMetaImageWriter ingest to the same voxels; and every bad input it
// refuses: too little data, a data file outside the header's folder, NDims 2, an unknown
// ElementType, a CompressedDataSize that lies, a zlib payload cut short.
#include "brickstore/Error.h"
#include "brickstore/Readers.h"
#include "tests/TestSupport.h"
#include "tests/brickstore/FormatTestSupport.h"
#include "tests/brickstore/RawTestSupport.h"

#include <gtest/gtest.h>

#include <cmath>
#include <cstring>
#include <filesystem>
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

/// One zlib stream, as MetaIO's compress2 writes it.
Bytes zlib(const Bytes& data) {
    uLongf size = compressBound(uLong(data.size()));
    Bytes out(size);
    EXPECT_EQ(compress2(out.data(), &size, data.data(), uLong(data.size()), 6), Z_OK);
    out.resize(size);
    return out;
}

std::string header(const std::string& type, const std::string& extra = "",
                   const std::string& dims = "6 5 4") {
    return "ObjectType = Image\nNDims = 3\nDimSize = " + dims + "\nElementType = " + type +
           "\nBinaryData = True\n" + extra;
}

/// An .mha: the header, ElementDataFile = LOCAL, then the data.
void writeMha(const std::string& path, const std::string& head, const Bytes& data) {
    std::string text = head + "ElementDataFile = LOCAL\n";
    Bytes file(text.begin(), text.end());
    file.insert(file.end(), data.begin(), data.end());
    test::writeFile(path, file.data(), file.size());
}

/// An .mhd naming `dataName` in its folder, and that file holding `data`.
void writeMhd(const std::string& path, const std::string& head, const std::string& dataName,
              const Bytes& data) {
    test::writeFile(path, head + "ElementDataFile = " + dataName + "\n");
    const std::string dataPath = (std::filesystem::path(path).parent_path() / dataName).string();
    test::writeFile(dataPath, data.data(), data.size());
}

struct TypeCase {
    std::string name;
    VoxelType type;
    bool msb;
};

class MetaImageTypeTest : public ::testing::TestWithParam<TypeCase> {};

TEST_P(MetaImageTypeTest, ReadsLocalAndDetachedRawAndZlibExactly) {
    const TypeCase& c = GetParam();
    test::TempDir dir;
    const Bytes host = patternVoxels(c.type, kVoxels);
    const Bytes disk = c.msb ? swapped(host, c.type) : host;
    const std::string order = std::string("BinaryDataByteOrderMSB = ") + (c.msb ? "True" : "False");
    const std::string raw = header(c.name, order + "\nCompressedData = False\n");
    const Bytes packed = zlib(disk);
    const std::string gz = header(c.name, order + "\nCompressedData = True\nCompressedDataSize = " +
                                              std::to_string(packed.size()) + "\n");
    writeMha(dir.file("raw.mha"), raw, disk);
    writeMha(dir.file("zlib.mha"), gz, packed);
    writeMhd(dir.file("raw.mhd"), raw, "raw.raw", disk);
    writeMhd(dir.file("zlib.mhd"), gz, "zlib.zraw", packed);
    for (const std::string name : {"raw.mha", "zlib.mha", "raw.mhd", "zlib.mhd"}) {
        auto source = openMetaImage(dir.file(name));
        EXPECT_EQ(source->info().dims, kDims) << name;
        EXPECT_EQ(source->info().type, c.type) << name;
        EXPECT_EQ(readAllBytes(*source, {3}), host) << name;
    }
}

INSTANTIATE_TEST_SUITE_P(MetaImageAllTypes, MetaImageTypeTest,
                         ::testing::Values(TypeCase{"MET_UCHAR", VoxelType::U8, false},
                                           TypeCase{"MET_USHORT", VoxelType::U16, false},
                                           TypeCase{"MET_USHORT", VoxelType::U16, true},
                                           TypeCase{"MET_SHORT", VoxelType::I16, false},
                                           TypeCase{"MET_SHORT", VoxelType::I16, true},
                                           TypeCase{"MET_FLOAT", VoxelType::F32, false},
                                           TypeCase{"MET_FLOAT", VoxelType::F32, true}),
                         [](const ::testing::TestParamInfo<TypeCase>& info) {
                             return info.param.name + (info.param.msb ? "_msb" : "_lsb");
                         });

TEST(MetaImageReaderTest, InfoHasSpacingOriginAndDescription) {
    test::TempDir dir;
    writeMha(dir.file("vol.mha"),
             header("MET_USHORT", "ElementSpacing = 0.5 0.75 2\nOffset = -10.5 20 0.25\n"
                                  "TransformMatrix = 1 0 0 0 1 0 0 0 1\n"
                                  "AnatomicalOrientation = RAI\nCompressedData = False\n"),
             patternVoxels(VoxelType::U16, kVoxels));
    auto source = openMetaImage(dir.file("vol.mha"));
    const VolumeInfo& info = source->info();
    EXPECT_EQ(info.dims, kDims);
    EXPECT_EQ(info.type, VoxelType::U16);
    EXPECT_EQ(info.spacingMm, (std::array<double, 3>{0.5, 0.75, 2.0}));
    EXPECT_EQ(info.originMm, (std::array<double, 3>{-10.5, 20, 0.25}));
    EXPECT_NE(info.description.find("MetaImage vol.mha, u16"), std::string::npos)
        << info.description;
}

TEST(MetaImageReaderTest, ElementSizeAndOriginAreSynonyms) {
    test::TempDir dir;
    writeMha(dir.file("vol.mha"), header("MET_UCHAR", "ElementSize = 2 3 4\nOrigin = 1 2 3\n"),
             patternVoxels(VoxelType::U8, kVoxels));
    auto source = openMetaImage(dir.file("vol.mha"));
    EXPECT_EQ(source->info().spacingMm, (std::array<double, 3>{2, 3, 4}));
    EXPECT_EQ(source->info().originMm, (std::array<double, 3>{1, 2, 3}));
}

TEST(MetaImageReaderTest, UnevenSliceCountsGiveTheSameBytes) {
    test::TempDir dir;
    const Bytes host = patternVoxels(VoxelType::F32, 7 * 3 * 11);
    const Bytes packed = zlib(host);
    writeMha(dir.file("raw.mha"), header("MET_FLOAT", "", "7 3 11"), host);
    writeMha(dir.file("zlib.mha"), header("MET_FLOAT", "CompressedData = True\n", "7 3 11"),
             packed);
    for (const std::string name : {"raw.mha", "zlib.mha"}) {
        auto source = openMetaImage(dir.file(name));
        EXPECT_EQ(readAllBytes(*source, {1, 5, 2}), host) << name;
    }
}

TEST(MetaImageReaderTest, HeaderSizeSkipsBytesOfTheDataFile) {
    test::TempDir dir;
    const Bytes host = patternVoxels(VoxelType::I16, kVoxels);
    Bytes withPreamble(37 + host.size(), 0xee); // (not insert(): GCC 12's -Warray-bounds)
    std::copy(host.begin(), host.end(), withPreamble.begin() + 37);
    writeMhd(dir.file("skip.mhd"), header("MET_SHORT", "HeaderSize = 37\n"), "skip.raw",
             withPreamble);
    EXPECT_EQ(readAllBytes(*openMetaImage(dir.file("skip.mhd"))), host);
    // -1: the data are the file's last bytes, whatever precedes them.
    writeMhd(dir.file("end.mhd"), header("MET_SHORT", "HeaderSize = -1\n"), "end.raw",
             withPreamble);
    EXPECT_EQ(readAllBytes(*openMetaImage(dir.file("end.mhd"))), host);
}

TEST(MetaImageReaderTest, DataFileMayLieInASubfolder) {
    test::TempDir dir;
    const Bytes host = patternVoxels(VoxelType::U8, kVoxels);
    std::filesystem::create_directory(dir.path() / "data");
    writeMhd(dir.file("vol.mhd"), header("MET_UCHAR"), "data/vol.raw", host);
    EXPECT_EQ(readAllBytes(*openMetaImage(dir.file("vol.mhd"))), host);
}

TEST(MetaImageReaderTest, DimSizeNeedingMoreBytesThanTheFileHasThrows) {
    test::TempDir dir;
    writeMha(dir.file("short.mha"), header("MET_USHORT"),
             patternVoxels(VoxelType::U16, kVoxels - 1));
    const std::string what = expectFormatError([&] { openMetaImage(dir.file("short.mha")); },
                                               dir.file("short.mha"), "DimSize");
    EXPECT_NE(what.find("promises 240 bytes"), std::string::npos) << what;
    writeMha(dir.file("long.mha"), header("MET_UCHAR"), patternVoxels(VoxelType::U8, kVoxels + 1));
    expectFormatError([&] { openMetaImage(dir.file("long.mha")); }, dir.file("long.mha"),
                      "DimSize");
    writeMhd(dir.file("vol.mhd"), header("MET_UCHAR"), "half.raw",
             patternVoxels(VoxelType::U8, kVoxels / 2));
    expectFormatError([&] { openMetaImage(dir.file("vol.mhd")); }, dir.file("half.raw"), "DimSize");
}

TEST(MetaImageReaderTest, HugeDimSizeThrowsBeforeReading) {
    test::TempDir dir;
    writeMha(dir.file("huge.mha"), header("MET_FLOAT", "", "4294967296 4294967296 2"), {1, 2});
    expectFormatError([&] { openMetaImage(dir.file("huge.mha")); }, dir.file("huge.mha"),
                      "DimSize");
}

/// A data file outside the header's folder, for the escape attempts below.
class MetaImageEscapeTest : public ::testing::Test {
  protected:
    void SetUp() override {
        const Bytes host = patternVoxels(VoxelType::U8, kVoxels);
        test::writeFile(mOutside.file("x.raw"), host.data(), host.size());
        std::filesystem::create_directory(mDir.path() / "hdr");
        std::filesystem::copy_file(mOutside.file("x.raw"), mDir.file("x.raw"));
    }
    std::string expectRejected(const std::string& dataFile) {
        const std::string mhd = mDir.file("hdr/vol.mhd");
        test::writeFile(mhd, header("MET_UCHAR") + "ElementDataFile = " + dataFile + "\n");
        return expectFormatError([&] { openMetaImage(mhd); }, mhd, "ElementDataFile");
    }
    test::TempDir mOutside;
    test::TempDir mDir;
};

TEST_F(MetaImageEscapeTest, DotDotDataFileThrows) {
    EXPECT_NE(expectRejected("../x.raw").find("'..'"), std::string::npos);
    expectRejected("sub/../../x.raw");
}

TEST_F(MetaImageEscapeTest, AbsoluteDataFileThrows) {
    EXPECT_NE(expectRejected(mOutside.file("x.raw")).find("absolute"), std::string::npos);
}

TEST_F(MetaImageEscapeTest, SymlinkOutOfTheFolderThrows) {
    std::filesystem::create_symlink(mOutside.file("x.raw"), mDir.path() / "hdr" / "link.raw");
    expectRejected("link.raw");
}

TEST_F(MetaImageEscapeTest, ListsAndPatternsOfFilesThrow) {
    EXPECT_NE(expectRejected("LIST").find("not supported"), std::string::npos);
    expectRejected("slice%03d.raw 1 4 1");
}

TEST(MetaImageReaderTest, NDimsOtherThanThreeThrows) {
    test::TempDir dir;
    writeMha(dir.file("2d.mha"),
             "ObjectType = Image\nNDims = 2\nDimSize = 6 5\nElementType = MET_UCHAR\n",
             patternVoxels(VoxelType::U8, 30));
    expectFormatError([&] { openMetaImage(dir.file("2d.mha")); }, dir.file("2d.mha"), "NDims");
}

TEST(MetaImageReaderTest, UnknownOrUnstoredElementTypeThrows) {
    test::TempDir dir;
    writeMha(dir.file("t.mha"), header("MET_QUATERNION"), patternVoxels(VoxelType::U8, kVoxels));
    std::string what = expectFormatError([&] { openMetaImage(dir.file("t.mha")); },
                                         dir.file("t.mha"), "ElementType");
    EXPECT_NE(what.find("MET_QUATERNION"), std::string::npos) << what;
    writeMha(dir.file("t.mha"), header("MET_DOUBLE"), patternVoxels(VoxelType::F32, kVoxels * 2));
    what = expectFormatError([&] { openMetaImage(dir.file("t.mha")); }, dir.file("t.mha"),
                             "ElementType");
    EXPECT_NE(what.find("not supported"), std::string::npos) << what;
}

TEST(MetaImageReaderTest, SeveralChannelsThrow) {
    test::TempDir dir;
    writeMha(dir.file("rgb.mha"), header("MET_UCHAR", "ElementNumberOfChannels = 3\n"),
             patternVoxels(VoxelType::U8, kVoxels * 3));
    expectFormatError([&] { openMetaImage(dir.file("rgb.mha")); }, dir.file("rgb.mha"),
                      "ElementNumberOfChannels");
}

TEST(MetaImageReaderTest, CompressedDataSizeThatLiesThrows) {
    test::TempDir dir;
    const Bytes packed = zlib(patternVoxels(VoxelType::U16, kVoxels));
    for (std::size_t lie : {packed.size() + 1, packed.size() - 1, std::size_t(1) << 40}) {
        writeMha(dir.file("lie.mha"),
                 header("MET_USHORT", "CompressedData = True\nCompressedDataSize = " +
                                          std::to_string(lie) + "\n"),
                 packed);
        expectFormatError([&] { openMetaImage(dir.file("lie.mha")); }, dir.file("lie.mha"),
                          "CompressedDataSize");
    }
}

TEST(MetaImageReaderTest, ZlibPayloadCutShortThrows) {
    test::TempDir dir;
    Bytes packed = zlib(patternVoxels(VoxelType::F32, kVoxels));
    packed.resize(packed.size() * 2 / 3);
    // Without CompressedDataSize and with one that matches the cut payload: either way the
    // stream itself ends early.
    writeMha(dir.file("cut.mha"), header("MET_FLOAT", "CompressedData = True\n"), packed);
    writeMhd(dir.file("cut.mhd"),
             header("MET_FLOAT", "CompressedData = True\nCompressedDataSize = " +
                                     std::to_string(packed.size()) + "\n"),
             "cut.zraw", packed);
    expectFormatError([&] { readAllBytes(*openMetaImage(dir.file("cut.mha"))); },
                      dir.file("cut.mha"), "data");
    expectFormatError([&] { readAllBytes(*openMetaImage(dir.file("cut.mhd"))); },
                      dir.file("cut.zraw"), "data");
}

TEST(MetaImageReaderTest, ZlibPayloadTooSmallForDimSizeThrowsAtOpen) {
    test::TempDir dir;
    writeMha(dir.file("tiny.mha"), header("MET_UCHAR", "CompressedData = True\n", "1000 1000 1000"),
             Bytes(20, 1));
    expectFormatError([&] { openMetaImage(dir.file("tiny.mha")); }, dir.file("tiny.mha"),
                      "DimSize");
}

TEST(MetaImageReaderTest, FieldAfterElementDataFileInAnMhdThrows) {
    test::TempDir dir;
    test::writeFile(dir.file("vol.raw"), patternVoxels(VoxelType::U8, kVoxels).data(), kVoxels);
    test::writeFile(dir.file("vol.mhd"),
                    header("MET_UCHAR") + "ElementDataFile = vol.raw\nElementSpacing = 1 1 1\n");
    expectFormatError([&] { openMetaImage(dir.file("vol.mhd")); }, dir.file("vol.mhd"),
                      "ElementDataFile");
}

TEST(MetaImageReaderTest, NotAMetaImageHeaderThrows) {
    test::TempDir dir;
    test::writeFile(dir.file("png.mha"), std::string("\x89PNG\r\n\x1a\n\0\0\0\rIHDR", 16));
    expectFormatError([&] { openMetaImage(dir.file("png.mha")); }, dir.file("png.mha"), "header");
    test::writeFile(dir.file("nodata.mha"), header("MET_UCHAR"));
    expectFormatError([&] { openMetaImage(dir.file("nodata.mha")); }, dir.file("nodata.mha"),
                      "ElementDataFile");
    test::writeFile(dir.file("long.mha"), header("MET_UCHAR") + "Comment = " +
                                              std::string(std::size_t(1) << 20, 'x') + "\n");
    expectFormatError([&] { openMetaImage(dir.file("long.mha")); }, dir.file("long.mha"), "header");
}

TEST(MetaImageReaderTest, AsciiDataAndBadSpacingThrow) {
    test::TempDir dir;
    const Bytes host = patternVoxels(VoxelType::U8, kVoxels);
    writeMha(dir.file("a.mha"),
             "ObjectType = Image\nNDims = 3\nDimSize = 6 5 4\nElementType = MET_UCHAR\n"
             "BinaryData = False\n",
             host);
    expectFormatError([&] { openMetaImage(dir.file("a.mha")); }, dir.file("a.mha"), "BinaryData");
    for (const std::string bad : {"1 0 1", "1 -2 1", "1 nan 1", "1 1"}) {
        writeMha(dir.file("s.mha"), header("MET_UCHAR", "ElementSpacing = " + bad + "\n"), host);
        expectFormatError([&] { openMetaImage(dir.file("s.mha")); }, dir.file("s.mha"),
                          "ElementSpacing");
    }
}

TEST(MetaImageReaderTest, NanVoxelThrows) {
    test::TempDir dir;
    Bytes host = patternVoxels(VoxelType::F32, kVoxels);
    const float nan = std::numeric_limits<float>::quiet_NaN();
    std::memcpy(host.data() + 4 * 17, &nan, 4);
    writeMha(dir.file("nan.mha"), header("MET_FLOAT"), host);
    expectFormatError([&] { readAllBytes(*openMetaImage(dir.file("nan.mha"))); },
                      dir.file("nan.mha"), "data");
}

/// Which vtkMetaImageWriter layouts each shared scan is written in: every layout on several
/// scans and every scan once or twice, so the suite stays quick.
std::vector<std::string> metaVariants(const std::string& scan) {
    static const std::map<std::string, std::vector<std::string>> kVariants = {
        {"cthead", {"mha-zlib"}},
        {"headsq", {"mha", "mhd-zlib"}},
        {"frog", {"mhd"}},
        {"ct_avm", {"mhd-zlib"}},
        {"iguana", {"mha-zlib"}},
        {"pancreas", {"mha"}},
        {"hydrogen", {"mhd", "mha"}},
        {"gaffer", {"mhd-zlib", "mha-zlib"}}};
    auto it = kVariants.find(scan);
    return it == kVariants.end() ? std::vector<std::string>{"mha"} : it->second;
}

class MetaImageRoundTrip : public ::testing::TestWithParam<test::SharedScan> {};

TEST_P(MetaImageRoundTrip, VtkWrittenScanIngestsToTheSameVoxels) {
    test::expectVtkWrittenScanRoundTrips(
        GetParam(), metaVariants(GetParam().name),
        [](const std::string& v) { return v + "." + v.substr(0, 3); }, openMetaImage, "MetaImage");
}

INSTANTIATE_TEST_SUITE_P(MetaImageSharedScans, MetaImageRoundTrip,
                         ::testing::ValuesIn(test::sharedScans()),
                         [](const ::testing::TestParamInfo<test::SharedScan>& info) {
                             return info.param.name;
                         });

} // namespace
} // namespace bc::brickstore
