// openHdf5: every shared scan written by h5py (tests/brickstore/writers/write_hdf5.py) in the
// layouts that matter (contiguous; chunked, gzip and shuffle; chunks that do not divide the
// volume; nested groups; big-endian types) ingests to exactly its voxels; direct reads of every
// type in every layout, spacing and uneven slice counts; and every bad input it refuses.
#include "brickstore/Error.h"
#include "brickstore/Readers.h"
#include "tests/TestSupport.h"
#include "tests/brickstore/FormatTestSupport.h"
#include "tests/brickstore/RawTestSupport.h"

#include <gmock/gmock.h>
#include <gtest/gtest.h>

#include <cmath>
#include <cstdint>
#include <cstring>
#include <filesystem>
#include <limits>
#include <string>
#include <vector>

namespace bc::brickstore {
namespace {

using test::Bytes;
using test::expectFormatError;
using test::patternVoxels;
using test::readAllBytes;
using ::testing::HasSubstr;
using ::testing::Not;

constexpr const char* kWriter = "brickstore/writers/write_hdf5.py";
constexpr const char* kModules = "h5py, numpy";
/// The small direct-test volume, x, y, z: z is cut by chunks of 3 and slabs of 1, 5 and 2.
constexpr std::array<std::uint64_t, 3> kDims{6, 5, 20};
constexpr std::uint64_t kVoxels = kDims[0] * kDims[1] * kDims[2];
const std::string kShape = "20,5,6"; // kDims as h5py's shape, [z][y][x]

/// One dataset argument of the writer: voxels of `raw` (NumPy `dtype`, shape z,y,x) stored
/// under `name`, with the writer's further options `extra`.
std::string datasetArg(const std::string& name, const std::string& raw, const std::string& dtype,
                       const std::string& shape, const std::string& extra = "") {
    return "name=" + name + " raw=" + raw + " dtype=" + dtype + " shape=" + shape + " " + extra;
}

void writeBytes(const std::string& path, const Bytes& bytes) {
    test::writeFile(path, bytes.data(), bytes.size());
}

SourceSpec hdf5Spec(const std::string& path, const std::string& dataset) {
    SourceSpec spec;
    spec.input = path;
    spec.dataset = dataset;
    return spec;
}

/// How one shared scan is written: the format's variants spread over the scans.
struct RoundTrip {
    std::string scan;    ///< SharedScan::name
    std::string dataset; ///< where it is stored
    std::string options; ///< the writer's storage options
};

class Hdf5RoundTripTest : public ::testing::TestWithParam<RoundTrip> {};

TEST_P(Hdf5RoundTripTest, IngestsToTheSourceVoxels) {
    if (!test::pythonHas(kModules)) return;
    const RoundTrip& c = GetParam();
    test::SharedScan scan;
    for (const test::SharedScan& s : test::sharedScans())
        if (s.name == c.scan) scan = s;
    ASSERT_EQ(scan.name, c.scan);
    if (!test::haveData(scan.file)) return test::missingData(scan.file);
    test::TempDir dir;
    const VolumeInfo info = test::dumpRaw(test::sharedSpec(scan), dir.file("scan.raw"));
    const std::string shape = std::to_string(info.dims[2]) + "," + std::to_string(info.dims[1]) +
                              "," + std::to_string(info.dims[0]);
    const std::string h5 = dir.file(c.scan + ".h5");
    ASSERT_TRUE(
        test::runPython(kWriter, {"file=" + h5, datasetArg(c.dataset, dir.file("scan.raw"),
                                                           scan.dataType, shape, c.options)}));
    test::expectIngestsToSameVoxels(test::sharedSpec(scan), hdf5Spec(h5, c.dataset),
                                    c.scan + " " + c.options);
}

INSTANTIATE_TEST_SUITE_P(
    SharedScans, Hdf5RoundTripTest,
    ::testing::Values(
        RoundTrip{"cthead", "/entry/data/volume", "layout=contiguous"},
        RoundTrip{"headsq", "/volume", "store=>u2 layout=chunked chunks=16,16,16 gzip=4 shuffle=1"},
        RoundTrip{"frog", "/exchange/data", "layout=chunked chunks=10,37,64 gzip=1"},
        RoundTrip{"ct_avm", "/a/b/c/d", "layout=chunked chunks=32,64,64"},
        RoundTrip{"iguana", "/data", "layout=contiguous"},
        RoundTrip{"pancreas", "/ct", "store=>i2 layout=chunked chunks=7,100,128 gzip=1 shuffle=1"},
        RoundTrip{"hydrogen", "/density", "store=>f4 layout=contiguous"},
        RoundTrip{"gaffer", "/smoke/density", "store=>f4 layout=chunked chunks=9,50,30 gzip=2"}),
    [](const ::testing::TestParamInfo<RoundTrip>& info) { return info.param.scan; });

TEST(Hdf5ReaderTest, InfoNamesDimsTypeSpacingAndLayout) {
    if (!test::pythonHas(kModules)) return;
    test::TempDir dir;
    const Bytes host = patternVoxels(VoxelType::U16, kVoxels);
    writeBytes(dir.file("v.raw"), host);
    const std::string h5 = dir.file("scan.h5");
    ASSERT_TRUE(test::runPython(
        kWriter, {"file=" + h5, datasetArg("/entry/data/v", dir.file("v.raw"), "uint16", kShape,
                                           "store=>u2 layout=chunked chunks=3,2,4 gzip=4 shuffle=1 "
                                           "um=2,0.5,0.25")}));
    auto source = openHdf5(h5, "entry/data/v");
    EXPECT_EQ(source->info().dims, kDims);
    EXPECT_EQ(source->info().type, VoxelType::U16);
    EXPECT_EQ(source->info().spacingMm, (std::array<double, 3>{0.00025, 0.0005, 0.002}));
    EXPECT_THAT(source->info().description, HasSubstr("HDF5 scan.h5 /entry/data/v"));
    EXPECT_THAT(source->info().description, HasSubstr("u16 big-endian"));
    EXPECT_THAT(source->info().description, HasSubstr("chunked 4x2x3 shuffle+gzip"));
    EXPECT_EQ(readAllBytes(*source, {1, 5, 2}), host);
    EXPECT_EQ(readAllBytes(*openHdf5(h5, "/entry/data/v"), {20}), host);
    EXPECT_EQ(readAllBytes(*openSource(hdf5Spec(h5, "/entry/data/v")), {3}), host);
}

/// i8 voxels widened to host-order i16, as the reader delivers them.
Bytes widenedI8(const Bytes& i8) {
    Bytes out(i8.size() * 2);
    for (std::size_t i = 0; i < i8.size(); ++i) {
        const auto v = std::int16_t(std::int8_t(i8[i]));
        std::memcpy(out.data() + 2 * i, &v, 2);
    }
    return out;
}

TEST(Hdf5ReaderTest, ReadsEveryTypeInEveryLayout) {
    if (!test::pythonHas(kModules)) return;
    test::TempDir dir;
    struct TypeCase {
        std::string raw, dtype, store;
        VoxelType type;
    };
    // f16 is written from f32 voxels that it holds exactly (quarter steps below 32).
    const std::vector<TypeCase> types = {{"u8.raw", "uint8", "|u1", VoxelType::U8},
                                         {"u16.raw", "uint16", "<u2", VoxelType::U16},
                                         {"u16.raw", "uint16", ">u2", VoxelType::U16},
                                         {"i16.raw", "int16", "<i2", VoxelType::I16},
                                         {"i16.raw", "int16", ">i2", VoxelType::I16},
                                         {"f32.raw", "float32", "<f4", VoxelType::F32},
                                         {"f32.raw", "float32", ">f4", VoxelType::F32},
                                         {"u8.raw", "int8", "|i1", VoxelType::I16},
                                         {"f32.raw", "float32", ">f2", VoxelType::F32}};
    for (VoxelType t : {VoxelType::U8, VoxelType::U16, VoxelType::I16, VoxelType::F32})
        writeBytes(dir.file(std::string(voxelTypeName(t)) + ".raw"), patternVoxels(t, kVoxels));
    const std::vector<std::string> layouts = {"layout=contiguous", "layout=compact",
                                              "layout=chunked chunks=7,3,4 gzip=1 shuffle=1"};
    std::vector<std::string> args = {"file=" + dir.file("types.h5")};
    for (std::size_t t = 0; t < types.size(); ++t)
        for (std::size_t l = 0; l < layouts.size(); ++l)
            args.push_back(datasetArg("/t" + std::to_string(t) + "/l" + std::to_string(l),
                                      dir.file(types[t].raw), types[t].dtype, kShape,
                                      "store=" + types[t].store + " " + layouts[l]));
    ASSERT_TRUE(test::runPython(kWriter, args));
    for (std::size_t t = 0; t < types.size(); ++t) {
        const Bytes raw = test::readFile(dir.file(types[t].raw));
        const Bytes want = types[t].dtype == "int8" ? widenedI8(raw) : raw;
        for (std::size_t l = 0; l < layouts.size(); ++l) {
            const std::string name = "/t" + std::to_string(t) + "/l" + std::to_string(l);
            auto source = openHdf5(dir.file("types.h5"), name);
            EXPECT_EQ(source->info().type, types[t].type) << types[t].store << " " << layouts[l];
            EXPECT_EQ(readAllBytes(*source, {3, 1}), want) << types[t].store << " " << layouts[l];
        }
    }
}

/// A file of several datasets, for the errors that must list the volumes it holds.
class Hdf5BadInputTest : public ::testing::Test {
  protected:
    void SetUp() override {
        if (!test::pythonHas(kModules)) return;
        writeBytes(mDir.file("u16.raw"), patternVoxels(VoxelType::U16, kVoxels));
        Bytes f32 = patternVoxels(VoxelType::F32, kVoxels);
        const float nan = std::numeric_limits<float>::quiet_NaN();
        std::memcpy(f32.data() + 4 * 37, &nan, 4);
        writeBytes(mDir.file("nan.raw"), f32);
        const std::string u16 = mDir.file("u16.raw");
        mReady = test::runPython(
            kWriter,
            {"file=" + mPath, datasetArg("/a/vol", u16, "uint16", kShape),
             datasetArg("/b/img", u16, "uint16", "30,20"),
             datasetArg("/c/wide", u16, "uint16", kShape, "store=<i8"),
             datasetArg("/d/vol2", mDir.file("nan.raw"), "float32", kShape,
                        "layout=chunked chunks=4,5,6"),
             datasetArg("/e/badspacing", u16, "uint16", kShape, "um=1,2"),
             "name=/f/ext external=other.h5:/vol", "file=" + mDir.file("other.h5"),
             datasetArg("/vol", u16, "uint16", kShape),
             "file=" + mDir.file("filter.h5") + " patch_filter=60001",
             datasetArg("/vol", u16, "uint16", kShape, "layout=chunked chunks=4,5,6 gzip=1")});
    }
    test::TempDir mDir;
    std::string mPath = mDir.file("several.h5");
    bool mReady = false;
};

TEST_F(Hdf5BadInputTest, MissingOrEmptyDatasetListsTheFilesVolumes) {
    if (!mReady) return;
    for (const std::string name : {"/nope", "", "/a/vol/below", "/e"}) {
        const std::string what =
            expectFormatError([&] { openHdf5(mPath, name); }, mPath, "dataset");
        EXPECT_THAT(what, HasSubstr("--dataset: /a/vol (6x5x20 u16), /d/vol2 (6x5x20 f32)"));
        EXPECT_THAT(what, Not(HasSubstr("/b/img"))) << "a 2D dataset is no volume";
        EXPECT_THAT(what, Not(HasSubstr("/c/wide"))) << "int64 is no supported type";
    }
    EXPECT_THAT(expectFormatError([&] { openHdf5(mPath, "/e"); }, mPath, "dataset"),
                HasSubstr("\"/e\" is a group, not a dataset"));
}

TEST_F(Hdf5BadInputTest, TwoDimensionalDatasetIsARankError) {
    if (!mReady) return;
    EXPECT_THAT(expectFormatError([&] { openHdf5(mPath, "/b/img"); }, mPath, "dataspace"),
                HasSubstr("rank 2 (shape 30x20)"));
}

TEST_F(Hdf5BadInputTest, UnsupportedTypeIsNamed) {
    if (!mReady) return;
    EXPECT_THAT(expectFormatError([&] { openHdf5(mPath, "/c/wide"); }, mPath, "type"),
                HasSubstr("holds i64"));
}

TEST_F(Hdf5BadInputTest, UnavailableFilterIsNamedBeforeReading) {
    if (!mReady) return;
    const std::string path = mDir.file("filter.h5");
    EXPECT_THAT(expectFormatError([&] { openHdf5(path, "/vol"); }, path, "filter"),
                HasSubstr("filter 60001 (\"private\")"));
}

TEST_F(Hdf5BadInputTest, ExternalLinkIsNotFollowed) {
    if (!mReady) return;
    EXPECT_THAT(expectFormatError([&] { openHdf5(mPath, "/f/ext"); }, mPath, "dataset"),
                HasSubstr("external link"));
}

TEST_F(Hdf5BadInputTest, BadElementSizeIsNamed) {
    if (!mReady) return;
    EXPECT_THAT(
        expectFormatError([&] { openHdf5(mPath, "/e/badspacing"); }, mPath, "element_size_um"),
        HasSubstr("holds 2 values"));
}

TEST_F(Hdf5BadInputTest, NanVoxelIsNamed) {
    if (!mReady) return;
    auto source = openHdf5(mPath, "/d/vol2");
    EXPECT_THAT(expectFormatError([&] { readAllBytes(*source, {4}); }, mPath, "data"),
                HasSubstr("voxel (1,1,1) of \"/d/vol2\" is NaN"));
}

TEST_F(Hdf5BadInputTest, TruncatedFileIsNamed) {
    if (!mReady) return;
    Bytes bytes = test::readFile(mPath);
    for (const std::size_t keep : {bytes.size() - 1, bytes.size() / 2, std::size_t(100)}) {
        const std::string cut = mDir.file("cut.h5");
        test::writeFile(cut, bytes.data(), keep);
        EXPECT_THAT(expectFormatError([&] { openHdf5(cut, "/a/vol"); }, cut, "file"),
                    HasSubstr("truncated"))
            << keep << " bytes kept";
    }
}

/// A file of `bytes` or fewer holding one u8 dataset "/v" of `shape` (z,y,x) whose voxels were
/// never written: `layout` "chunked" (64^3 chunks, none allocated) or "contiguous".
std::string declaredOnly(const test::TempDir& dir, const std::string& shape,
                         const std::string& layout, std::uint64_t bytes) {
    const std::string h5 = dir.file(layout + ".h5");
    const std::string chunks = layout == "chunked" ? " chunks=64,64,64" : "";
    EXPECT_TRUE(test::runPython(kWriter, {"file=" + h5, "name=/v dtype=uint8 shape=" + shape +
                                                            " layout=" + layout + chunks}));
    EXPECT_LE(std::filesystem::file_size(h5), bytes);
    return h5;
}

// A dataspace whose voxels the file does not hold, refused when opened, within a second: the
// ingest of either used to run for minutes on fill values.

TEST(Hdf5ReaderTest, TerabyteDatasetWithoutChunksIsRefusedWhenOpened) {
    if (!test::pythonHas(kModules)) return;
    test::TempDir dir;
    const std::string h5 = declaredOnly(dir, "1048576,1024,1024", "chunked", 1500);
    const std::string what = test::expectRefusedAtOnce([&] { openHdf5(h5, "/v"); }, h5, "storage");
    EXPECT_THAT(what, HasSubstr("\"/v\""));
    EXPECT_THAT(what, HasSubstr("1024x1024x1048576 u8"));
    EXPECT_THAT(what, HasSubstr("--max-expansion"));
}

TEST(Hdf5ReaderTest, UnwrittenDatasetOf4096CubedIsRefusedWhenOpened) {
    if (!test::pythonHas(kModules)) return;
    for (const std::string layout : {"chunked", "contiguous"}) {
        test::TempDir dir;
        const std::string h5 = declaredOnly(dir, "4096,4096,4096", layout, 2000);
        EXPECT_THAT(
            test::expectRefusedAtOnce([&] { openSource(hdf5Spec(h5, "/v")); }, h5, "storage"),
            HasSubstr("4096x4096x4096 u8"))
            << layout;
    }
}

TEST(Hdf5ReaderTest, RaisedExpansionLimitLetsADatasetOfOneChunkOpen) {
    if (!test::pythonHas(kModules)) return;
    test::TempDir dir;
    const std::string h5 = dir.file("one.h5");
    ASSERT_TRUE(test::runPython(kWriter, {"file=" + h5, "name=/v dtype=uint8 "
                                                        "shape=4096,4096,4096 layout=chunked "
                                                        "chunks=64,64,64 first=64"}));
    // One 64^3 chunk of 4096^3: 262144 times what it holds.
    EXPECT_THAT(test::expectRefusedAtOnce([&] { openHdf5(h5, "/v"); }, h5, "storage"),
                HasSubstr("hold only 262.1 kB"));
    InputLimits limits;
    limits.maxExpansion = 1ull << 18;
    const test::InputLimitsGuard guard(limits);
    auto source = openHdf5(h5, "/v");
    EXPECT_EQ(source->info().dims, (std::array<std::uint64_t, 3>{4096, 4096, 4096}));
    std::vector<std::byte> slice(4096 * 4096);
    source->readSlices(1, slice);
    EXPECT_EQ(slice[63], std::byte{7});
    EXPECT_EQ(slice[64], std::byte{0});
}

TEST(Hdf5ReaderTest, NonHdf5FileWithAnH5NameIsNamed) {
    test::TempDir dir;
    const std::string path = dir.file("notes.h5");
    test::writeFile(path, std::string("NRRD0004\nthis is not HDF5\n") + std::string(2000, 'x'));
    EXPECT_THAT(expectFormatError([&] { openSource(hdf5Spec(path, "/v")); }, path, "file"),
                HasSubstr("not an HDF5 file"));
}

} // namespace
} // namespace bc::brickstore
