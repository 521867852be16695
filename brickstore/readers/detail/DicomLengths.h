#pragma once
// A walk over the element and item lengths of a DICOM file before GDCM reads it
// (DicomLengths.cpp): GDCM allocates each value at the length the file declares before reading
// it, so a 4 KiB file declaring a 4 GiB element would make it allocate (and zero) 4 GiB.
#include <string>

namespace bc::brickstore::detail {

/// Checks that every element and item of the DICOM file at `path` (Part 10 with a preamble, or
/// a bare data set; explicit or implicit VR, little or big endian; sequences nested at most 64
/// deep) declares no more bytes than remain in its file or enclosing item. A deflated data set
/// is checked up to its start. A partial element header is a fault too (GDCM asserts on some).
/// Returns false when a file without the Part 10 preamble fails (most likely not DICOM at all:
/// the caller skips it, as it skips files GDCM cannot read).
/// @throw FormatError(path, "length") naming the element, for a Part 10 file (preamble and
/// "DICM"); FormatError(path, "path") if unreadable.
bool checkDicomLengths(const std::string& path);

} // namespace bc::brickstore::detail
