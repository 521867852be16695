// openNifti on the two real NIfTI-1 scans (checked against a raw copy and against an
// independent zlib decode) and on small headers built here, one per bad input.
#include "brickstore/Error.h"
#include "brickstore/Readers.h"
#include "tests/TestSupport.h"
#include "tests/brickstore/VolumeTestSupport.h"

#include <algorithm>
#include <cmath>
#include <cstring>
#include <limits>
#include <vector>

#include <zlib.h>
// The test target does not get niftilib's include folder; <nifti/...> reaches it from /usr/include.
#include <nifti/nifti1.h>

namespace bc::brickstore {
namespace {

using bc::test::TempDir;

/// Reads the whole volume through the reader in uneven steps (1, 7, 32, ... slices).
std::vector<std::byte> readAllSlices(VolumeSource& source) {
    return test::readAllSlices(source, {1, 7, 32});
}

/// A valid single-file header: `dims` voxels of `datatype`, 1 mm spacing, voxels at byte 352.
nifti_1_header makeHeader(std::array<short, 3> dims, short datatype, short bitpix) {
    nifti_1_header hdr;
    std::memset(&hdr, 0, sizeof(hdr));
    hdr.sizeof_hdr = 348;
    hdr.dim[0] = 3;
    for (int i = 0; i < 3; ++i)
        hdr.dim[i + 1] = dims[i];
    for (int i = 4; i < 8; ++i)
        hdr.dim[i] = 1;
    hdr.datatype = datatype;
    hdr.bitpix = bitpix;
    for (int i = 0; i < 8; ++i)
        hdr.pixdim[i] = 1.0f;
    hdr.vox_offset = 352.0f;
    std::memcpy(hdr.magic, "n+1", 4);
    return hdr;
}

/// Header, the 4-byte extension flag (no extensions), then the voxel bytes.
template <typename T>
void writeNifti(const std::string& path, const nifti_1_header& hdr, const std::vector<T>& voxels) {
    std::vector<char> bytes(352 + voxels.size() * sizeof(T), 0);
    std::memcpy(bytes.data(), &hdr, sizeof(hdr));
    if (!voxels.empty()) std::memcpy(bytes.data() + 352, voxels.data(), voxels.size() * sizeof(T));
    bc::test::writeFile(path, bytes.data(), bytes.size());
}

std::vector<std::uint8_t> rampU8(std::size_t n) {
    std::vector<std::uint8_t> v(n);
    for (std::size_t i = 0; i < n; ++i)
        v[i] = std::uint8_t(i * 37 % 256);
    return v;
}

/// Expects openNifti (and a full read) to throw FormatError naming `path` and `field`.
void expectFormatError(const std::string& path, const std::string& field) {
    try {
        auto source = openNifti(path);
        readAllSlices(*source);
        FAIL() << "no FormatError for " << path;
    } catch (const FormatError& e) {
        EXPECT_EQ(e.file(), path);
        EXPECT_EQ(e.field(), field) << e.what();
        EXPECT_NE(std::string(e.what()).find(path), std::string::npos) << e.what();
        EXPECT_NE(std::string(e.what()).find(field), std::string::npos) << e.what();
    }
}

template <typename T> std::vector<T> asVector(const std::vector<std::byte>& bytes) {
    std::vector<T> v(bytes.size() / sizeof(T));
    std::memcpy(v.data(), bytes.data(), v.size() * sizeof(T));
    return v;
}

/// The first `bytes` bytes of a gzip file, decoded with zlib directly.
std::vector<std::uint8_t> gunzip(const std::string& path,
                                 std::size_t bytes = std::numeric_limits<std::size_t>::max()) {
    std::vector<std::uint8_t> file;
    gzFile gz = gzopen(path.c_str(), "rb");
    EXPECT_NE(gz, nullptr) << path;
    if (!gz) return file;
    std::vector<std::uint8_t> buffer(1 << 20);
    while (file.size() < bytes) {
        const int got =
            gzread(gz, buffer.data(), unsigned(std::min(buffer.size(), bytes - file.size())));
        if (got <= 0) break;
        file.insert(file.end(), buffer.begin(), buffer.begin() + got);
    }
    gzclose(gz);
    return file;
}

/// A little-endian float of the 348-byte header, read from its byte offset.
float headerFloat(const std::vector<std::uint8_t>& file, std::size_t offset) {
    float v = 0;
    std::memcpy(&v, file.data() + offset, sizeof(v)); // little-endian file, little-endian host
    return v;
}

// CT_AVM.nii.gz stores the raw file's bytes with scl_slope 2.2086 (scl_inter 0). The reader
// keeps the u8 voxels as they are and records the slope (physical = stored x slope + inter)
// instead of growing the volume into f32; checked against every raw byte and the header.
TEST(NiftiReaderTest, CtAvmKeepsItsRawBytesAndRecordsSclSlope) {
    if (!bc::test::haveData("CT_AVM.nii.gz")) return bc::test::missingData("CT_AVM.nii.gz");
    const std::string path = bc::test::dataPath("CT_AVM.nii.gz");
    auto source = openNifti(path);
    const VolumeInfo& info = source->info();
    EXPECT_EQ(info.dims, (std::array<std::uint64_t, 3>{256, 242, 154}));
    EXPECT_NEAR(info.spacingMm[0], 0.72, 1e-3);
    EXPECT_NEAR(info.spacingMm[1], 0.721, 1e-3);
    EXPECT_NEAR(info.spacingMm[2], 1.0, 1e-3);
    EXPECT_NE(info.description.find("CT_AVM.nii.gz, u8 with scl_slope 2.20863"), std::string::npos)
        << info.description;

    const std::vector<std::uint8_t> header = gunzip(path, 348);
    ASSERT_EQ(header.size(), 348u);
    const double slope = headerFloat(header, 112), inter = headerFloat(header, 116);
    ASSERT_NEAR(slope, 2.2086, 1e-4);
    ASSERT_EQ(inter, 0.0);
    ASSERT_EQ(info.type, VoxelType::U8);
    EXPECT_EQ(info.valueScale, slope);
    EXPECT_EQ(info.valueOffset, inter);

    const std::vector<std::uint8_t> voxels = asVector<std::uint8_t>(readAllSlices(*source));
    const std::vector<std::uint8_t> raw =
        bc::test::readFile(bc::test::dataPath("CT_AVM_256x242x154_uint8.raw"));
    EXPECT_TRUE(voxels == raw);
}

TEST(NiftiReaderTest, IguanaMatchesAnIndependentGzipDecode) {
    if (!bc::test::haveData("Iguana.nii.gz")) return bc::test::missingData("Iguana.nii.gz");
    const std::string path = bc::test::dataPath("Iguana.nii.gz");
    auto source = openNifti(path);
    const VolumeInfo& info = source->info();
    EXPECT_EQ(info.dims, (std::array<std::uint64_t, 3>{210, 256, 179}));
    EXPECT_EQ(info.type, VoxelType::U8);
    for (double s : info.spacingMm)
        EXPECT_NEAR(s, 0.102, 1e-3);

    const std::vector<std::uint8_t> file = gunzip(path);
    ASSERT_GE(file.size(), 348u);
    const float slope = headerFloat(file, 112), inter = headerFloat(file, 116);
    EXPECT_TRUE((slope == 0.0f || slope == 1.0f) &&
                inter == 0.0f); // identity: the bytes are the values
    const float voxOffset = headerFloat(file, 108);
    const std::size_t offset = std::size_t(voxOffset);
    ASSERT_EQ(file.size() - offset, info.voxelCount());

    const std::vector<std::byte> voxels = readAllSlices(*source);
    EXPECT_EQ(std::memcmp(voxels.data(), file.data() + offset, voxels.size()), 0);
}

TEST(NiftiReaderTest, ZeroDimensionIsRejected) {
    TempDir dir;
    nifti_1_header hdr = makeHeader({4, 0, 3}, DT_UINT8, 8);
    writeNifti(dir.file("zero.nii"), hdr, std::vector<std::uint8_t>{});
    expectFormatError(dir.file("zero.nii"), "dims");
}

TEST(NiftiReaderTest, NegativeDimensionIsRejected) {
    TempDir dir;
    nifti_1_header hdr = makeHeader({4, -2, 3}, DT_UINT8, 8);
    writeNifti(dir.file("negative.nii"), hdr, rampU8(24));
    expectFormatError(dir.file("negative.nii"), "dims");
}

TEST(NiftiReaderTest, NanSpacingIsRejected) {
    TempDir dir;
    nifti_1_header hdr = makeHeader({4, 3, 2}, DT_UINT8, 8);
    hdr.pixdim[2] = std::numeric_limits<float>::quiet_NaN();
    writeNifti(dir.file("nan.nii"), hdr, rampU8(24));
    expectFormatError(dir.file("nan.nii"), "spacing");
}

TEST(NiftiReaderTest, NegativeSpacingIsRejected) {
    TempDir dir;
    nifti_1_header hdr = makeHeader({4, 3, 2}, DT_UINT8, 8);
    hdr.pixdim[3] = -2.0f;
    writeNifti(dir.file("negative.nii"), hdr, rampU8(24));
    expectFormatError(dir.file("negative.nii"), "spacing");
}

TEST(NiftiReaderTest, ZeroSpacingIsRejected) {
    TempDir dir;
    nifti_1_header hdr = makeHeader({4, 3, 2}, DT_UINT8, 8);
    hdr.pixdim[1] = 0.0f;
    writeNifti(dir.file("zero.nii"), hdr, rampU8(24));
    expectFormatError(dir.file("zero.nii"), "spacing");
}

TEST(NiftiReaderTest, ComplexAndRgbDatatypesAreRejected) {
    TempDir dir;
    writeNifti(dir.file("complex.nii"), makeHeader({2, 2, 2}, DT_COMPLEX64, 64),
               std::vector<float>(16, 1.0f));
    expectFormatError(dir.file("complex.nii"), "datatype");
    writeNifti(dir.file("rgb.nii"), makeHeader({2, 2, 2}, DT_RGB24, 24), rampU8(24));
    expectFormatError(dir.file("rgb.nii"), "datatype");
}

TEST(NiftiReaderTest, UnknownDatatypeIsRejected) {
    TempDir dir;
    writeNifti(dir.file("unknown.nii"), makeHeader({2, 2, 2}, 9999, 8), rampU8(8));
    expectFormatError(dir.file("unknown.nii"), "datatype");
}

// NIfTI-1 dims are int16, so a header cannot express a volume whose byte size overflows 64
// bits; the reachable form of "a header promising more than the file holds" is truncation.
TEST(NiftiReaderTest, TruncatedDataIsRejectedBeforeReading) {
    TempDir dir;
    writeNifti(dir.file("short.nii"), makeHeader({64, 64, 64}, DT_INT16, 16),
               std::vector<std::int16_t>(1000, 5));
    expectFormatError(dir.file("short.nii"), "data");
}

TEST(NiftiReaderTest, TruncatedGzipDataIsRejectedWhenRead) {
    TempDir dir;
    const nifti_1_header hdr = makeHeader({32, 32, 8}, DT_UINT8, 8);
    const std::string path = dir.file("short.nii.gz");
    gzFile gz = gzopen(path.c_str(), "wb");
    ASSERT_NE(gz, nullptr);
    const char pad[4] = {0, 0, 0, 0};
    const std::vector<std::uint8_t> half = rampU8(32 * 32 * 4);
    gzwrite(gz, &hdr, sizeof(hdr));
    gzwrite(gz, pad, sizeof(pad));
    gzwrite(gz, half.data(), unsigned(half.size()));
    gzclose(gz);
    auto source = openNifti(path); // a gzip stream's length is only known by reading it
    std::vector<std::byte> slices(4 * source->info().sliceBytes());
    source->readSlices(4, slices);
    try {
        source->readSlices(4, slices);
        FAIL() << "no FormatError for the missing slices";
    } catch (const FormatError& e) {
        EXPECT_EQ(e.file(), path);
        EXPECT_EQ(e.field(), "data");
        EXPECT_NE(std::string(e.what()).find("slice 4"), std::string::npos) << e.what();
    }
}

TEST(NiftiReaderTest, VoxOffsetInsideTheHeaderIsRejected) {
    TempDir dir;
    nifti_1_header hdr = makeHeader({2, 2, 2}, DT_UINT8, 8);
    hdr.vox_offset = 100.0f;
    writeNifti(dir.file("offset.nii"), hdr, rampU8(8));
    expectFormatError(dir.file("offset.nii"), "vox_offset");
}

TEST(NiftiReaderTest, NotNiftiIsRejected) {
    TempDir dir;
    nifti_1_header hdr = makeHeader({2, 2, 2}, DT_UINT8, 8);
    std::memcpy(hdr.magic, "xyz", 4);
    writeNifti(dir.file("magic.nii"), hdr, rampU8(8));
    expectFormatError(dir.file("magic.nii"), "magic");
    bc::test::writeFile(dir.file("tiny.nii"), "not a nifti file");
    expectFormatError(dir.file("tiny.nii"), "header");
}

TEST(NiftiReaderTest, Int32IsConvertedToF32) {
    TempDir dir;
    const std::vector<std::int32_t> values = {-70000, 0, 1, 2, 100000, 7, -3, 123456789};
    writeNifti(dir.file("i32.nii"), makeHeader({2, 2, 2}, DT_INT32, 32), values);
    auto source = openNifti(dir.file("i32.nii"));
    EXPECT_EQ(source->info().type, VoxelType::F32);
    EXPECT_NE(source->info().description.find("int32 converted to f32"), std::string::npos)
        << source->info().description;
    const std::vector<float> read = asVector<float>(readAllSlices(*source));
    for (std::size_t i = 0; i < values.size(); ++i)
        EXPECT_EQ(read[i], float(values[i]));
}

TEST(NiftiReaderTest, Float64IsConvertedToF32) {
    TempDir dir;
    const std::vector<double> values = {0.5, -1.25, 3.0e10, 1e-3, 2, 3, 4, 5};
    writeNifti(dir.file("f64.nii"), makeHeader({2, 2, 2}, DT_FLOAT64, 64), values);
    auto source = openNifti(dir.file("f64.nii"));
    EXPECT_EQ(source->info().type, VoxelType::F32);
    const std::vector<float> read = asVector<float>(readAllSlices(*source));
    for (std::size_t i = 0; i < values.size(); ++i)
        EXPECT_EQ(read[i], float(values[i]));
}

TEST(NiftiReaderTest, IntegerScalingThatFitsGivesI16) {
    TempDir dir;
    nifti_1_header hdr = makeHeader({4, 2, 2}, DT_UINT8, 8);
    hdr.scl_slope = 1.0f;
    hdr.scl_inter = -1024.0f;
    const std::vector<std::uint8_t> values = rampU8(16);
    writeNifti(dir.file("scaled.nii"), hdr, values);
    auto source = openNifti(dir.file("scaled.nii"));
    EXPECT_EQ(source->info().type, VoxelType::I16);
    EXPECT_NE(source->info().description.find("scl_inter -1024"), std::string::npos)
        << source->info().description;
    const std::vector<std::int16_t> read = asVector<std::int16_t>(readAllSlices(*source));
    for (std::size_t i = 0; i < values.size(); ++i)
        EXPECT_EQ(read[i], values[i] - 1024);
}

TEST(NiftiReaderTest, ScalingThatIsNotAnExactI16MapIsRecordedNotApplied) {
    TempDir dir;
    nifti_1_header hdr = makeHeader({2, 2, 2}, DT_INT16, 16);
    hdr.scl_slope = 1.0f;
    hdr.scl_inter = -1024.0f; // the int16 range shifted by -1024 leaves i16
    const std::vector<std::int16_t> values = {-32768, 0, 5, 32767, 1, 2, 3, 4};
    writeNifti(dir.file("wide.nii"), hdr, values);
    auto source = openNifti(dir.file("wide.nii"));
    EXPECT_EQ(source->info().type, VoxelType::I16);
    EXPECT_EQ(source->info().valueScale, 1.0);
    EXPECT_EQ(source->info().valueOffset, -1024.0);
    EXPECT_TRUE(asVector<std::int16_t>(readAllSlices(*source)) == values);

    hdr = makeHeader({2, 2, 2}, DT_UINT8, 8);
    hdr.scl_slope = 0.5f; // not an integer
    writeNifti(dir.file("half.nii"), hdr, rampU8(8));
    auto half = openNifti(dir.file("half.nii"));
    EXPECT_EQ(half->info().type, VoxelType::U8);
    EXPECT_EQ(half->info().valueScale, 0.5);
    EXPECT_TRUE(asVector<std::uint8_t>(readAllSlices(*half)) == rampU8(8));

    hdr = makeHeader({2, 2, 2}, DT_INT32, 32); // converted anyway: scaling applied in f32
    hdr.scl_slope = 0.5f;
    const std::vector<std::int32_t> wide = {0, 2, 4, 6, 8, 10, 12, 100000};
    writeNifti(dir.file("i32.nii"), hdr, wide);
    auto converted = openNifti(dir.file("i32.nii"));
    EXPECT_EQ(converted->info().type, VoxelType::F32);
    EXPECT_EQ(converted->info().valueScale, 1.0);
    const std::vector<float> read = asVector<float>(readAllSlices(*converted));
    for (std::size_t i = 0; i < wide.size(); ++i)
        EXPECT_EQ(read[i], float(wide[i]) * 0.5f);
}

TEST(NiftiReaderTest, IdentityScalingKeepsTheNativeType) {
    TempDir dir;
    nifti_1_header hdr = makeHeader({2, 2, 2}, DT_UINT16, 16);
    hdr.scl_slope = 1.0f;
    hdr.scl_inter = 0.0f;
    const std::vector<std::uint16_t> values = {0, 1, 65535, 300, 4, 5, 6, 7};
    writeNifti(dir.file("u16.nii"), hdr, values);
    auto source = openNifti(dir.file("u16.nii"));
    EXPECT_EQ(source->info().type, VoxelType::U16);
    EXPECT_EQ(asVector<std::uint16_t>(readAllSlices(*source)), values);
}

TEST(NiftiReaderTest, NanVoxelIsRejectedWhenRead) {
    TempDir dir;
    std::vector<float> values(8, 1.0f);
    values[5] = std::numeric_limits<float>::quiet_NaN();
    writeNifti(dir.file("nanvoxel.nii"), makeHeader({2, 2, 2}, DT_FLOAT32, 32), values);
    expectFormatError(dir.file("nanvoxel.nii"), "data");
}

TEST(NiftiReaderTest, BigEndianFileIsSwapped) {
    TempDir dir;
    nifti_1_header hdr = makeHeader({3, 2, 2}, DT_INT16, 16);
    hdr.pixdim[1] = 0.5f;
    std::vector<std::int16_t> values = {-2, -1, 0, 1, 2, 300, -300, 32767, -32768, 9, 10, 11};
    auto swap = [](auto& v) {
        auto* b = reinterpret_cast<unsigned char*>(&v);
        std::reverse(b, b + sizeof(v));
    };
    std::vector<std::int16_t> swapped = values;
    for (auto& v : swapped)
        swap(v);
    swap(hdr.sizeof_hdr);
    for (auto& d : hdr.dim)
        swap(d);
    swap(hdr.datatype);
    swap(hdr.bitpix);
    for (auto& p : hdr.pixdim)
        swap(p);
    swap(hdr.vox_offset);
    writeNifti(dir.file("be.nii"), hdr, swapped);
    auto source = openNifti(dir.file("be.nii"));
    EXPECT_EQ(source->info().dims, (std::array<std::uint64_t, 3>{3, 2, 2}));
    EXPECT_EQ(source->info().type, VoxelType::I16);
    EXPECT_DOUBLE_EQ(source->info().spacingMm[0], 0.5);
    EXPECT_EQ(asVector<std::int16_t>(readAllSlices(*source)), values);
}

TEST(NiftiReaderTest, FourDimensionalFileGivesItsFirstVolume) {
    TempDir dir;
    nifti_1_header hdr = makeHeader({2, 2, 2}, DT_UINT8, 8);
    hdr.dim[0] = 4;
    hdr.dim[4] = 3;
    const std::vector<std::uint8_t> values = rampU8(24);
    writeNifti(dir.file("4d.nii"), hdr, values);
    auto source = openNifti(dir.file("4d.nii"));
    EXPECT_NE(source->info().description.find("first of 3 volumes"), std::string::npos);
    const std::vector<std::uint8_t> read = asVector<std::uint8_t>(readAllSlices(*source));
    EXPECT_EQ(read, std::vector<std::uint8_t>(values.begin(), values.begin() + 8));
}

} // namespace
// A non-finite scl_slope or scl_inter is an error naming the file and that field,
// worded plainly (it used to be read as "no scaling" with a description that ran two type
// names together).
TEST(NiftiReaderTest, NonFiniteScalingIsAClearErrorNamingTheField) {
    TempDir dir;
    const float bad[] = {std::numeric_limits<float>::quiet_NaN(),
                         std::numeric_limits<float>::infinity()};
    for (float value : bad) {
        for (const char* field : {"scl_slope", "scl_inter"}) {
            nifti_1_header hdr = makeHeader({4, 2, 2}, DT_UINT8, 8);
            hdr.scl_slope = 1.0f;
            (std::string(field) == "scl_slope" ? hdr.scl_slope : hdr.scl_inter) = value;
            const std::string path = dir.file("bad.nii");
            writeNifti(path, hdr, rampU8(16));
            expectFormatError(path, field);
            try {
                openNifti(path);
            } catch (const FormatError& e) {
                const std::string what = e.what();
                EXPECT_NE(what.find(std::isnan(value) ? "nan" : "inf"), std::string::npos) << what;
                EXPECT_NE(what.find("is not a finite number"), std::string::npos) << what;
            }
        }
    }
}

TEST(NiftiReaderTest, DescriptionNamesEachTypeOnce) {
    TempDir dir;
    writeNifti(dir.file("plain.nii"), makeHeader({4, 2, 2}, DT_UINT8, 8), rampU8(16));
    EXPECT_EQ(openNifti(dir.file("plain.nii"))->info().description, "NIfTI-1 plain.nii, u8");
    nifti_1_header hdr = makeHeader({4, 2, 2}, DT_UINT8, 8);
    hdr.scl_slope = 2.0f;
    hdr.scl_inter = -1024.0f;
    writeNifti(dir.file("scaled.nii"), hdr, rampU8(16));
    EXPECT_EQ(openNifti(dir.file("scaled.nii"))->info().description,
              "NIfTI-1 scaled.nii, uint8 scaled by scl_slope 2, scl_inter -1024 to i16");
}

// A .nii.gz whose dims need more voxel bytes than its gzip payload can inflate to (deflate
// expands at most 1032:1) is refused when opened, before any voxel is read.
TEST(NiftiReaderTest, GzipTooSmallForItsDimsIsRefusedOnOpen) {
    TempDir dir;
    nifti_1_header hdr = makeHeader({4096, 4096, 64}, DT_UINT8, 8); // 1 GiB of voxels
    const std::string plain = dir.file("big.nii");
    writeNifti(plain, hdr, rampU8(4096));
    ASSERT_EQ(bc::test::runCommand("gzip -f " + plain).exitCode, 0);
    try {
        openNifti(plain + ".gz");
        FAIL() << "no FormatError";
    } catch (const FormatError& e) {
        EXPECT_EQ(e.field(), "dims") << e.what();
        EXPECT_NE(std::string(e.what()).find("1032:1"), std::string::npos) << e.what();
    }
}

} // namespace bc::brickstore
