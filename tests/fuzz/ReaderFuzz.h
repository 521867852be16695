#pragma once
// What the reader targets (NRRD, NIfTI, DICOM) do with a volume that opened: what a user's
// ingest would, bounded so one input stays fast.
#include "brickstore/Error.h"
#include "brickstore/VolumeSource.h"
#include "tests/fuzz/FuzzSupport.h"

#include <algorithm>
#include <cstddef>
#include <vector>

namespace bc::fuzz {

/// Slices larger than this are not read (the header alone is what is fuzzed then).
constexpr std::uint64_t kMaxFuzzSliceBytes = 1u << 20;
/// A volume up to this size is read to its end (so a reader's end-of-data checks run).
constexpr std::uint64_t kMaxFuzzVolumeBytes = 4u << 20;

/// The info a reader returns must pass the checks every reader promises (validateVolumeInfo);
/// then slices are read one at a time: three, or all of a small volume. A FormatError while
/// reading is an accepted outcome (truncated or corrupt data); anything else propagates.
inline void exerciseVolume(brickstore::VolumeSource& source, const std::string& path) {
    const brickstore::VolumeInfo& info = source.info();
    try {
        brickstore::validateVolumeInfo(info, path);
    } catch (const brickstore::FormatError&) {
        require(false, "a reader returned a volume that validateVolumeInfo rejects");
    }
    const std::uint64_t sliceBytes = info.sliceBytes();
    if (sliceBytes > kMaxFuzzSliceBytes) return;
    const bool whole = sliceBytes * info.dims[2] <= kMaxFuzzVolumeBytes;
    const std::uint64_t slices = whole ? info.dims[2] : std::min<std::uint64_t>(3, info.dims[2]);
    std::vector<std::byte> slice(sliceBytes);
    try {
        for (std::uint64_t z = 0; z < slices; ++z)
            source.readSlices(1, slice);
    } catch (const brickstore::FormatError&) {
        return;
    }
    require(source.nextSlice() == slices, "the slice cursor did not advance");
}

} // namespace bc::fuzz
