#pragma once
// The DICOM series reader without its sandbox (DicomReader.cpp): what openDicomSeries runs in
// the sandboxed child, and what the fuzz harness runs in process for coverage.
#include "brickstore/VolumeSource.h"
#include "brickstore/readers/detail/SandboxedSource.h"

#include <memory>
#include <string>

namespace bc::brickstore::detail {

/// openDicomSeries in this process: GDCM's assertions abort it. `reading` (may be empty) is
/// called before each file GDCM reads: every header while opening, a slice's file before its
/// pixels are decoded. @throw FormatError as openDicomSeries.
std::unique_ptr<VolumeSource> openDicomSeriesInProcess(const std::string& folder,
                                                       const ReadingFile& reading = {});

} // namespace bc::brickstore::detail
