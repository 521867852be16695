// A folder holding one DICOM series as a slice stream. Every file's header (all tags before
// the pixel data) is read first (readers/detail/DicomHeaders.h), to select the image slices,
// check that they form one complete, consistent series and sort them along the slice normal;
// then each readSlices step decodes one file's pixels with gdcm::ImageReader (any transfer
// syntax gdcm decodes), so only a slice is ever in memory. Rescale slope/intercept keep the
// stored type when they are the identity, give i16 when integer rescaling maps every storable
// value into i16 (CT in HU), and f32 otherwise.
//
// All of it runs in the parser sandbox (readers/detail/SandboxedSource.h): Debian builds GDCM
// with assertions, and fuzzed files still make it abort where the length pre-walk does not
// reach (gdcmFileMetaInformation.cxx:375 on a file cut inside its meta header). The child
// reports each file before GDCM reads it, so an abort is named by file.
#include "brickstore/Error.h"
#include "brickstore/Readers.h"
#include "brickstore/readers/detail/DicomHeaders.h"
#include "brickstore/readers/detail/DicomSeries.h"

#include <gdcmImage.h>
#include <gdcmImageReader.h>
#include <gdcmTag.h>

#include <algorithm>
#include <cmath>
#include <cstdint>
#include <cstring>
#include <vector>

namespace bc::brickstore {
namespace {

using detail::fileName;
using detail::numberText;
using detail::PixelLayout;
using detail::SliceHeader;

const gdcm::Tag kPixelData(0x7fe0, 0x0010);

bool isSmallInteger(double v) {
    return v == std::floor(v) && std::abs(v) < 2147483648.0;
}

/// The stored type: native when every slice's rescale is the identity, i16 when integer
/// rescaling maps every storable value of every slice into i16, f32 otherwise.
VoxelType storedTypeOf(const std::vector<SliceHeader>& slices) {
    const PixelLayout& layout = slices.front().layout;
    const bool identity = std::all_of(slices.begin(), slices.end(), [](const auto& s) {
        return s.slope == 1.0 && s.intercept == 0.0;
    });
    if (identity) {
        if (layout.bitsAllocated == 8 && !layout.isSigned) return VoxelType::U8;
        if (layout.bitsAllocated == 16) return layout.isSigned ? VoxelType::I16 : VoxelType::U16;
        return VoxelType::F32;
    }
    for (const SliceHeader& s : slices) {
        if (!isSmallInteger(s.slope) || !isSmallInteger(s.intercept)) return VoxelType::F32;
        const double a = layout.minValue() * s.slope + s.intercept,
                     b = layout.maxValue() * s.slope + s.intercept;
        if (std::min(a, b) < -32768.0 || std::max(a, b) > 32767.0) return VoxelType::F32;
    }
    return VoxelType::I16;
}

template <typename T> void storeVoxel(std::byte* out, std::size_t i, T v) {
    std::memcpy(out + i * sizeof(T), &v, sizeof(T));
}

/// The stored value of one container word (U: its unsigned type), with bits above Bits
/// Stored dropped and the sign extended when the layout asks for it.
template <typename U> std::int64_t storedValue(U word, const PixelLayout& layout) {
    std::uint64_t bits = word;
    if (layout.masked()) bits &= (std::uint64_t(1) << layout.bitsStored) - 1;
    const unsigned width = layout.valueBits();
    if (layout.isSigned && ((bits >> (width - 1)) & 1u))
        return std::int64_t(bits) - (std::int64_t(1) << width);
    return std::int64_t(bits);
}

/// Decodes one slice of U-sized words into the stored type. Integer outputs are exact: the
/// type was chosen so that every storable value lands in range.
template <typename U>
void decodeSlice(const std::byte* in, std::size_t count, const SliceHeader& s, VoxelType type,
                 std::byte* out) {
    const auto slope = std::int64_t(s.slope), intercept = std::int64_t(s.intercept);
    for (std::size_t i = 0; i < count; ++i) {
        U word;
        std::memcpy(&word, in + i * sizeof(U), sizeof(U));
        const std::int64_t v = storedValue(word, s.layout);
        switch (type) {
        case VoxelType::U8:
            storeVoxel(out, i, std::uint8_t(v));
            break;
        case VoxelType::U16:
            storeVoxel(out, i, std::uint16_t(v));
            break;
        case VoxelType::I16:
            storeVoxel(out, i, std::int16_t(v * slope + intercept));
            break;
        case VoxelType::F32:
            storeVoxel(out, i, float(double(v) * s.slope + s.intercept));
            break;
        }
    }
}

class DicomSeries final : public VolumeSource {
  public:
    DicomSeries(const std::string& folder, std::vector<SliceHeader> slices,
                const detail::ReadingFile& reading)
        : mFolder(folder), mSlices(std::move(slices)), mReading(reading) {
        detail::checkConsistent(folder, mSlices);
        const double sliceSpacing = detail::sortAndSpace(folder, mSlices);
        const SliceHeader& first = mSlices.front();
        mInfo.dims = {first.columns, first.rows, mSlices.size()};
        mInfo.type = storedTypeOf(mSlices);
        mInfo.spacingMm = {first.pixelSpacing[1], first.pixelSpacing[0], sliceSpacing};
        mInfo.originMm = first.position;
        validateVolumeInfo(mInfo, folder);
        mInfo.description = describe();
    }

    const VolumeInfo& info() const override { return mInfo; }

  private:
    void readNextSlices(std::uint64_t count, std::span<std::byte> out) override {
        for (std::uint64_t i = 0; i < count; ++i)
            readSlice(mSlices[nextSlice() + i],
                      out.subspan(i * mInfo.sliceBytes(), mInfo.sliceBytes()));
    }

    std::string describe() const {
        const SliceHeader& first = mSlices.front();
        const PixelLayout& layout = first.layout;
        std::string text =
            "DICOM series " + fileName(mFolder) + " (" + std::to_string(mSlices.size()) +
            " slices" + (first.modality.empty() ? "" : ", " + first.modality) + "), " +
            (layout.isSigned ? "int" : "uint") + std::to_string(layout.bitsAllocated) + " (" +
            std::to_string(layout.bitsStored) + " bits stored)";
        const std::string stored(voxelTypeName(mInfo.type));
        const bool uniform = std::all_of(mSlices.begin(), mSlices.end(), [&](const auto& s) {
            return s.slope == first.slope && s.intercept == first.intercept;
        });
        if (!uniform) return text + " rescaled per slice to " + stored;
        if (first.slope != 1.0 || first.intercept != 0.0)
            return text + " rescaled by slope " + numberText(first.slope) + ", intercept " +
                   numberText(first.intercept) + " to " + stored;
        return text + (mInfo.type == VoxelType::F32 ? " converted to f32" : " as " + stored);
    }

    void readSlice(const SliceHeader& slice, std::span<std::byte> out) {
        if (mReading) mReading(slice.path);
        gdcm::ImageReader reader;
        reader.SetFileName(slice.path.c_str());
        if (!reader.Read())
            throw FormatError(slice.path, "PixelData", "gdcm cannot read or decode the image");
        const gdcm::Image& image = reader.GetImage();
        const gdcm::PixelFormat& format = image.GetPixelFormat();
        if (image.GetColumns() != mInfo.dims[0] || image.GetRows() != mInfo.dims[1] ||
            format.GetBitsAllocated() != slice.layout.bitsAllocated ||
            format.GetSamplesPerPixel() != 1)
            throw FormatError(slice.path, "PixelData",
                              "the decoded image does not match the header's Rows, Columns, "
                              "Bits Allocated or Samples per Pixel");
        const std::size_t wordBytes = slice.layout.bitsAllocated / 8,
                          voxels = std::size_t(mInfo.dims[0] * mInfo.dims[1]);
        if (image.GetBufferLength() != voxels * wordBytes)
            throw FormatError(slice.path, "PixelData",
                              "holds " + std::to_string(image.GetBufferLength()) +
                                  " bytes, not the " + std::to_string(voxels * wordBytes) +
                                  " that Rows x Columns x Bits Allocated need");
        // GDCM copies GetBufferLength() bytes out of native pixel data without checking that
        // the element holds that many (found by fuzzing: a heap overread).
        const gdcm::ByteValue* native =
            reader.GetFile().GetDataSet().GetDataElement(kPixelData).GetByteValue();
        if (native && native->GetLength() < voxels * wordBytes)
            throw FormatError(slice.path, "PixelData",
                              "holds " + std::to_string(native->GetLength()) +
                                  " bytes of native pixels, not the " +
                                  std::to_string(voxels * wordBytes) +
                                  " that Rows x Columns x Bits Allocated need");
        mPixels.resize(voxels * wordBytes);
        if (!image.GetBuffer(reinterpret_cast<char*>(mPixels.data())))
            throw FormatError(slice.path, "PixelData", "gdcm cannot decode the pixel data");
        switch (wordBytes) {
        case 1:
            decodeSlice<std::uint8_t>(mPixels.data(), voxels, slice, mInfo.type, out.data());
            break;
        case 2:
            decodeSlice<std::uint16_t>(mPixels.data(), voxels, slice, mInfo.type, out.data());
            break;
        default:
            decodeSlice<std::uint32_t>(mPixels.data(), voxels, slice, mInfo.type, out.data());
            break;
        }
    }

    std::string mFolder;
    std::vector<SliceHeader> mSlices; ///< sorted along the slice normal
    detail::ReadingFile mReading;
    VolumeInfo mInfo;
    std::vector<std::byte> mPixels; ///< one decoded slice, reused
};

} // namespace

namespace detail {

std::unique_ptr<VolumeSource> openDicomSeriesInProcess(const std::string& folder,
                                                       const ReadingFile& reading) {
    return std::make_unique<DicomSeries>(folder, detail::readFolder(folder, reading), reading);
}

} // namespace detail

std::unique_ptr<VolumeSource> openDicomSeries(const std::string& folder) {
    return detail::openSandboxed({folder, "DICOM", "per file", {}}, parserSandboxLimits(),
                                 [folder](const detail::ReadingFile& reading) {
                                     return detail::openDicomSeriesInProcess(folder, reading);
                                 });
}

} // namespace bc::brickstore
