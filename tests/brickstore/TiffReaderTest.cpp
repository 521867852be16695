// openTiff: every shared scan written by independent writers (tifffile; libtiff's tiffcp for
// LZW and zstd) as multi-page classic and BigTIFF files and as folders of one-slice files, in
// strips and tiles, uncompressed, LZW, deflate (both codes) and zstd, with predictors and both
// byte orders, ingests to exactly the source voxels; info() and spacing from the resolution
// tags and ImageJ's description; and every bad input it refuses is a FormatError naming the
// file (and page) and the field.
#include "brickstore/Error.h"
#include "brickstore/Readers.h"
#include "tests/TestSupport.h"
#include "tests/brickstore/FormatTestSupport.h"
#include "tests/brickstore/RawTestSupport.h"

#include <gmock/gmock.h>
#include <gtest/gtest.h>

#include <filesystem>
#include <memory>
#include <string>
#include <vector>

namespace bc::brickstore {
namespace {

using test::expectFormatError;
using ::testing::HasSubstr;

const char* kWriter = "brickstore/writers/write_tiff.py";
const char* kModules = "numpy, tifffile";

/// Whether libtiff's tiffcp (Debian libtiff-tools) is there, which writes the LZW and zstd
/// files; a skip without it, a failure under CI=true (scripts/setup.sh installs it).
bool haveTiffcp() {
    if (test::runCommand("command -v tiffcp").exitCode == 0) return true;
    if (test::dataRequired())
        ADD_FAILURE() << "tiffcp is missing (CI=true: scripts/setup.sh installs libtiff-tools)";
    else
        [] { GTEST_SKIP() << "tiffcp (libtiff-tools) is missing: it writes LZW and zstd files"; }();
    return false;
}

// --- Round trips of the shared scans -----------------------------------------------------

struct RoundTrip {
    std::string scan;    ///< a SharedScan name
    std::string variant; ///< a variant of write_tiff.py; folder_* write a folder
    bool needsTiffcp = false;
};

test::SharedScan sharedScan(const std::string& name) {
    for (const test::SharedScan& s : test::sharedScans())
        if (s.name == name) return s;
    ADD_FAILURE() << "no shared scan " << name;
    return {};
}

class TiffRoundTripTest : public ::testing::TestWithParam<RoundTrip> {};

TEST_P(TiffRoundTripTest, IngestsToTheSourceVoxels) {
    if (!test::pythonHas(kModules)) return;
    const RoundTrip& c = GetParam();
    if (c.needsTiffcp && !haveTiffcp()) return;
    const test::SharedScan s = sharedScan(c.scan);
    if (!test::haveData(s.file)) return test::missingData(s.file);
    test::TempDir dir;
    const std::string raw = dir.file("scan.raw");
    const VolumeInfo info = test::dumpRaw(test::sharedSpec(s), raw);
    ASSERT_TRUE(
        test::runPython(kWriter, {"roundtrip", raw, s.dataType, std::to_string(info.dims[0]),
                                  std::to_string(info.dims[1]), std::to_string(info.dims[2]),
                                  dir.path().string(), c.variant}));
    SourceSpec written;
    written.input = dir.file(c.variant.rfind("folder_", 0) == 0 ? c.variant : c.variant + ".tif");
    test::expectIngestsToSameVoxels(test::sharedSpec(s), written, s.name + " as " + c.variant);
}

// Each scan in one layout, so that every layout and type is met once and the suite stays quick.
INSTANTIATE_TEST_SUITE_P(TiffScans, TiffRoundTripTest,
                         ::testing::Values(RoundTrip{"cthead", "strips_be"},
                                           RoundTrip{"headsq", "folder_zlib_tiles"},
                                           RoundTrip{"frog", "bigtiff_zlib_tiles"},
                                           RoundTrip{"ct_avm", "lzw_strips", true},
                                           RoundTrip{"iguana", "zstd_tiles", true},
                                           RoundTrip{"pancreas", "legacy_deflate_be"},
                                           RoundTrip{"hydrogen", "zstd_strips", true},
                                           RoundTrip{"gaffer", "folder_lzw_tiles", true},
                                           RoundTrip{"cthead", "bigtiff_strips"},
                                           RoundTrip{"frog", "folder_mixed"}),
                         [](const ::testing::TestParamInfo<RoundTrip>& info) {
                             return info.param.scan + "_" + info.param.variant;
                         });

// --- Direct reads and bad inputs: small files written once for the suite -----------------

class TiffReaderTest : public ::testing::Test {
  protected:
    static void SetUpTestSuite() {
        sDir = std::make_unique<test::TempDir>();
        sWriter = test::runCommand("/usr/bin/python3 '" + test::testsPath(kWriter) + "' cases '" +
                                   sDir->path().string() + "'");
    }
    static void TearDownTestSuite() { sDir.reset(); }

    /// Whether the cases are written: a skip without the writer's modules (a failure under CI).
    static bool ready() {
        if (!test::pythonHas(kModules)) return false;
        EXPECT_EQ(sWriter.exitCode, 0) << sWriter.text;
        return sWriter.exitCode == 0;
    }
    static std::string path(const std::string& name) { return sDir->file(name); }

    /// The file `name`.tif, read `counts` slices at a time, must hold `name`.raw.
    static void expectVoxels(const std::string& name, const std::vector<std::uint64_t>& counts) {
        auto source = openTiff(path(name + ".tif"), std::nullopt);
        EXPECT_EQ(test::readAllBytes(*source, counts), test::readFile(path(name + ".raw"))) << name;
    }

    static std::unique_ptr<test::TempDir> sDir;
    static test::CommandOutput sWriter;
};

std::unique_ptr<test::TempDir> TiffReaderTest::sDir;
test::CommandOutput TiffReaderTest::sWriter;

void expectSpacing(const VolumeInfo& info, std::array<double, 3> mm) {
    for (int a = 0; a < 3; ++a)
        EXPECT_NEAR(info.spacingMm[a], mm[a], 1e-9 * mm[a]) << "axis " << a;
}

TEST_F(TiffReaderTest, ImageJStackHasItsMicronSpacingInMillimetres) {
    if (!ready()) return;
    auto source = openTiff(path("imagej_um.tif"), std::nullopt);
    const VolumeInfo& info = source->info();
    EXPECT_EQ(info.dims, (std::array<std::uint64_t, 3>{40, 30, 7}));
    EXPECT_EQ(info.type, VoxelType::U16);
    // 2 and 4 pixels per micron; ImageJ's spacing=2.5 (microns) between slices.
    expectSpacing(info, {0.0005, 0.00025, 0.0025});
    EXPECT_THAT(info.description, HasSubstr("TIFF imagej_um.tif (7 pages"));
    EXPECT_THAT(info.description, HasSubstr("u16"));
}

TEST_F(TiffReaderTest, ResolutionInCentimetresAndInchesGivesMillimetres) {
    if (!ready()) return;
    auto cm = openTiff(path("cm_i16.tif"), std::nullopt);
    EXPECT_EQ(cm->info().type, VoxelType::I16);
    expectSpacing(cm->info(), {5.0, 2.5, 1.0}); // 2 and 4 pixels per cm; no z spacing: 1
    auto inch = openTiff(path("inch_f32_tiles.tif"), std::nullopt);
    EXPECT_EQ(inch->info().type, VoxelType::F32);
    expectSpacing(inch->info(), {0.1, 0.2, 1.0}); // 254 and 127 pixels per inch
    EXPECT_THAT(inch->info().description, HasSubstr("deflate tiles"));
}

TEST_F(TiffReaderTest, SpacingGivenOverridesTheFile) {
    if (!ready()) return;
    auto source = openTiff(path("imagej_um.tif"), std::array<double, 3>{0.7, 0.8, 0.9});
    expectSpacing(source->info(), {0.7, 0.8, 0.9});
}

TEST_F(TiffReaderTest, UnevenSliceCountsReadTheSameVoxels) {
    if (!ready()) return;
    for (const char* name : {"imagej_um", "cm_i16", "inch_f32_tiles", "u8_pages"}) {
        expectVoxels(name, {1, 5, 2});
        expectVoxels(name, {100});
    }
}

TEST_F(TiffReaderTest, FolderWithASliceOfAnotherWidthNamesItAndImageWidth) {
    if (!ready()) return;
    const std::string what = expectFormatError([] { openTiff(path("mixed_width"), std::nullopt); },
                                               path("mixed_width/s3.tif"), "ImageWidth");
    EXPECT_THAT(what, HasSubstr("is 21; the first slice's (s1.tif) is 20"));
}

TEST_F(TiffReaderTest, FolderWithASliceOfAnotherLengthNamesItAndImageLength) {
    if (!ready()) return;
    expectFormatError([] { openTiff(path("mixed_length"), std::nullopt); },
                      path("mixed_length/s3.tif"), "ImageLength");
}

TEST_F(TiffReaderTest, FolderWithASliceOfAnotherTypeNamesItAndBitsPerSample) {
    if (!ready()) return;
    expectFormatError([] { openTiff(path("mixed_type"), std::nullopt); }, path("mixed_type/s3.tif"),
                      "BitsPerSample");
}

TEST_F(TiffReaderTest, PageOfAnotherWidthNamesThePage) {
    if (!ready()) return;
    const std::string what =
        expectFormatError([] { openTiff(path("page_width.tif"), std::nullopt); },
                          path("page_width.tif"), "ImageWidth");
    EXPECT_THAT(what, HasSubstr("page 3: ImageWidth is 21; the first page's is 20"));
}

TEST_F(TiffReaderTest, TruncatedMultiPageFileNamesTheStripCutShort) {
    if (!ready()) return;
    const std::string what = expectFormatError(
        [] {
            auto source = openTiff(path("truncated.tif"), std::nullopt);
            test::readAllBytes(*source);
        },
        path("truncated.tif"), "StripByteCounts");
    EXPECT_THAT(what, HasSubstr("page 5: strip 3"));
    EXPECT_THAT(what, HasSubstr("runs past the end of the file"));
}

TEST_F(TiffReaderTest, StripByteCountBeyondTheFileIsRefusedBeforeReading) {
    if (!ready()) return;
    const std::string what = expectFormatError(
        [] {
            auto source = openTiff(path("beyond.tif"), std::nullopt);
            test::readAllBytes(*source);
        },
        path("beyond.tif"), "StripByteCounts");
    EXPECT_THAT(what, HasSubstr("strip 1 (65000 bytes at offset"));
}

TEST_F(TiffReaderTest, CorruptDeflateDataCarriesLibtiffsMessage) {
    if (!ready()) return;
    const std::string what = expectFormatError(
        [] {
            auto source = openTiff(path("corrupt_deflate.tif"), std::nullopt);
            test::readAllBytes(*source);
        },
        path("corrupt_deflate.tif"), "data");
    EXPECT_THAT(what, HasSubstr("page 2: strip 0 (deflate) cannot be read or decoded"));
    EXPECT_THAT(what, HasSubstr("(libtiff: "));
}

TEST_F(TiffReaderTest, RgbIsRefusedNamingSamplesPerPixel) {
    if (!ready()) return;
    expectFormatError([] { openTiff(path("rgb.tif"), std::nullopt); }, path("rgb.tif"),
                      "SamplesPerPixel");
}

TEST_F(TiffReaderTest, UnsupportedSampleTypesAreRefusedNamingTheField) {
    if (!ready()) return;
    expectFormatError([] { openTiff(path("bilevel.tif"), std::nullopt); }, path("bilevel.tif"),
                      "BitsPerSample");
    expectFormatError([] { openTiff(path("float64.tif"), std::nullopt); }, path("float64.tif"),
                      "BitsPerSample");
    const std::string what = expectFormatError([] { openTiff(path("uint32.tif"), std::nullopt); },
                                               path("uint32.tif"), "SampleFormat");
    EXPECT_THAT(what, HasSubstr("32-bit unsigned integer samples"));
}

TEST_F(TiffReaderTest, PaletteImageIsRefusedNamingPhotometricInterpretation) {
    if (!ready()) return;
    expectFormatError([] { openTiff(path("palette.tif"), std::nullopt); }, path("palette.tif"),
                      "PhotometricInterpretation");
}

TEST_F(TiffReaderTest, JpegIsRefusedNamingCompression) {
    if (!ready() || !haveTiffcp()) return;
    const std::string what = expectFormatError([] { openTiff(path("jpeg.tif"), std::nullopt); },
                                               path("jpeg.tif"), "Compression");
    EXPECT_THAT(what, HasSubstr("7 is not read"));
}

TEST_F(TiffReaderTest, ImageJHyperstackOfChannelsIsRefused) {
    if (!ready()) return;
    expectFormatError([] { openTiff(path("hyperstack.tif"), std::nullopt); },
                      path("hyperstack.tif"), "ImageDescription");
}

TEST_F(TiffReaderTest, NaNVoxelIsRefusedNamingPageAndVoxel) {
    if (!ready()) return;
    const std::string what = expectFormatError(
        [] {
            auto source = openTiff(path("nan.tif"), std::nullopt);
            test::readAllBytes(*source);
        },
        path("nan.tif"), "data");
    EXPECT_THAT(what, HasSubstr("page 2: voxel (3,2) is NaN"));
}

TEST_F(TiffReaderTest, NonTiffFileWithATifNameCarriesLibtiffsMessage) {
    if (!ready()) return;
    const std::string what = expectFormatError(
        [] { openTiff(path("not_a_tiff.tif"), std::nullopt); }, path("not_a_tiff.tif"), "header");
    EXPECT_THAT(what, HasSubstr("bad magic number"));
}

TEST_F(TiffReaderTest, EmptyFolderIsRefused) {
    if (!ready()) return;
    expectFormatError([] { openTiff(path("empty"), std::nullopt); }, path("empty"), "files");
}

} // namespace
} // namespace bc::brickstore
