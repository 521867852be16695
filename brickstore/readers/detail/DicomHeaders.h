#pragma once
// The headers of a DICOM series (DicomHeaders.cpp): every file's tags before its pixel data,
// read with gdcm after the length pre-walk (DicomLengths.h), checked to form one complete,
// consistent series and sorted along the slice normal. Used by the series reader
// (DicomReader.cpp), in the parser sandbox's child.
#include "brickstore/readers/detail/SandboxedSource.h"

#include <array>
#include <cmath>
#include <cstdint>
#include <string>
#include <vector>

namespace bc::brickstore::detail {

using Vec3 = std::array<double, 3>;

/// Where the integer pixel values sit in their container (8, 16 or 32 bits allocated).
struct PixelLayout {
    unsigned bitsAllocated = 16;
    unsigned bitsStored = 16;
    unsigned highBit = 15;
    bool isSigned = false;

    /// Bits above Bits Stored (overlays, garbage) are dropped only in the usual low-aligned layout.
    bool masked() const { return bitsStored < bitsAllocated && highBit + 1 == bitsStored; }
    unsigned valueBits() const { return masked() ? bitsStored : bitsAllocated; }
    double minValue() const { return isSigned ? -std::ldexp(1.0, int(valueBits()) - 1) : 0.0; }
    double maxValue() const {
        return isSigned ? std::ldexp(1.0, int(valueBits()) - 1) - 1.0
                        : std::ldexp(1.0, int(valueBits())) - 1.0;
    }
    bool operator==(const PixelLayout&) const = default;
};

/// What one file's header says about its slice.
struct SliceHeader {
    std::string path;
    std::string seriesUid;
    std::string modality;
    Vec3 position{};
    std::array<double, 6> orientation{};
    std::array<double, 2> pixelSpacing{}; ///< row spacing (y), column spacing (x)
    double sliceThickness = 0.0;
    std::uint64_t rows = 0;
    std::uint64_t columns = 0;
    PixelLayout layout;
    double slope = 1.0;
    double intercept = 0.0;
    double along = 0.0; ///< position projected on the slice normal
};

/// The headers of the folder's DICOM image slices, in file-name order; files that are not DICOM
/// or not images are skipped. `reading` (may be empty) is called before each file is read.
/// @throw FormatError naming the folder (no slices, not a folder) or the file and field at fault.
std::vector<SliceHeader> readFolder(const std::string& folder, const ReadingFile& reading);

/// One series, one grid, one pixel layout: anything else is not one volume.
/// @throw FormatError naming the folder, the field and both files.
void checkConsistent(const std::string& folder, const std::vector<SliceHeader>& slices);

/// Sorts along the normal and returns the slice spacing. Equal positions (a duplicate) or a
/// gap above 1.5x the median (a missing slice) throw FormatError naming both files.
double sortAndSpace(const std::string& folder, std::vector<SliceHeader>& slices);

/// "1-001.dcm" of a path, and "%g" of a number, as messages write them.
std::string fileName(const std::string& path);
std::string numberText(double v);

} // namespace bc::brickstore::detail
