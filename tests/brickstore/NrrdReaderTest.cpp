// openNrrd: attached and detached headers, raw and gzip data, every stored type in both byte
// orders, spacing and origin, slice-by-slice reads, and every bad header it refuses:
// sizes, types, spacings, truncated or overlong data, data files outside the header's folder.
#include "brickstore/Error.h"
#include "brickstore/Readers.h"
#include "tests/TestSupport.h"
#include "tests/brickstore/RawTestSupport.h"

#include <gtest/gtest.h>

#include <cmath>
#include <cstddef>
#include <cstdint>
#include <cstring>
#include <filesystem>
#include <limits>
#include <string>
#include <tuple>
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

/// One gzip member (deflate with the gzip wrapper, windowBits 15 + 16), as teem writes.
Bytes gzip(const Bytes& data) {
    z_stream z{};
    EXPECT_EQ(deflateInit2(&z, Z_BEST_SPEED, Z_DEFLATED, 31, 8, Z_DEFAULT_STRATEGY), Z_OK);
    Bytes out(deflateBound(&z, data.size()) + 64);
    z.next_in = const_cast<Bytef*>(data.data());
    z.avail_in = static_cast<uInt>(data.size());
    z.next_out = out.data();
    z.avail_out = static_cast<uInt>(out.size());
    EXPECT_EQ(deflate(&z, Z_FINISH), Z_STREAM_END);
    out.resize(z.total_out);
    deflateEnd(&z);
    return out;
}

std::string header(const std::string& type, const std::string& extra,
                   const std::string& sizes = "6 5 4") {
    return "NRRD0004\n# made by NrrdReaderTest\ntype: " + type + "\ndimension: 3\nsizes: " + sizes +
           "\n" + extra;
}

/// An attached NRRD: the header, a blank line, then the data.
void writeAttached(const std::string& path, const std::string& head, const Bytes& data) {
    std::string text = head + "\n";
    Bytes file(text.begin(), text.end());
    file.insert(file.end(), data.begin(), data.end());
    test::writeFile(path, file.data(), file.size());
}

Bytes readNrrd(const std::string& path, const std::vector<std::uint64_t>& counts = {1}) {
    auto source = openNrrd(path);
    return readAllBytes(*source, counts);
}

struct TypeCase {
    std::string name;
    VoxelType type;
    Endian endian;
};

class NrrdTypeTest : public ::testing::TestWithParam<TypeCase> {
  protected:
    std::string headOf(const std::string& encoding) const {
        const TypeCase& c = GetParam();
        return header(c.name, "encoding: " + encoding + "\nendian: " +
                                  (c.endian == Endian::Big ? "big" : "little") + "\n");
    }
    Bytes host() const { return patternVoxels(GetParam().type, kVoxels); }
    Bytes onDisk() const {
        return GetParam().endian == Endian::Big ? swapped(host(), GetParam().type) : host();
    }
    test::TempDir mDir;
};

TEST_P(NrrdTypeTest, ReadsAttachedRawExactly) {
    writeAttached(mDir.file("vol.nrrd"), headOf("raw"), onDisk());
    auto source = openNrrd(mDir.file("vol.nrrd"));
    EXPECT_EQ(source->info().dims, kDims);
    EXPECT_EQ(source->info().type, GetParam().type);
    EXPECT_EQ(readAllBytes(*source), host());
}

TEST_P(NrrdTypeTest, ReadsAttachedGzipExactly) {
    writeAttached(mDir.file("vol.nrrd"), headOf("gzip"), gzip(onDisk()));
    EXPECT_EQ(readNrrd(mDir.file("vol.nrrd")), host());
}

TEST_P(NrrdTypeTest, ReadsDetachedRawExactly) {
    test::writeFile(mDir.file("vol.nhdr"), headOf("raw") + "data file: vol.raw\n");
    Bytes data = onDisk();
    test::writeFile(mDir.file("vol.raw"), data.data(), data.size());
    EXPECT_EQ(readNrrd(mDir.file("vol.nhdr")), host());
}

TEST_P(NrrdTypeTest, ReadsDetachedGzipExactly) {
    test::writeFile(mDir.file("vol.nhdr"), headOf("gz") + "datafile: vol.raw.gz\n");
    Bytes data = gzip(onDisk());
    test::writeFile(mDir.file("vol.raw.gz"), data.data(), data.size());
    EXPECT_EQ(readNrrd(mDir.file("vol.nhdr")), host());
}

INSTANTIATE_TEST_SUITE_P(AllTypes, NrrdTypeTest,
                         ::testing::Values(TypeCase{"uchar", VoxelType::U8, Endian::Little},
                                           TypeCase{"uint8_t", VoxelType::U8, Endian::Big},
                                           TypeCase{"unsigned short", VoxelType::U16, Endian::Big},
                                           TypeCase{"uint16", VoxelType::U16, Endian::Little},
                                           TypeCase{"short", VoxelType::I16, Endian::Big},
                                           TypeCase{"int16_t", VoxelType::I16, Endian::Little},
                                           TypeCase{"float", VoxelType::F32, Endian::Little},
                                           TypeCase{"float", VoxelType::F32, Endian::Big}),
                         [](const ::testing::TestParamInfo<TypeCase>& info) {
                             std::string name =
                                 info.param.name +
                                 (info.param.endian == Endian::Big ? "_big" : "_little");
                             std::replace(name.begin(), name.end(), ' ', '_');
                             return name;
                         });

TEST(NrrdReaderTest, SliceCountsDoNotChangeTheBytes) {
    test::TempDir dir;
    Bytes host = patternVoxels(VoxelType::U16, kVoxels);
    writeAttached(dir.file("raw.nrrd"), header("ushort", "encoding: raw\nendian: little\n"), host);
    writeAttached(dir.file("gz.nrrd"), header("ushort", "encoding: gzip\nendian: little\n"),
                  gzip(host));
    for (const std::string name : {"raw.nrrd", "gz.nrrd"}) {
        EXPECT_EQ(readNrrd(dir.file(name), {4}), host) << name;
        EXPECT_EQ(readNrrd(dir.file(name), {1}), host) << name;
        EXPECT_EQ(readNrrd(dir.file(name), {3, 1}), host) << name;
        EXPECT_EQ(readNrrd(dir.file(name), {0, 2}), host) << name;
    }
}

TEST(NrrdReaderTest, ReadsSpacingsField) {
    test::TempDir dir;
    writeAttached(dir.file("vol.nrrd"), header("uchar", "encoding: raw\nspacings: 0.5 0.75 2\n"),
                  patternVoxels(VoxelType::U8, kVoxels));
    auto source = openNrrd(dir.file("vol.nrrd"));
    EXPECT_EQ(source->info().spacingMm, (std::array<double, 3>{0.5, 0.75, 2.0}));
    EXPECT_EQ(source->info().originMm, (std::array<double, 3>{0, 0, 0}));
}

TEST(NrrdReaderTest, SpacingIsTheLengthOfEachSpaceDirection) {
    test::TempDir dir;
    writeAttached(dir.file("vol.nrrd"),
                  header("uchar", "encoding: raw\nspace: left-posterior-superior\n"
                                  "space directions: (0,-3,4) (1.5,0,0) ( 0, 0, 2.5 )\n"
                                  "space origin: (-10.5,20,0.25)\n"),
                  patternVoxels(VoxelType::U8, kVoxels));
    auto source = openNrrd(dir.file("vol.nrrd"));
    EXPECT_EQ(source->info().spacingMm, (std::array<double, 3>{5.0, 1.5, 2.5}));
    EXPECT_EQ(source->info().originMm, (std::array<double, 3>{-10.5, 20, 0.25}));
}

TEST(NrrdReaderTest, IgnoresCommentsKeyValuePairsAndCrlfLineEnds) {
    test::TempDir dir;
    Bytes host = patternVoxels(VoxelType::I16, kVoxels);
    std::string head = "NRRD0005\r\n# comment\r\ntype: int16\r\ndimension: 3\r\nsizes: 6 5 4\r\n"
                       "encoding: raw\r\nendian: little\r\nkinds: domain domain domain\r\n"
                       "patient:=somebody: with colons\r\n\r\n";
    Bytes file(head.begin(), head.end());
    file.insert(file.end(), host.begin(), host.end());
    test::writeFile(dir.file("vol.nrrd"), file.data(), file.size());
    EXPECT_EQ(readNrrd(dir.file("vol.nrrd")), host);
}

TEST(NrrdReaderTest, DetachedDataSkipsLinesAndMayLieInASubfolder) {
    test::TempDir dir;
    Bytes host = patternVoxels(VoxelType::U8, kVoxels);
    std::filesystem::create_directory(dir.path() / "data");
    std::string preamble = "two lines\nof preamble\n";
    Bytes file(preamble.begin(), preamble.end());
    file.insert(file.end(), host.begin(), host.end());
    test::writeFile(dir.file("data/vol.raw"), file.data(), file.size());
    test::writeFile(
        dir.file("vol.nhdr"),
        header("uchar", "encoding: raw\nline skip: 2\nbyte skip: 0\ndata file: ./data/vol.raw\n"));
    EXPECT_EQ(readNrrd(dir.file("vol.nhdr"), {2}), host);
}

TEST(NrrdReaderTest, SymlinkInsideTheHeaderFolderIsAllowed) {
    test::TempDir dir;
    Bytes host = patternVoxels(VoxelType::U8, kVoxels);
    test::writeFile(dir.file("real.raw"), host.data(), host.size());
    std::filesystem::create_symlink("real.raw", dir.path() / "link.raw");
    test::writeFile(dir.file("vol.nhdr"), header("uchar", "encoding: raw\ndata file: link.raw\n"));
    EXPECT_EQ(readNrrd(dir.file("vol.nhdr")), host);
}

TEST(NrrdReaderTest, ReadsConcatenatedGzipMembers) {
    test::TempDir dir;
    Bytes host = patternVoxels(VoxelType::F32, kVoxels);
    Bytes data = gzip(Bytes(host.begin(), host.begin() + 100));
    Bytes second = gzip(Bytes(host.begin() + 100, host.end()));
    data.insert(data.end(), second.begin(), second.end());
    writeAttached(dir.file("vol.nrrd"), header("float", "encoding: gzip\nendian: little\n"), data);
    EXPECT_EQ(readNrrd(dir.file("vol.nrrd"), {3}), host);
}

TEST(NrrdReaderTest, ZeroSizeThrows) {
    test::TempDir dir;
    writeAttached(dir.file("zero.nrrd"), header("uchar", "encoding: raw\n", "6 0 4"), {});
    expectFormatError([&] { openNrrd(dir.file("zero.nrrd")); }, dir.file("zero.nrrd"), "dims");
}

TEST(NrrdReaderTest, SizesWhoseByteSizeOverflowsThrow) {
    test::TempDir dir;
    writeAttached(
        dir.file("huge.nrrd"),
        header("ushort", "encoding: raw\nendian: little\n", "4294967296 4294967296 4294967296"),
        {1, 2, 3});
    expectFormatError([&] { openNrrd(dir.file("huge.nrrd")); }, dir.file("huge.nrrd"), "dims");
}

TEST(NrrdReaderTest, NegativeOrNonNumericSizeThrows) {
    test::TempDir dir;
    writeAttached(dir.file("neg.nrrd"), header("uchar", "encoding: raw\n", "6 -5 4"), {});
    expectFormatError([&] { openNrrd(dir.file("neg.nrrd")); }, dir.file("neg.nrrd"), "sizes");
}

TEST(NrrdReaderTest, AttachedDataShorterThanHeaderPromisesThrows) {
    test::TempDir dir;
    Bytes data = patternVoxels(VoxelType::U16, kVoxels - 1);
    writeAttached(dir.file("short.nrrd"), header("ushort", "encoding: raw\nendian: big\n"), data);
    std::string what = expectFormatError([&] { openNrrd(dir.file("short.nrrd")); },
                                         dir.file("short.nrrd"), "size");
    EXPECT_NE(what.find("promises 240 bytes"), std::string::npos) << what;
}

TEST(NrrdReaderTest, AttachedDataLongerThanHeaderPromisesThrows) {
    test::TempDir dir;
    writeAttached(dir.file("long.nrrd"), header("uchar", "encoding: raw\n"),
                  patternVoxels(VoxelType::U8, kVoxels + 2));
    expectFormatError([&] { openNrrd(dir.file("long.nrrd")); }, dir.file("long.nrrd"), "size");
}

TEST(NrrdReaderTest, DetachedDataShorterThanHeaderPromisesThrows) {
    test::TempDir dir;
    Bytes data = patternVoxels(VoxelType::U8, kVoxels / 2);
    test::writeFile(dir.file("half.raw"), data.data(), data.size());
    test::writeFile(dir.file("vol.nhdr"), header("uchar", "encoding: raw\ndata file: half.raw\n"));
    std::string what =
        expectFormatError([&] { openNrrd(dir.file("vol.nhdr")); }, dir.file("half.raw"), "size");
    EXPECT_NE(what.find("vol.nhdr"), std::string::npos) << what;
}

TEST(NrrdReaderTest, GzipDataInflatingToFewerBytesThrows) {
    test::TempDir dir;
    writeAttached(dir.file("few.nrrd"), header("uchar", "encoding: gzip\n"),
                  gzip(patternVoxels(VoxelType::U8, kVoxels - 10)));
    expectFormatError([&] { readNrrd(dir.file("few.nrrd")); }, dir.file("few.nrrd"), "size");
}

TEST(NrrdReaderTest, TruncatedGzipDataThrows) {
    test::TempDir dir;
    Bytes data = gzip(patternVoxels(VoxelType::U16, kVoxels));
    data.resize(data.size() / 2);
    writeAttached(dir.file("cut.nrrd"), header("ushort", "encoding: gzip\nendian: little\n"), data);
    expectFormatError([&] { readNrrd(dir.file("cut.nrrd")); }, dir.file("cut.nrrd"), "data");
}

TEST(NrrdReaderTest, GzipDataInflatingPastTheDeclaredSizeThrows) {
    test::TempDir dir;
    writeAttached(dir.file("more.nrrd"), header("uchar", "encoding: gzip\n"),
                  gzip(patternVoxels(VoxelType::U8, kVoxels + 1)));
    auto source = openNrrd(dir.file("more.nrrd"));
    std::string what =
        expectFormatError([&] { readAllBytes(*source); }, dir.file("more.nrrd"), "data");
    EXPECT_NE(what.find("gzip data inflates past the declared 120 bytes"), std::string::npos)
        << what;
}

TEST(NrrdReaderTest, CorruptGzipDataThrows) {
    test::TempDir dir;
    writeAttached(dir.file("bad.nrrd"), header("uchar", "encoding: gzip\n"),
                  Bytes(64, std::uint8_t{0x5a}));
    expectFormatError([&] { readNrrd(dir.file("bad.nrrd")); }, dir.file("bad.nrrd"), "data");
}

TEST(NrrdReaderTest, BadSpacingsThrow) {
    test::TempDir dir;
    for (const std::string bad : {"nan", "0", "-1.5"}) {
        writeAttached(dir.file("sp.nrrd"),
                      header("uchar", "encoding: raw\nspacings: 1 " + bad + " 1\n"),
                      patternVoxels(VoxelType::U8, kVoxels));
        expectFormatError([&] { openNrrd(dir.file("sp.nrrd")); }, dir.file("sp.nrrd"), "spacings");
    }
}

TEST(NrrdReaderTest, ZeroOrNanSpaceDirectionThrows) {
    test::TempDir dir;
    for (const std::string bad : {"(0,0,0)", "(nan,0,0)", "none"}) {
        writeAttached(
            dir.file("dir.nrrd"),
            header("uchar", "encoding: raw\nspace directions: (1,0,0) " + bad + " (0,0,1)\n"),
            patternVoxels(VoxelType::U8, kVoxels));
        expectFormatError([&] { openNrrd(dir.file("dir.nrrd")); }, dir.file("dir.nrrd"),
                          "space directions");
    }
}

TEST(NrrdReaderTest, UnknownTypeThrows) {
    test::TempDir dir;
    writeAttached(dir.file("type.nrrd"), header("quaternion", "encoding: raw\n"), {});
    expectFormatError([&] { openNrrd(dir.file("type.nrrd")); }, dir.file("type.nrrd"), "type");
}

TEST(NrrdReaderTest, UnstoredTypeThrows) {
    test::TempDir dir;
    writeAttached(dir.file("double.nrrd"), header("double", "encoding: raw\nendian: little\n"), {});
    expectFormatError([&] { openNrrd(dir.file("double.nrrd")); }, dir.file("double.nrrd"), "type");
}

TEST(NrrdReaderTest, DimensionOtherThanThreeThrows) {
    test::TempDir dir;
    writeAttached(dir.file("4d.nrrd"),
                  "NRRD0004\ntype: uchar\ndimension: 4\nsizes: 2 6 5 4\nencoding: raw\n", {});
    expectFormatError([&] { openNrrd(dir.file("4d.nrrd")); }, dir.file("4d.nrrd"), "dimension");
}

TEST(NrrdReaderTest, MultiByteTypeWithoutEndianThrows) {
    test::TempDir dir;
    writeAttached(dir.file("end.nrrd"), header("short", "encoding: raw\n"),
                  patternVoxels(VoxelType::I16, kVoxels));
    expectFormatError([&] { openNrrd(dir.file("end.nrrd")); }, dir.file("end.nrrd"), "endian");
}

TEST(NrrdReaderTest, UnsupportedEncodingThrows) {
    test::TempDir dir;
    writeAttached(dir.file("txt.nrrd"), header("uchar", "encoding: ascii\n"), {});
    expectFormatError([&] { openNrrd(dir.file("txt.nrrd")); }, dir.file("txt.nrrd"), "encoding");
}

TEST(NrrdReaderTest, NonZeroByteSkipThrows) {
    test::TempDir dir;
    writeAttached(dir.file("skip.nrrd"), header("uchar", "encoding: raw\nbyte skip: -1\n"),
                  patternVoxels(VoxelType::U8, kVoxels));
    expectFormatError([&] { openNrrd(dir.file("skip.nrrd")); }, dir.file("skip.nrrd"), "byte skip");
}

TEST(NrrdReaderTest, FileWithoutNrrdMagicThrows) {
    test::TempDir dir;
    test::writeFile(dir.file("not.nrrd"), "P5\n6 5\n255\n");
    expectFormatError([&] { openNrrd(dir.file("not.nrrd")); }, dir.file("not.nrrd"), "magic");
}

/// A data file outside the header's folder, for the escape attempts below.
class NrrdEscapeTest : public ::testing::Test {
  protected:
    void SetUp() override {
        Bytes host = patternVoxels(VoxelType::U8, kVoxels);
        test::writeFile(mOutside.file("secret.raw"), host.data(), host.size());
        std::filesystem::create_directory(mDir.path() / "hdr");
    }
    void expectRejected(const std::string& dataFile) {
        const std::string nhdr = mDir.file("hdr/vol.nhdr");
        test::writeFile(nhdr, header("uchar", "encoding: raw\ndata file: " + dataFile + "\n"));
        expectFormatError([&] { openNrrd(nhdr); }, nhdr, "data file");
    }
    test::TempDir mOutside;
    test::TempDir mDir;
};

TEST_F(NrrdEscapeTest, AbsoluteDataFileThrows) {
    expectRejected(mOutside.file("secret.raw"));
}

TEST_F(NrrdEscapeTest, DataFileWithDotDotThrows) {
    std::filesystem::copy_file(mOutside.file("secret.raw"), mDir.file("secret.raw"));
    expectRejected("../secret.raw");
    expectRejected("sub/../../secret.raw");
}

TEST_F(NrrdEscapeTest, DataFileSymlinkPointingOutsideThrows) {
    std::filesystem::create_symlink(mOutside.file("secret.raw"), mDir.path() / "hdr" / "link.raw");
    expectRejected("link.raw");
}

TEST_F(NrrdEscapeTest, DataFileInSymlinkedFolderOutsideThrows) {
    std::filesystem::create_directory_symlink(mOutside.path(), mDir.path() / "hdr" / "linked");
    expectRejected("linked/secret.raw");
}

TEST(NrrdReaderTest, NanVoxelThrowsNamingItsPosition) {
    test::TempDir dir;
    Bytes host = patternVoxels(VoxelType::F32, kVoxels);
    float nan = std::numeric_limits<float>::quiet_NaN();
    std::memcpy(host.data() + 4 * (4 + 6 * (3 + 5 * 2)), &nan, 4);
    writeAttached(dir.file("nan.nrrd"), header("float", "encoding: gzip\nendian: big\n"),
                  gzip(swapped(host, VoxelType::F32)));
    auto source = openNrrd(dir.file("nan.nrrd"));
    std::string what =
        expectFormatError([&] { readAllBytes(*source); }, dir.file("nan.nrrd"), "data");
    EXPECT_NE(what.find("(4,3,2)"), std::string::npos) << what;
}

} // namespace
} // namespace bc::brickstore
