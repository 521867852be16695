// openDicomSeries on the real TCIA pancreas CT series (geometry, HU range, and slices checked
// against gdcm decoding the files directly), and on folders assembled here from its slices,
// one per bad input: mixed series, a missing or duplicate slice, a differing grid, no slices.
#include "brickstore/Error.h"
#include "brickstore/Readers.h"
#include "brickstore/readers/detail/DicomSeries.h"
#include "tests/TestSupport.h"

#include <algorithm>
#include <cstdio>
#include <cstring>
#include <filesystem>
#include <fstream>
#include <iterator>
#include <limits>
#include <map>
#include <vector>

// The test target does not get gdcm's include folder; <gdcm-3.0/...> reaches it from /usr/include.
#include <gdcm-3.0/gdcmAttribute.h>
#include <gdcm-3.0/gdcmImageReader.h>
#include <gdcm-3.0/gdcmReader.h>
#include <gdcm-3.0/gdcmWriter.h>

namespace bc::brickstore {
namespace {

namespace fs = std::filesystem;
using bc::test::TempDir;

const char* kSeries = "tcia_pancreas_ct_dicom";
constexpr std::uint64_t kSlices = 134;

std::string sliceFile(int number) {
    char name[16];
    std::snprintf(name, sizeof(name), "1-%03d.dcm", number);
    return (fs::path(bc::test::dataPath(kSeries)) / name).string();
}

/// Links the real slices `first..last` (1-based, inclusive) into `dir`, except `skip`.
void linkSlices(const TempDir& dir, int first, int last, int skip = -1) {
    for (int i = first; i <= last; ++i)
        if (i != skip)
            fs::create_symlink(sliceFile(i), dir.path() / fs::path(sliceFile(i)).filename());
}

/// The bytes of real slice `number`.
std::string sliceBytes(int number) {
    std::ifstream in(sliceFile(number), std::ios::binary);
    return std::string(std::istreambuf_iterator<char>(in), std::istreambuf_iterator<char>());
}

/// Links the real slices `first..last` into `dir` but slice `damaged`, which is written from
/// `bytes` (a damaged copy of it). Returns the damaged file's path.
template <typename Bytes>
std::string linkSlicesWithDamaged(const TempDir& dir, int first, int last, int damaged,
                                  const Bytes& bytes) {
    std::vector<fs::path> slices;
    for (int i = first; i <= last; ++i)
        slices.push_back(sliceFile(i));
    const std::string name = fs::path(sliceFile(damaged)).filename().string();
    return bc::test::linkWithDamagedFile(dir.path(), slices, name, bytes);
}

/// Writes a copy of real slice `number` to `path` with `change` applied to its data set.
template <typename Change>
void writeModifiedSlice(int number, const std::string& path, Change change) {
    gdcm::Reader reader;
    reader.SetFileName(sliceFile(number).c_str());
    ASSERT_TRUE(reader.Read());
    change(reader.GetFile().GetDataSet());
    gdcm::Writer writer;
    writer.SetFile(reader.GetFile());
    writer.SetFileName(path.c_str());
    ASSERT_TRUE(writer.Write());
}

/// Expects openDicomSeries(folder) to throw FormatError for `file` (the folder or a file in it)
/// and `field`, naming both and `words`. Returns its message (empty when none was thrown).
std::string expectOpenError(const std::string& folder, const std::string& file,
                            const std::string& field, const std::string& words) {
    try {
        openDicomSeries(folder);
        ADD_FAILURE() << "no FormatError for " << folder;
        return {};
    } catch (const FormatError& e) {
        const std::string what = e.what();
        EXPECT_EQ(e.file(), file) << what;
        EXPECT_EQ(e.field(), field) << what;
        EXPECT_NE(what.find(file), std::string::npos) << what;
        EXPECT_NE(what.find(field), std::string::npos) << what;
        EXPECT_NE(what.find(words), std::string::npos) << what;
        return what;
    }
}

/// Expects openDicomSeries(folder) to throw FormatError naming the folder, `field` and `words`.
void expectFolderError(const std::string& folder, const std::string& field,
                       const std::string& words) {
    expectOpenError(folder, folder, field, words);
}

/// Slice position along the normal of the series, read here with gdcm's attribute parser.
double positionAlongNormal(const gdcm::DataSet& ds) {
    gdcm::Attribute<0x0020, 0x0032> ipp;
    gdcm::Attribute<0x0020, 0x0037> iop;
    ipp.SetFromDataSet(ds);
    iop.SetFromDataSet(ds);
    const double n[3] = {iop[1] * iop[5] - iop[2] * iop[4], iop[2] * iop[3] - iop[0] * iop[5],
                         iop[0] * iop[4] - iop[1] * iop[3]};
    return ipp[0] * n[0] + ipp[1] * n[1] + ipp[2] * n[2];
}

/// Slice `number` decoded by gdcm::ImageReader, rescaled to HU here.
std::vector<std::int16_t> gdcmSliceInHu(int number) {
    gdcm::ImageReader reader;
    reader.SetFileName(sliceFile(number).c_str());
    EXPECT_TRUE(reader.Read());
    const gdcm::DataSet& ds = reader.GetFile().GetDataSet();
    gdcm::Attribute<0x0028, 0x1052> intercept;
    gdcm::Attribute<0x0028, 0x1053> slope;
    gdcm::Attribute<0x0028, 0x0103> representation;
    intercept.SetFromDataSet(ds);
    slope.SetFromDataSet(ds);
    representation.SetFromDataSet(ds);
    EXPECT_EQ(representation.GetValue(), 0); // unsigned stored values in this series
    const gdcm::Image& image = reader.GetImage();
    std::vector<std::uint16_t> stored(image.GetBufferLength() / 2);
    EXPECT_TRUE(image.GetBuffer(reinterpret_cast<char*>(stored.data())));
    std::vector<std::int16_t> hu(stored.size());
    for (std::size_t i = 0; i < stored.size(); ++i)
        hu[i] = std::int16_t(double(stored[i]) * slope.GetValue() + intercept.GetValue());
    return hu;
}

TEST(DicomReaderTest, PancreasSeriesHasItsGeometryAndHuRange) {
    if (!bc::test::haveData(kSeries)) return bc::test::missingData(kSeries);
    auto source = openDicomSeries(bc::test::dataPath(kSeries)); // LICENSE and Citations are skipped
    const VolumeInfo& info = source->info();
    EXPECT_EQ(info.dims, (std::array<std::uint64_t, 3>{512, 512, kSlices}));
    EXPECT_EQ(info.type, VoxelType::I16);
    EXPECT_NEAR(info.spacingMm[0], 1.0742, 1e-3);
    EXPECT_NEAR(info.spacingMm[1], 1.0742, 1e-3);
    EXPECT_NEAR(info.spacingMm[2], 3.0, 1e-3);
    EXPECT_NEAR(info.originMm[2], 85.91, 1e-3); // the lowest slice, 1-134.dcm
    EXPECT_NE(info.description.find("intercept -1000"), std::string::npos) << info.description;

    std::vector<std::int16_t> slab(10 * info.sliceBytes() / 2);
    int lo = std::numeric_limits<int>::max(), hi = std::numeric_limits<int>::min();
    for (std::uint64_t z = 0; z < info.dims[2];) {
        const std::uint64_t n = std::min<std::uint64_t>(10, info.dims[2] - z);
        source->readSlices(n, std::as_writable_bytes(std::span(slab)).first(n * info.sliceBytes()));
        const auto [mn, mx] = std::minmax_element(
            slab.begin(), slab.begin() + std::ptrdiff_t(n * info.sliceBytes() / 2));
        lo = std::min<int>(lo, *mn);
        hi = std::max<int>(hi, *mx);
        z += n;
    }
    RecordProperty("minHu", lo);
    RecordProperty("maxHu", hi);
    EXPECT_GE(lo, -1000);
    EXPECT_LE(hi, 1988);
    EXPECT_LT(lo, -900); // air is there
    EXPECT_GT(hi, 1000); // and bone
}

TEST(DicomReaderTest, PancreasSlicesMatchGdcmDecodingInPositionOrder) {
    if (!bc::test::haveData(kSeries)) return bc::test::missingData(kSeries);
    std::vector<std::pair<double, int>> order; // (position along the normal, file number)
    for (int i = 1; i <= int(kSlices); ++i) {
        gdcm::Reader reader;
        reader.SetFileName(sliceFile(i).c_str());
        ASSERT_TRUE(reader.Read()) << sliceFile(i);
        order.emplace_back(positionAlongNormal(reader.GetFile().GetDataSet()), i);
    }
    std::sort(order.begin(), order.end());
    std::map<std::uint64_t, int> wanted; // sorted index -> file number
    for (int number : {1, 50, 101}) {
        auto it = std::find_if(order.begin(), order.end(),
                               [&](const auto& p) { return p.second == number; });
        wanted[std::uint64_t(it - order.begin())] = number;
    }

    auto source = openDicomSeries(bc::test::dataPath(kSeries));
    const std::uint64_t sliceBytes = source->info().sliceBytes();
    std::vector<std::int16_t> slice(sliceBytes / 2);
    for (std::uint64_t z = 0; z <= wanted.rbegin()->first; ++z) {
        source->readSlices(1, std::as_writable_bytes(std::span(slice)));
        if (!wanted.count(z)) continue;
        EXPECT_EQ(slice, gdcmSliceInHu(wanted[z]))
            << "sorted slice " << z << " = " << sliceFile(wanted[z]);
    }
}

TEST(DicomReaderTest, MixedSeriesIsRejected) {
    if (!bc::test::haveData(kSeries)) return bc::test::missingData(kSeries);
    TempDir dir;
    linkSlices(dir, 10, 14);
    writeModifiedSlice(15, dir.file("1-015.dcm"), [](gdcm::DataSet& ds) {
        gdcm::DataElement uid = ds.GetDataElement(gdcm::Tag(0x0020, 0x000e));
        const std::string other =
            "1.2.826.0.1.3680043.2.1125.424"; // even length, as UI values are padded
        uid.SetByteValue(other.data(), gdcm::VL(std::uint32_t(other.size())));
        ds.Replace(uid);
    });
    expectFolderError(dir.path().string(), "SeriesInstanceUID", "mixed series");
}

TEST(DicomReaderTest, MissingSliceIsRejected) {
    if (!bc::test::haveData(kSeries)) return bc::test::missingData(kSeries);
    TempDir dir;
    linkSlices(dir, 1, int(kSlices), 67);
    expectFolderError(dir.path().string(), "ImagePositionPatient", "missing slice");
}

TEST(DicomReaderTest, DuplicateSliceIsRejected) {
    if (!bc::test::haveData(kSeries)) return bc::test::missingData(kSeries);
    TempDir dir;
    linkSlices(dir, 20, 25);
    fs::create_symlink(sliceFile(22), dir.path() / "copy-of-22.dcm");
    expectFolderError(dir.path().string(), "ImagePositionPatient", "duplicate");
}

TEST(DicomReaderTest, DifferentRowsAreRejected) {
    if (!bc::test::haveData(kSeries)) return bc::test::missingData(kSeries);
    TempDir dir;
    linkSlices(dir, 30, 33);
    writeModifiedSlice(34, dir.file("1-034.dcm"), [](gdcm::DataSet& ds) {
        gdcm::Attribute<0x0028, 0x0010> rows;
        rows.SetValue(256);
        ds.Replace(rows.GetAsDataElement());
    });
    expectFolderError(dir.path().string(), "Rows/Columns", "256");
}

// A slice whose PixelData is short, by its declared length or by the bytes the file
// really holds, is refused when the series is opened (every slice is checked before the first
// is decoded), naming that file; gdcm would otherwise pad it or leave the previous slice's
// pixels in place.
TEST(DicomReaderTest, ShortOrTruncatedPixelDataIsRejectedOnOpen) {
    if (!bc::test::haveData(kSeries)) return bc::test::missingData(kSeries);
    const auto original = bc::test::readFile(sliceFile(32));
    const std::uint8_t tag[] = {0xe0, 0x7f, 0x10, 0x00}; // (7FE0,0010), implicit VR
    std::size_t pixels = std::string::npos;
    for (std::size_t i = 0; i + 8 <= original.size() && pixels == std::string::npos; ++i)
        if (std::memcmp(original.data() + i, tag, 4) == 0) pixels = i;
    ASSERT_NE(pixels, std::string::npos);
    auto shortened = original;
    const std::uint32_t length = 1000;
    std::memcpy(shortened.data() + pixels + 4, &length, 4); // little-endian host
    shortened.resize(pixels + 8 + length);
    auto cut = original;
    cut.resize(original.size() - 300000);
    for (const auto* bytes : {&shortened, &cut}) {
        TempDir dir;
        const std::string bad = linkSlicesWithDamaged(dir, 30, 34, 32, *bytes);
        expectOpenError(dir.path().string(), bad, "PixelData", "524288");
    }
}

TEST(DicomReaderTest, DifferentOrientationIsRejected) {
    if (!bc::test::haveData(kSeries)) return bc::test::missingData(kSeries);
    TempDir dir;
    linkSlices(dir, 40, 43);
    writeModifiedSlice(44, dir.file("1-044.dcm"), [](gdcm::DataSet& ds) {
        gdcm::Attribute<0x0020, 0x0037> iop = {{1, 0, 0, 0, 0, -1}}; // coronal
        ds.Replace(iop.GetAsDataElement());
    });
    expectFolderError(dir.path().string(), "ImageOrientationPatient", "1-044.dcm");
}

TEST(DicomReaderTest, NonIntegerRescaleGivesF32) {
    if (!bc::test::haveData(kSeries)) return bc::test::missingData(kSeries);
    TempDir dir;
    linkSlices(dir, 70, 72);
    writeModifiedSlice(73, dir.file("1-073.dcm"), [](gdcm::DataSet& ds) {
        gdcm::Attribute<0x0028, 0x1053> slope;
        slope.SetValue(0.5);
        ds.Replace(slope.GetAsDataElement());
    });
    auto source = openDicomSeries(dir.path().string());
    EXPECT_EQ(source->info().type, VoxelType::F32);
    EXPECT_NE(source->info().description.find("rescaled per slice"), std::string::npos)
        << source->info().description;
    std::vector<float> slices(2 * source->info().sliceBytes() / 4);
    source->readSlices(2, std::as_writable_bytes(std::span(slices)));
    const std::vector<std::int16_t> hu73 = gdcmSliceInHu(73), hu72 = gdcmSliceInHu(72);
    std::size_t mismatches = 0;
    for (std::size_t i = 0; i < hu73.size(); ++i) {
        // 1-073.dcm is the lowest slice: stored * 0.5 - 1000 = (hu + 1000) * 0.5 - 1000
        mismatches += slices[i] != float((hu73[i] + 1000) * 0.5 - 1000);
        mismatches += slices[hu73.size() + i] != float(hu72[i]);
    }
    EXPECT_EQ(mismatches, 0u);
}

TEST(DicomReaderTest, EmptyFolderIsRejected) {
    TempDir dir;
    expectFolderError(dir.path().string(), "slices", "no DICOM image slices");
}

TEST(DicomReaderTest, FolderWithoutDicomFilesIsRejected) {
    TempDir dir;
    bc::test::writeFile(dir.file("LICENSE"), "CC BY 4.0\n");
    bc::test::writeFile(dir.file("notes.txt"), std::string(2000, 'x'));
    expectFolderError(dir.path().string(), "slices", "no DICOM image slices");
}

TEST(DicomReaderTest, NonDicomFilesBesideTheSlicesAreSkipped) {
    if (!bc::test::haveData(kSeries)) return bc::test::missingData(kSeries);
    TempDir dir;
    linkSlices(dir, 60, 64);
    bc::test::writeFile(dir.file("README"), "five slices\n");
    auto source = openDicomSeries(dir.path().string());
    EXPECT_EQ(source->info().dims, (std::array<std::uint64_t, 3>{512, 512, 5}));
    EXPECT_NEAR(source->info().spacingMm[2], 3.0, 1e-3);
}

/// The bytes of real slice `number` with the 4-byte length of implicit-VR element (group,
/// element) set to `length` (found by fuzzing: GDCM allocates a declared length before reading).
std::string sliceWithLength(int number, std::uint16_t group, std::uint16_t element,
                            std::uint32_t length) {
    std::string bytes = sliceBytes(number);
    const char tag[4] = {char(group & 0xFF), char(group >> 8), char(element & 0xFF),
                         char(element >> 8)};
    const std::size_t at = bytes.find(std::string(tag, 4), 132);
    EXPECT_NE(at, std::string::npos);
    if (at != std::string::npos) std::memcpy(bytes.data() + at + 4, &length, 4);
    return bytes;
}

TEST(DicomReaderTest, ElementLongerThanItsFileIsRejectedBeforeAllocation) {
    if (!bc::test::haveData(kSeries)) return bc::test::missingData(kSeries);
    TempDir dir;
    // Modality (0008,0060) declaring 4 GiB - 256 bytes in a 0.5 MiB file.
    const std::string path =
        linkSlicesWithDamaged(dir, 60, 62, 62, sliceWithLength(62, 0x0008, 0x0060, 0xFFFFFF00u));
    expectOpenError(dir.path().string(), path, "length", "(0008,0060)");
}

TEST(DicomReaderTest, FileWithoutPreambleAndBadLengthsIsSkipped) {
    if (!bc::test::haveData(kSeries)) return bc::test::missingData(kSeries);
    TempDir dir;
    linkSlices(dir, 60, 62);
    // Read as a bare implicit-VR data set, this claims a 0x78787878-byte element: not DICOM.
    bc::test::writeFile(dir.file("notes.txt"), std::string(64, 'x'));
    auto source = openDicomSeries(dir.path().string());
    EXPECT_EQ(source->info().dims, (std::array<std::uint64_t, 3>{512, 512, 3}));
}

TEST(DicomReaderTest, TinyJunkFileBesideTheSlicesIsSkipped) {
    if (!bc::test::haveData(kSeries)) return bc::test::missingData(kSeries);
    TempDir dir;
    linkSlices(dir, 60, 62);
    // Found by fuzzing: these 4 bytes made GDCM's reader assert (abort) in ReadUpToTag.
    const unsigned char junk[] = {0x08, 0x00, 0x00, 0x08};
    bc::test::writeFile(dir.file("junk"), junk, sizeof(junk));
    auto source = openDicomSeries(dir.path().string());
    EXPECT_EQ(source->info().dims, (std::array<std::uint64_t, 3>{512, 512, 3}));
}

TEST(DicomReaderTest, ItemEndedBySequenceDelimiterIsRejected) {
    // Found by fuzzing: an undefined-length item closed by a sequence delimiter (not an item
    // delimiter) made GDCM assert (abort) in DataSet::ReadNested. Part 10, implicit VR LE.
    std::string file(128, '\0');
    file += "DICM";
    const std::string syntax("1.2.840.10008.1.2\0", 18);
    file += std::string("\x02\x00\x10\x00UI\x12\x00", 8) + syntax;
    auto element = [&](std::uint16_t group, std::uint16_t tag, std::uint32_t length) {
        const char header[8] = {char(group & 0xFF),        char(group >> 8),
                                char(tag & 0xFF),          char(tag >> 8),
                                char(length & 0xFF),       char(length >> 8 & 0xFF),
                                char(length >> 16 & 0xFF), char(length >> 24)};
        file.append(header, 8);
    };
    element(0x0008, 0x1140, 0xFFFFFFFFu); // a sequence of undefined length
    element(0xFFFE, 0xE000, 0xFFFFFFFFu); // an item of undefined length
    element(0x0008, 0x0100, 2);
    file += "AB";
    element(0xFFFE, 0xE0DD, 0); // sequence delimiter where the item delimiter belongs
    TempDir dir;
    bc::test::writeFile(dir.file("bad.dcm"), file);
    expectOpenError(dir.path().string(), dir.file("bad.dcm"), "length", "");
}

TEST(DicomReaderTest, MetaElementWithUnknownVrIsRejected) {
    if (!bc::test::haveData(kSeries)) return bc::test::missingData(kSeries);
    // Found by fuzzing: File Meta Information Group Length with its VR "UL" changed to "LU"
    // made GDCM assert (abort) in ReadImplicitDataElement ("Should not happen").
    std::string bytes = sliceBytes(62);
    ASSERT_EQ(bytes.substr(128, 10), std::string("DICM\x02\x00\x00\x00UL", 10));
    bytes[136] = 'L';
    bytes[137] = 'U';
    TempDir dir;
    bc::test::writeFile(dir.file("1-062.dcm"), bytes);
    expectOpenError(dir.path().string(), dir.file("1-062.dcm"), "length", "");
}

TEST(DicomReaderTest, PixelDataShorterThanRowsTimesColumnsIsRejected) {
    if (!bc::test::haveData(kSeries)) return bc::test::missingData(kSeries);
    // Found by fuzzing: GDCM copied Rows x Columns x 2 bytes out of a shorter native pixel
    // data element (a heap overread). Columns 512 -> 520: 16 KiB more than the file holds.
    std::string bytes = sliceWithLength(62, 0x0028, 0x0011, 2);
    const std::size_t at = bytes.find(std::string("\x28\x00\x11\x00\x02\x00\x00\x00", 8), 132);
    ASSERT_NE(at, std::string::npos);
    const std::uint16_t columns = 520;
    std::memcpy(bytes.data() + at + 8, &columns, 2);
    TempDir dir;
    bc::test::writeFile(dir.file("1-062.dcm"), bytes);
    // Refused when the series is opened (every slice's PixelData length is checked against
    // Rows x Columns then), and by the read itself, should a file pass that check.
    try {
        auto source = openDicomSeries(dir.path().string());
        std::vector<std::byte> slice(source->info().sliceBytes());
        source->readSlices(1, slice);
        FAIL() << "no FormatError for short pixel data";
    } catch (const FormatError& e) {
        EXPECT_EQ(e.field(), "PixelData") << e.what();
        EXPECT_NE(std::string(e.what()).find("524288 bytes"), std::string::npos) << e.what();
    }
}

/// Real slice `number` cut right after its (0002,0012) element, inside the file meta group
/// (whose group length promises more): found by fuzzing, GDCM asserts on it
/// (gdcmFileMetaInformation.cxx:375, "Should not happen") and aborts the process it runs in.
std::string sliceCutInMetaHeader(int number) {
    std::string bytes = sliceBytes(number);
    const std::size_t at = bytes.find(std::string("\x02\x00\x12\x00UI", 6), 132);
    EXPECT_NE(at, std::string::npos);
    if (at == std::string::npos) return bytes;
    std::uint16_t length = 0;
    std::memcpy(&length, bytes.data() + at + 6, 2);
    bytes.resize(at + 8 + length);
    return bytes;
}

// GDCM runs in the sandboxed child, so its assertion is an error naming the file
// and quoting GDCM's assertion text, not the end of the process; and the input still makes GDCM
// abort in process (else this test would no longer test the sandbox).
TEST(DicomReaderTest, FileThatMakesGdcmAssertIsAnErrorNamingIt) {
    if (!bc::test::haveData(kSeries)) return bc::test::missingData(kSeries);
    TempDir dir;
    const std::string path = linkSlicesWithDamaged(dir, 60, 62, 62, sliceCutInMetaHeader(62));
    testing::internal::CaptureStderr();
    const std::string what =
        expectOpenError(dir.path().string(), path, "file", "DICOM parser aborted");
    const std::string printed = testing::internal::GetCapturedStderr();
    EXPECT_LT(what.size(), 1024u) << what;
    // GDCM's own words end the error instead of standing on stderr above it.
    EXPECT_NE(what.find("Assertion `0 && \"Should not happen\"' failed."), std::string::npos)
        << what;
    EXPECT_EQ(printed.find("Should not happen"), std::string::npos) << printed;
    GTEST_FLAG_SET(death_test_style, "threadsafe");
    EXPECT_DEATH(detail::openDicomSeriesInProcess(dir.path().string()),
                 "gdcmFileMetaInformation.*Assertion");
}

TEST(DicomReaderTest, NotAFolderIsRejected) {
    TempDir dir;
    expectFolderError(dir.file("absent"), "folder", "not a folder");
}

} // namespace
} // namespace bc::brickstore
