#pragma once
// What the reader targets (NRRD, NIfTI, DICOM) do with a volume that opened: what a user's
// ingest would, bounded so one input stays fast; the whole input step of a reader that opens
// one file; and gzip for the seeds of readers that take gzip data.
#include "brickstore/Error.h"
#include "brickstore/VolumeSource.h"
#include "tests/fuzz/FuzzSupport.h"

#include <algorithm>
#include <cstddef>
#include <memory>
#include <string>
#include <vector>

#include <zlib.h>

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

/// LLVMFuzzerTestOneInput of a reader that opens one file: the input is written to `path` and
/// opened with `open` (a FormatError is the expected refusal), and the volume exercised.
template <typename Open>
int fuzzReader(const std::uint8_t* data, std::size_t size, const std::string& path, Open open) {
    writeFile(path, {data, size});
    std::unique_ptr<brickstore::VolumeSource> source;
    try {
        source = open(path);
    } catch (const brickstore::FormatError&) {
        return 0;
    }
    exerciseVolume(*source, path);
    return 0;
}

/// 16x16x8 u8 voxels: the detached data file of the seeds of readers whose headers name one.
inline Bytes detachedVoxels() {
    Bytes v(16 * 16 * 8);
    for (std::size_t i = 0; i < v.size(); ++i)
        v[i] = std::uint8_t((i * 37) ^ (i >> 4));
    return v;
}

/// A shared scan the seeds crop: its file, its type as the format names it, its slice size,
/// bytes per voxel and its spacing as the format writes it.
struct SeedScan {
    const char* file;
    const char* type;
    unsigned x, y, bytes;
    const char* spacing;
};

/// Edge of the corner the seeds crop from a scan: a seed stays well under -max_len.
constexpr unsigned kSeedEdge = 32;

/// The kSeedEdge x kSeedEdge x `slices` corner of `scan` in the folder `data`; empty when the
/// scan is missing.
inline Bytes scanCorner(const std::string& data, const SeedScan& scan, unsigned slices) {
    const Bytes whole = readPrefix(std::filesystem::path(data) / scan.file,
                                   std::size_t(scan.x) * scan.y * scan.bytes * slices);
    return cropVoxels(whole, 0, scan.x, scan.y, scan.bytes, kSeedEdge, kSeedEdge, slices);
}

/// `raw` compressed as one gzip member (the targets link zlib when they use it).
inline Bytes gzipBytes(const Bytes& raw) {
    z_stream z{};
    require(deflateInit2(&z, 6, Z_DEFLATED, 15 + 16, 8, Z_DEFAULT_STRATEGY) == Z_OK,
            "deflateInit2");
    Bytes out(deflateBound(&z, uLong(raw.size())) + 32);
    z.next_in = const_cast<Bytes::value_type*>(raw.data());
    z.avail_in = uInt(raw.size());
    z.next_out = out.data();
    z.avail_out = uInt(out.size());
    require(deflate(&z, Z_FINISH) == Z_STREAM_END, "deflate");
    out.resize(z.total_out);
    deflateEnd(&z);
    return out;
}

} // namespace bc::fuzz
