// The headers of a DICOM series (DicomHeaders.h): each file is walked for its lengths, then read
// by gdcm up to its pixel data; counts, geometry, rescale and the pixel data's length are
// checked for every slice before any is decoded.
#include "brickstore/readers/detail/DicomHeaders.h"
#include "brickstore/Error.h"
#include "brickstore/VolumeSource.h"
#include "brickstore/readers/detail/DicomLengths.h"

#include <gdcmReader.h>
#include <gdcmStringFilter.h>
#include <gdcmTag.h>

#include <algorithm>
#include <cmath>
#include <cstdio>
#include <cstdlib>
#include <filesystem>
#include <fstream>
#include <optional>
#include <set>

namespace bc::brickstore::detail {
namespace {

const gdcm::Tag kSeriesInstanceUid(0x0020, 0x000e);
const gdcm::Tag kImagePosition(0x0020, 0x0032);
const gdcm::Tag kImageOrientation(0x0020, 0x0037);
const gdcm::Tag kModality(0x0008, 0x0060);
const gdcm::Tag kSliceThickness(0x0018, 0x0050);
const gdcm::Tag kSamplesPerPixel(0x0028, 0x0002);
const gdcm::Tag kNumberOfFrames(0x0028, 0x0008);
const gdcm::Tag kRows(0x0028, 0x0010);
const gdcm::Tag kColumns(0x0028, 0x0011);
const gdcm::Tag kPixelSpacing(0x0028, 0x0030);
const gdcm::Tag kBitsAllocated(0x0028, 0x0100);
const gdcm::Tag kBitsStored(0x0028, 0x0101);
const gdcm::Tag kHighBit(0x0028, 0x0102);
const gdcm::Tag kPixelRepresentation(0x0028, 0x0103);
const gdcm::Tag kRescaleIntercept(0x0028, 0x1052);
const gdcm::Tag kRescaleSlope(0x0028, 0x1053);
const gdcm::Tag kPixelData(0x7fe0, 0x0010);

/// Where a file's PixelData value starts and how long it says it is (nullopt: undefined
/// length, i.e. encapsulated frames whose decoded size only the decoder knows).
struct PixelDataSpan {
    std::uint64_t offset = 0;
    std::optional<std::uint64_t> declaredBytes;
};

std::string trim(const std::string& s) {
    const auto first = s.find_first_not_of(" \t\r\n");
    if (first == std::string::npos) return {};
    return s.substr(first, s.find_last_not_of(" \t\r\n") - first + 1);
}

/// Reads a tag's value(s) as text through the data dictionary (binary US values included).
class TagText {
  public:
    TagText(const std::string& path, const gdcm::File& file)
        : mPath(path), mDataSet(file.GetDataSet()) {
        mFilter.SetFile(file);
    }

    std::string text(const gdcm::Tag& tag) const {
        if (!mDataSet.FindDataElement(tag)) return {};
        return trim(mFilter.ToString(tag));
    }

    /// `count` backslash-separated numbers; nullopt when the tag is absent or empty.
    std::optional<std::vector<double>> numbers(const gdcm::Tag& tag, const char* name,
                                               std::size_t count) const {
        const std::string value = text(tag);
        if (value.empty()) return std::nullopt;
        std::vector<double> out;
        std::size_t start = 0;
        while (start <= value.size()) {
            const std::size_t end = std::min(value.find('\\', start), value.size());
            const std::string token = trim(value.substr(start, end - start));
            char* stop = nullptr;
            const double v = std::strtod(token.c_str(), &stop);
            if (token.empty() || *stop != '\0' || !std::isfinite(v))
                throw FormatError(mPath, name,
                                  "\"" + value + "\" is not a list of " + std::to_string(count) +
                                      " numbers");
            out.push_back(v);
            start = end + 1;
        }
        if (out.size() != count)
            throw FormatError(mPath, name,
                              "\"" + value + "\" holds " + std::to_string(out.size()) +
                                  " numbers, not " + std::to_string(count));
        return out;
    }

    std::vector<double> required(const gdcm::Tag& tag, const char* name, std::size_t count) const {
        auto values = numbers(tag, name, count);
        if (!values) throw FormatError(mPath, name, "missing; every slice of a series needs it");
        return *values;
    }

    double single(const gdcm::Tag& tag, const char* name, double fallback) const {
        auto values = numbers(tag, name, 1);
        return values ? (*values)[0] : fallback;
    }

    /// A whole number in 0..65535 (the range of a US value); `fallback` when absent.
    unsigned count(const gdcm::Tag& tag, const char* name,
                   std::optional<unsigned> fallback = {}) const {
        auto values = numbers(tag, name, 1);
        if (!values && fallback) return *fallback;
        if (!values) throw FormatError(mPath, name, "missing; every slice of a series needs it");
        const double v = (*values)[0];
        if (v < 0.0 || v > 65535.0 || v != std::floor(v))
            throw FormatError(mPath, name,
                              numberText(v) + " is not a whole number between 0 and 65535");
        return unsigned(v);
    }

  private:
    std::string mPath;
    const gdcm::DataSet& mDataSet;
    gdcm::StringFilter mFilter;
};

PixelLayout layoutOf(const std::string& path, const TagText& tags) {
    PixelLayout layout;
    layout.bitsAllocated = tags.count(kBitsAllocated, "BitsAllocated");
    if (layout.bitsAllocated != 8 && layout.bitsAllocated != 16 && layout.bitsAllocated != 32)
        throw FormatError(path, "BitsAllocated",
                          std::to_string(layout.bitsAllocated) +
                              " bits per pixel; only 8, 16 and 32 are supported");
    layout.bitsStored = tags.count(kBitsStored, "BitsStored", layout.bitsAllocated);
    layout.highBit = tags.count(kHighBit, "HighBit", layout.bitsStored - 1);
    if (layout.bitsStored == 0 || layout.bitsStored > layout.bitsAllocated)
        throw FormatError(path, "BitsStored",
                          std::to_string(layout.bitsStored) +
                              " is not between 1 and Bits Allocated (" +
                              std::to_string(layout.bitsAllocated) + ")");
    const unsigned representation = tags.count(kPixelRepresentation, "PixelRepresentation");
    if (representation > 1)
        throw FormatError(path, "PixelRepresentation",
                          std::to_string(representation) + " is neither 0 nor 1");
    layout.isSigned = representation == 1;
    return layout;
}

void readGeometry(const TagText& tags, SliceHeader& slice) {
    const auto position = tags.required(kImagePosition, "ImagePositionPatient", 3);
    const auto orientation = tags.required(kImageOrientation, "ImageOrientationPatient", 6);
    const auto spacing = tags.required(kPixelSpacing, "PixelSpacing", 2);
    std::copy(position.begin(), position.end(), slice.position.begin());
    std::copy(orientation.begin(), orientation.end(), slice.orientation.begin());
    std::copy(spacing.begin(), spacing.end(), slice.pixelSpacing.begin());
    slice.sliceThickness = tags.single(kSliceThickness, "SliceThickness", 0.0);
}

void readPixelDescription(const TagText& tags, SliceHeader& slice) {
    if (tags.count(kSamplesPerPixel, "SamplesPerPixel", 1) != 1)
        throw FormatError(slice.path, "SamplesPerPixel",
                          "colour images are not supported; a series must be greyscale");
    if (tags.single(kNumberOfFrames, "NumberOfFrames", 1.0) != 1.0)
        throw FormatError(slice.path, "NumberOfFrames",
                          "multi-frame files are not supported; one slice per file");
    slice.columns = tags.count(kColumns, "Columns");
    slice.layout = layoutOf(slice.path, tags);
    slice.slope = tags.single(kRescaleSlope, "RescaleSlope", 1.0);
    slice.intercept = tags.single(kRescaleIntercept, "RescaleIntercept", 0.0);
    if (slice.slope == 0.0 || std::abs(slice.slope) > 1e20)
        throw FormatError(slice.path, "RescaleSlope",
                          numberText(slice.slope) + " is zero or absurdly large");
    if (std::abs(slice.intercept) > 1e20)
        throw FormatError(slice.path, "RescaleIntercept",
                          numberText(slice.intercept) + " is absurdly large");
}

/// The PixelData element's value as the file holds it. gdcm's ReadUpToTag stops right after
/// the element's tag and length (implicit VR: tag, 4-byte length; explicit OB/OW: tag, VR, 2
/// reserved bytes, 4-byte length), so the length is the 4 bytes before the stream position.
std::optional<PixelDataSpan> locatePixelData(const std::string& path, const gdcm::Reader& reader) {
    const std::uint64_t position = reader.GetStreamCurrentPosition();
    if (position < 8) return std::nullopt;
    std::ifstream in(path, std::ios::binary);
    std::array<unsigned char, 12> head{};
    const std::uint64_t start = position >= 12 ? position - 12 : position - 8;
    in.seekg(std::streamoff(start));
    in.read(reinterpret_cast<char*>(head.data()), std::streamsize(position - start));
    if (std::uint64_t(in.gcount()) != position - start) return std::nullopt;
    const bool big = reader.GetFile().GetHeader().GetDataSetTransferSyntax().GetSwapCode() ==
                     gdcm::SwapCode::BigEndian;
    // The tag (7FE0,0010) sits 8 (implicit) or 12 (explicit) bytes back: otherwise the stream
    // is not where this expects and nothing is claimed.
    auto isTag = [&](std::size_t i) {
        return big ? head[i] == 0x7f && head[i + 1] == 0xe0 && head[i + 2] == 0x00 &&
                         head[i + 3] == 0x10
                   : head[i] == 0xe0 && head[i + 1] == 0x7f && head[i + 2] == 0x10 &&
                         head[i + 3] == 0x00;
    };
    const std::size_t n = std::size_t(position - start);
    if (!isTag(n - 8) && !(n == 12 && isTag(0))) return std::nullopt;
    const unsigned char* l = head.data() + n - 4;
    const std::uint32_t length = big ? std::uint32_t(l[0]) << 24 | std::uint32_t(l[1]) << 16 |
                                           std::uint32_t(l[2]) << 8 | l[3]
                                     : std::uint32_t(l[3]) << 24 | std::uint32_t(l[2]) << 16 |
                                           std::uint32_t(l[1]) << 8 | l[0];
    PixelDataSpan span;
    span.offset = position;
    if (length != 0xffffffffu) span.declaredBytes = length;
    return span;
}

/// Rows x Columns within the slice limit, and a native PixelData that holds Rows x Columns x
/// Samples x Bits Allocated / 8 bytes both by its declared length and by the bytes the file
/// really has after it: checked for every slice, before any is decoded.
void checkPixelData(const SliceHeader& slice, const std::optional<PixelDataSpan>& span) {
    const std::string need = std::to_string(slice.columns) + " x " + std::to_string(slice.rows) +
                             " x 1 sample x " + std::to_string(slice.layout.bitsAllocated / 8) +
                             " bytes";
    if (slice.rows * slice.columns > kMaxSliceVoxels)
        throw FormatError(slice.path, "Rows/Columns",
                          std::to_string(slice.rows) + " x " + std::to_string(slice.columns) +
                              ": a slice of " + std::to_string(slice.rows * slice.columns) +
                              " pixels exceeds the limit of " + std::to_string(kMaxSliceVoxels));
    if (!span || !span->declaredBytes) return;
    const std::uint64_t needBytes = slice.rows * slice.columns * (slice.layout.bitsAllocated / 8);
    std::error_code ec;
    const std::uint64_t fileBytes = std::filesystem::file_size(slice.path, ec);
    if (ec) throw FormatError(slice.path, "file", "cannot get its size: " + ec.message());
    const std::uint64_t held = fileBytes > span->offset ? fileBytes - span->offset : 0;
    if (*span->declaredBytes < needBytes)
        throw FormatError(slice.path, "PixelData",
                          "declares " + std::to_string(*span->declaredBytes) + " bytes; " + need +
                              " need " + std::to_string(needBytes));
    if (held < needBytes)
        throw FormatError(slice.path, "PixelData",
                          "the file holds " + std::to_string(held) +
                              " bytes of pixel data after byte " + std::to_string(span->offset) +
                              "; " + need + " need " + std::to_string(needBytes) +
                              " (file truncated)");
}

/// The header of one file; nullopt for a file that is not DICOM (LICENSE, notes) or a DICOM
/// object that is not an image (DICOMDIR, structured report: no Rows).
std::optional<SliceHeader> readSliceHeader(const std::string& path) {
    // GDCM allocates whatever length a file declares before reading it: check them first.
    if (!detail::checkDicomLengths(path)) return std::nullopt;
    gdcm::Reader reader;
    reader.SetFileName(path.c_str());
    if (!reader.ReadUpToTag(kPixelData, std::set<gdcm::Tag>{kPixelData})) return std::nullopt;
    const TagText tags(path, reader.GetFile());
    if (tags.text(kRows).empty()) return std::nullopt;
    SliceHeader slice;
    slice.path = path;
    slice.rows = tags.count(kRows, "Rows");
    slice.seriesUid = tags.text(kSeriesInstanceUid);
    if (slice.seriesUid.empty()) throw FormatError(path, "SeriesInstanceUID", "missing");
    slice.modality = tags.text(kModality);
    readGeometry(tags, slice);
    readPixelDescription(tags, slice);
    checkPixelData(slice, locatePixelData(path, reader));
    return slice;
}

} // namespace

std::string fileName(const std::string& path) {
    return std::filesystem::path(path).filename().string();
}

std::string numberText(double v) {
    char text[32];
    std::snprintf(text, sizeof(text), "%g", v);
    return text;
}

std::vector<SliceHeader> readFolder(const std::string& folder, const ReadingFile& reading) {
    std::error_code ec;
    if (!std::filesystem::is_directory(folder, ec))
        throw FormatError(folder, "folder", "not a folder");
    std::vector<std::string> files;
    for (const auto& entry : std::filesystem::directory_iterator(folder, ec))
        if (entry.is_regular_file(ec)) files.push_back(entry.path().string());
    if (ec) throw FormatError(folder, "folder", "cannot list it: " + ec.message());
    std::sort(files.begin(), files.end());
    std::vector<SliceHeader> slices;
    for (const std::string& file : files) {
        if (reading) reading(file);
        if (auto slice = readSliceHeader(file)) slices.push_back(std::move(*slice));
    }
    if (slices.empty())
        throw FormatError(folder, "slices",
                          "no DICOM image slices among its " + std::to_string(files.size()) +
                              " files");
    return slices;
}

namespace {

Vec3 sliceNormal(const SliceHeader& slice) {
    const auto& o = slice.orientation;
    const Vec3 n{o[1] * o[5] - o[2] * o[4], o[2] * o[3] - o[0] * o[5], o[0] * o[4] - o[1] * o[3]};
    const double length = std::sqrt(n[0] * n[0] + n[1] * n[1] + n[2] * n[2]);
    if (!(length > 0.5))
        throw FormatError(slice.path, "ImageOrientationPatient",
                          "row and column directions are not orthogonal unit vectors");
    return {n[0] / length, n[1] / length, n[2] / length};
}

template <typename T, std::size_t N>
bool nearlyEqual(const std::array<T, N>& a, const std::array<T, N>& b, double tolerance) {
    for (std::size_t i = 0; i < N; ++i)
        if (std::abs(a[i] - b[i]) > tolerance) return false;
    return true;
}

} // namespace

void checkConsistent(const std::string& folder, const std::vector<SliceHeader>& slices) {
    const SliceHeader& first = slices.front();
    const std::string ref = " (" + fileName(first.path) + " has ";
    for (const SliceHeader& s : slices) {
        const std::string name = fileName(s.path);
        if (s.seriesUid != first.seriesUid)
            throw FormatError(folder, "SeriesInstanceUID",
                              "mixed series: " + name + " is in series " + s.seriesUid + ", " +
                                  fileName(first.path) + " in " + first.seriesUid +
                                  "; put each series in its own folder");
        if (s.rows != first.rows || s.columns != first.columns)
            throw FormatError(folder, "Rows/Columns",
                              name + " is " + std::to_string(s.columns) + "x" +
                                  std::to_string(s.rows) + ref + std::to_string(first.columns) +
                                  "x" + std::to_string(first.rows) + ")");
        if (!nearlyEqual(s.orientation, first.orientation, 1e-4))
            throw FormatError(folder, "ImageOrientationPatient",
                              name + " is oriented differently" + ref + "another)");
        if (!nearlyEqual(s.pixelSpacing, first.pixelSpacing, 1e-4))
            throw FormatError(folder, "PixelSpacing",
                              name + " has a different pixel spacing" + ref + "another)");
        if (!(s.layout == first.layout))
            throw FormatError(folder, "BitsAllocated/BitsStored/PixelRepresentation",
                              name + " stores its pixels differently" + ref + "another layout)");
    }
}

double sortAndSpace(const std::string& folder, std::vector<SliceHeader>& slices) {
    const Vec3 n = sliceNormal(slices.front());
    for (SliceHeader& s : slices)
        s.along = s.position[0] * n[0] + s.position[1] * n[1] + s.position[2] * n[2];
    std::stable_sort(slices.begin(), slices.end(),
                     [](const auto& a, const auto& b) { return a.along < b.along; });
    if (slices.size() == 1)
        return slices.front().sliceThickness > 0.0 ? slices.front().sliceThickness : 1.0;
    std::vector<double> gaps;
    for (std::size_t i = 1; i < slices.size(); ++i)
        gaps.push_back(slices[i].along - slices[i - 1].along);
    std::vector<double> sorted = gaps;
    std::nth_element(sorted.begin(), sorted.begin() + std::ptrdiff_t(sorted.size() / 2),
                     sorted.end());
    const double median = sorted[sorted.size() / 2];
    for (std::size_t i = 0; i < gaps.size(); ++i) {
        const SliceHeader &a = slices[i], &b = slices[i + 1];
        const std::string where = fileName(a.path) + " (at " + numberText(a.along) + " mm) and " +
                                  fileName(b.path) + " (at " + numberText(b.along) + " mm)";
        if (gaps[i] <= std::max(1e-4, 0.01 * median))
            throw FormatError(folder, "ImagePositionPatient", "duplicate slice position: " + where);
        if (gaps[i] > 1.5 * median)
            throw FormatError(folder, "ImagePositionPatient",
                              "missing slice between " + where + ": gap " + numberText(gaps[i]) +
                                  " mm, median " + numberText(median) + " mm");
    }
    return (slices.back().along - slices.front().along) / double(slices.size() - 1);
}

} // namespace bc::brickstore::detail
