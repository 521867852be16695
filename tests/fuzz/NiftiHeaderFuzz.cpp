// libFuzzer target of the NIfTI-1 reader (scripts/fuzz.sh nifti_header builds and runs it).
//
// Input: the bytes of a .nii file (plain or gzip), written to a private scratch folder and
// opened with openNifti, as ingest would. A FormatError is the expected refusal; a crash,
// sanitizer report, other exception or a volume that validateVolumeInfo rejects is a finding.
// Slices are then read (tests/fuzz/ReaderFuzz.h).
//
// With BC_FUZZ_SEED_DIR set, the binary first writes seeds there from the real scans
// (BC_SHARED_DATA_DIR: CT_AVM.nii.gz, Iguana.nii.gz): each real header with its extensions and
// a truncated payload; the same header cropped to 2 slices (dim[3] = 2) with their voxels,
// plain and gzip; and a 16-bit scaled variant (datatype, scl_slope) for the converting path.
#include "brickstore/Readers.h"
#include "tests/fuzz/ReaderFuzz.h"

#include <cstring>
#include <zlib.h>

// After the standard headers: nifti1.h redefines DT_UNKNOWN, which <dirent.h> also declares.
#include <nifti1_io.h>

namespace {

using namespace bc;
using fuzz::Bytes;
using fuzz::gzipBytes;

/// The first `maxBytes` decompressed bytes of a gzip file.
Bytes gunzipPrefix(const std::string& path, std::size_t maxBytes) {
    gzFile file = gzopen(path.c_str(), "rb");
    if (!file) return {};
    Bytes bytes(maxBytes);
    const int got = gzread(file, bytes.data(), unsigned(maxBytes));
    gzclose(file);
    bytes.resize(got > 0 ? std::size_t(got) : 0);
    return bytes;
}

template <typename T> T field(const Bytes& b, std::size_t offset) {
    T v;
    std::memcpy(&v, b.data() + offset, sizeof(T));
    return v;
}

template <typename T> void setField(Bytes& b, std::size_t offset, T v) {
    std::memcpy(b.data() + offset, &v, sizeof(T));
}

// nifti_1_header offsets.
constexpr std::size_t kDim = 40, kDatatype = 70, kBitpix = 72, kVoxOffset = 108, kSclSlope = 112;

void writeScanSeeds(const std::string& seeds, const std::string& scan, const std::string& name) {
    const Bytes real = gunzipPrefix(scan, 1 << 20);
    if (real.size() < 352) return;
    const auto voxOffset = std::size_t(field<float>(real, kVoxOffset));
    const auto x = std::size_t(field<std::int16_t>(real, kDim + 2)),
               y = std::size_t(field<std::int16_t>(real, kDim + 4));
    const std::size_t bytesPerVoxel = std::size_t(field<std::int16_t>(real, kBitpix)) / 8;
    if (voxOffset < 348 || voxOffset > real.size()) return;
    // The real header and a truncated payload.
    Bytes truncated(real.begin(), real.begin() + std::ptrdiff_t(voxOffset + 4096));
    fuzz::writeSeed(seeds, name + "-truncated", truncated);
    // Cropped to 32x32x2 voxels: complete, so the voxels are read.
    const Bytes voxels = fuzz::cropVoxels(real, voxOffset, x, y, bytesPerVoxel, 32, 32, 2);
    if (voxels.empty()) return;
    Bytes cropped(real.begin(), real.begin() + std::ptrdiff_t(voxOffset));
    cropped.insert(cropped.end(), voxels.begin(), voxels.end());
    setField<std::int16_t>(cropped, kDim + 2, 32);
    setField<std::int16_t>(cropped, kDim + 4, 32);
    setField<std::int16_t>(cropped, kDim + 6, 2);
    fuzz::writeSeed(seeds, name + "-cropped", cropped);
    fuzz::writeSeed(seeds, name + "-cropped-gz", gzipBytes(cropped));
    // 16-bit voxels with an integer scaling (converted to i16) over a 8x8x2 crop.
    Bytes scaled(cropped.begin(), cropped.begin() + std::ptrdiff_t(voxOffset + 8 * 8 * 2 * 2));
    setField<std::int16_t>(scaled, kDim + 2, 8);
    setField<std::int16_t>(scaled, kDim + 4, 8);
    setField<std::int16_t>(scaled, kDatatype, 512); // DT_UINT16
    setField<std::int16_t>(scaled, kBitpix, 16);
    setField<float>(scaled, kSclSlope, 1.0f);
    setField<float>(scaled, kSclSlope + 4, -1024.0f);
    fuzz::writeSeed(seeds, name + "-scaled", scaled);
}

void writeSeeds(const std::string& seeds) {
    const std::string data = fuzz::sharedData();
    if (data.empty()) return;
    writeScanSeeds(seeds, data + "/CT_AVM.nii.gz", "ct-avm");
    writeScanSeeds(seeds, data + "/Iguana.nii.gz", "iguana");
}

} // namespace

extern "C" int LLVMFuzzerTestOneInput(const std::uint8_t* data, std::size_t size) {
    return fuzz::fuzzReader(data, size, (fuzz::scratchDir() / "volume.nii").string(),
                            brickstore::openNifti);
}

extern "C" int LLVMFuzzerInitialize(int*, char***) {
    nifti_set_debug_level(0);
    if (const std::string seeds = fuzz::envFolder("BC_FUZZ_SEED_DIR"); !seeds.empty())
        writeSeeds(seeds);
    return 0;
}
