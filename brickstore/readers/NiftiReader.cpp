// Single-file NIfTI-1 volumes (.nii, .nii.gz) as a slice stream. niftilib parses and byte-swaps
// the header; the voxels are streamed with its znzlib (plain or gzip) one bounded chunk at a
// time, so the volume never sits in memory whole. uint8/int16/uint16/float32 stay native;
// other scalar types and scl_slope/scl_inter scaling are converted on read to i16 (integer
// scaling whose full range fits) or f32.
#include "brickstore/Error.h"
#include "brickstore/Readers.h"
#include "brickstore/detail/RegularFile.h"

#include <algorithm>
#include <array>
#include <cmath>
#include <cstdint>
#include <cstdio>
#include <cstdlib>
#include <cstring>
#include <filesystem>
#include <fstream>
#include <limits>
#include <memory>
#include <utility>
#include <vector>

// After the standard headers: nifti1.h redefines DT_UNKNOWN, which <dirent.h> also declares.
#include <nifti1_io.h>
#include <znzlib.h>

namespace bc::brickstore {
namespace {

/// Voxels converted per staging step: bounds the reader's own memory whatever the slice size.
constexpr std::size_t kChunkVoxels = std::size_t(1) << 16;
/// Largest single znzread (gzread counts in unsigned int).
constexpr std::size_t kMaxReadBytes = std::size_t(1) << 28;

enum class InputKind { U8, I8, U16, I16, U32, I32, U64, I64, F32, F64 };

/// How the file stores one voxel.
struct InputType {
    InputKind kind;
    std::size_t bytes;
    const char* name;
};

/// The scalar datatypes brickcast reads; complex, RGB, bit and 128-bit types throw.
InputType inputTypeOf(const std::string& path, int datatype) {
    switch (datatype) {
    case DT_UINT8:
        return {InputKind::U8, 1, "uint8"};
    case DT_INT8:
        return {InputKind::I8, 1, "int8"};
    case DT_UINT16:
        return {InputKind::U16, 2, "uint16"};
    case DT_INT16:
        return {InputKind::I16, 2, "int16"};
    case DT_UINT32:
        return {InputKind::U32, 4, "uint32"};
    case DT_INT32:
        return {InputKind::I32, 4, "int32"};
    case DT_UINT64:
        return {InputKind::U64, 8, "uint64"};
    case DT_INT64:
        return {InputKind::I64, 8, "int64"};
    case DT_FLOAT32:
        return {InputKind::F32, 4, "float32"};
    case DT_FLOAT64:
        return {InputKind::F64, 8, "float64"};
    case DT_BINARY:
    case DT_COMPLEX64:
    case DT_COMPLEX128:
    case DT_COMPLEX256:
    case DT_RGB24:
    case DT_RGBA32:
    case DT_FLOAT128:
        throw FormatError(path, "datatype",
                          std::string(nifti_datatype_string(datatype)) + " (code " +
                              std::to_string(datatype) +
                              ") is not supported; only scalar integer and float volumes are");
    }
    throw FormatError(path, "datatype", "unknown datatype code " + std::to_string(datatype));
}

bool isFloat(InputKind k) {
    return k == InputKind::F32 || k == InputKind::F64;
}

/// Smallest and largest value of an integer input type.
std::array<double, 2> integerRange(InputKind k) {
    switch (k) {
    case InputKind::U8:
        return {0.0, 255.0};
    case InputKind::I8:
        return {-128.0, 127.0};
    case InputKind::U16:
        return {0.0, 65535.0};
    case InputKind::I16:
        return {-32768.0, 32767.0};
    case InputKind::U32:
        return {0.0, 4294967295.0};
    case InputKind::I32:
        return {-2147483648.0, 2147483647.0};
    case InputKind::U64:
        return {0.0, 18446744073709551615.0};
    default:
        return {-9223372036854775808.0, 9223372036854775807.0};
    }
}

/// value * slope + inter; the identity when scl_slope is 0 (NIfTI-1: no scaling).
struct Scaling {
    double slope = 1.0;
    double inter = 0.0;
    bool identity() const { return slope == 1.0 && inter == 0.0; }
};

std::string numberText(double v) {
    char text[32];
    std::snprintf(text, sizeof(text), "%g", v);
    return text;
}

/// A non-finite scl_slope or scl_inter is refused rather than read as "no scaling" (as
/// niftilib does): it says the header is damaged, and guessing would change every value.
Scaling scalingOf(const std::string& path, const nifti_1_header& hdr) {
    const std::pair<const char*, float> fields[2] = {{"scl_slope", hdr.scl_slope},
                                                     {"scl_inter", hdr.scl_inter}};
    for (const auto& [name, value] : fields)
        if (!std::isfinite(value))
            throw FormatError(path, name,
                              numberText(value) +
                                  " is not a finite number; NIfTI-1 scaling needs a finite "
                                  "scl_slope (0 = no scaling) and scl_inter");
    if (hdr.scl_slope == 0.0f) return {};
    return {hdr.scl_slope, hdr.scl_inter};
}

bool isSmallInteger(double v) {
    return v == std::floor(v) && std::abs(v) < 2147483648.0;
}

/// Native when the type is stored as is; i16 when integer scaling maps the type's whole range
/// into i16; f32 otherwise.
VoxelType storedTypeOf(const InputType& in, const Scaling& s) {
    if (s.identity()) {
        switch (in.kind) {
        case InputKind::U8:
            return VoxelType::U8;
        case InputKind::U16:
            return VoxelType::U16;
        case InputKind::I16:
            return VoxelType::I16;
        default:
            return VoxelType::F32;
        }
    }
    if (isFloat(in.kind) || !isSmallInteger(s.slope) || !isSmallInteger(s.inter))
        return VoxelType::F32;
    const auto range = integerRange(in.kind);
    const double a = range[0] * s.slope + s.inter, b = range[1] * s.slope + s.inter;
    const bool fits = std::min(a, b) >= -32768.0 && std::max(a, b) <= 32767.0;
    return fits ? VoxelType::I16 : VoxelType::F32;
}

struct HeaderDeleter {
    void operator()(nifti_1_header* hdr) const { std::free(hdr); }
};
using HeaderPtr = std::unique_ptr<nifti_1_header, HeaderDeleter>;

struct ZnzCloser {
    void operator()(znzptr* file) const { znzclose(file); }
};
using ZnzPtr = std::unique_ptr<znzptr, ZnzCloser>;

/// The raw header, byte-swapped to host order. niftilib's nifti_image_read is not used: it
/// rejects a bad header without saying which field, and silently replaces bad pixdims by 1.
HeaderPtr readHeader(const std::string& path, bool& swapped) {
    int swap = 0;
    HeaderPtr hdr(nifti_read_header(path.c_str(), &swap, 0));
    if (!hdr)
        throw FormatError(path, "header",
                          "cannot read a 348-byte NIfTI-1 header (missing or too short)");
    swapped = swap != 0;
    if (hdr->sizeof_hdr != 348)
        throw FormatError(path, "sizeof_hdr",
                          std::to_string(hdr->sizeof_hdr) +
                              " instead of 348: not NIfTI-1 (NIfTI-2 is not supported)");
    if (std::memcmp(hdr->magic, "ni1", 4) == 0)
        throw FormatError(path, "magic",
                          "a two-file NIfTI (.hdr/.img) pair; only single-file .nii is supported");
    if (std::memcmp(hdr->magic, "n+1", 4) != 0)
        throw FormatError(path, "magic", "not \"n+1\": not a single-file NIfTI-1 image");
    return hdr;
}

/// dims x, y, z; `volumes` gets the count of 3-D volumes in dims 4..7 (only the first is read).
std::array<std::uint64_t, 3> dimsOf(const std::string& path, const nifti_1_header& hdr,
                                    std::uint64_t& volumes) {
    const int rank = hdr.dim[0];
    if (rank < 1 || rank > 7)
        throw FormatError(path, "dims",
                          "dim[0] = " + std::to_string(rank) + " is not a rank between 1 and 7");
    std::array<std::uint64_t, 3> dims{1, 1, 1};
    volumes = 1;
    for (int i = 1; i <= rank; ++i) {
        if (hdr.dim[i] < 0 || (i > 3 && hdr.dim[i] == 0))
            throw FormatError(path, "dims",
                              "dim[" + std::to_string(i) + "] = " + std::to_string(hdr.dim[i]) +
                                  (hdr.dim[i] < 0 ? " is negative" : " is zero"));
        if (i <= 3)
            dims[i - 1] = std::uint64_t(hdr.dim[i]);
        else
            volumes *= std::uint64_t(hdr.dim[i]); // int16 factors: cannot overflow
    }
    return dims;
}

/// pixdim[1..3] as given: zero, negative or NaN spacing is left for validateVolumeInfo to reject.
std::array<double, 3> spacingOf(const nifti_1_header& hdr) {
    std::array<double, 3> spacing{1, 1, 1};
    for (int i = 1; i <= 3 && i <= hdr.dim[0]; ++i)
        spacing[i - 1] = hdr.pixdim[i];
    return spacing;
}

/// Translation of the sform (preferred) or qform; axis-aligned approximation of the position.
std::array<double, 3> originOf(const nifti_1_header& hdr) {
    std::array<double, 3> origin{0, 0, 0};
    if (hdr.sform_code > 0)
        origin = {hdr.srow_x[3], hdr.srow_y[3], hdr.srow_z[3]};
    else if (hdr.qform_code > 0)
        origin = {hdr.qoffset_x, hdr.qoffset_y, hdr.qoffset_z};
    for (double& o : origin)
        if (!std::isfinite(o)) o = 0.0;
    return origin;
}

std::uint64_t voxOffsetOf(const std::string& path, const nifti_1_header& hdr) {
    const double offset = hdr.vox_offset;
    if (!std::isfinite(offset) || offset < 348.0 || offset != std::floor(offset) || offset > 1e15)
        throw FormatError(path, "vox_offset",
                          std::to_string(offset) +
                              " is not a whole byte offset at or after the 348-byte header");
    return std::uint64_t(offset);
}

bool isGzip(const std::string& path) {
    std::ifstream in(path, std::ios::binary);
    unsigned char magic[2] = {0, 0};
    in.read(reinterpret_cast<char*>(magic), 2);
    return in.gcount() == 2 && magic[0] == 0x1f && magic[1] == 0x8b;
}

/// A plain file must hold the voxels; a gzip file must be large enough to inflate to them
/// (a truncated one can only fail when read, see readExact).
void checkFileHolds(const std::string& path, const VolumeInfo& info, std::uint64_t voxOffset,
                    std::uint64_t dataBytes) {
    std::error_code ec;
    const std::uint64_t size = std::filesystem::file_size(path, ec);
    if (ec) throw FormatError(path, "file", "cannot get its size: " + ec.message());
    if (isGzip(path)) {
        checkCompressedPayload(info, voxOffset + dataBytes, size, "gzip", kMaxGzipRatio, path);
        return;
    }
    if (size < voxOffset || size - voxOffset < dataBytes)
        throw FormatError(path, "data",
                          "truncated: the header promises " + std::to_string(dataBytes) +
                              " bytes of voxels at offset " + std::to_string(voxOffset) +
                              " but the file holds " + std::to_string(size) + " bytes");
}

void swapElements(std::byte* data, std::size_t count, std::size_t bytes) {
    if (bytes == 1) return;
    for (std::size_t i = 0; i < count; ++i)
        std::reverse(data + i * bytes, data + (i + 1) * bytes);
}

/// Out-of-range values become infinities (a plain cast is undefined) for checkFinite to report.
float toFloat(double v) {
    constexpr double kMax = std::numeric_limits<float>::max();
    if (std::isnan(v) || std::abs(v) <= kMax) return float(v);
    return v > 0 ? std::numeric_limits<float>::infinity() : -std::numeric_limits<float>::infinity();
}

template <typename T> T load(const std::byte* data, std::size_t i) {
    T v;
    std::memcpy(&v, data + i * sizeof(T), sizeof(T));
    return v;
}

template <typename T> void store(std::byte* data, std::size_t i, T v) {
    std::memcpy(data + i * sizeof(T), &v, sizeof(T));
}

/// Converts `count` host-order inputs of type T to i16 (exact integer scaling) or f32.
template <typename T>
void convertTo(const std::byte* in, std::size_t count, const Scaling& s, VoxelType out,
               std::byte* dst) {
    if (out == VoxelType::I16) {
        const auto slope = std::int64_t(s.slope), inter = std::int64_t(s.inter);
        for (std::size_t i = 0; i < count; ++i)
            store(dst, i, std::int16_t(std::int64_t(load<T>(in, i)) * slope + inter));
        return;
    }
    for (std::size_t i = 0; i < count; ++i)
        store(dst, i, toFloat(double(load<T>(in, i)) * s.slope + s.inter));
}

void convert(InputKind kind, const std::byte* in, std::size_t count, const Scaling& s,
             VoxelType out, std::byte* dst) {
    switch (kind) {
    case InputKind::U8:
        return convertTo<std::uint8_t>(in, count, s, out, dst);
    case InputKind::I8:
        return convertTo<std::int8_t>(in, count, s, out, dst);
    case InputKind::U16:
        return convertTo<std::uint16_t>(in, count, s, out, dst);
    case InputKind::I16:
        return convertTo<std::int16_t>(in, count, s, out, dst);
    case InputKind::U32:
        return convertTo<std::uint32_t>(in, count, s, out, dst);
    case InputKind::I32:
        return convertTo<std::int32_t>(in, count, s, out, dst);
    case InputKind::U64:
        return convertTo<std::uint64_t>(in, count, s, out, dst);
    case InputKind::I64:
        return convertTo<std::int64_t>(in, count, s, out, dst);
    case InputKind::F32:
        return convertTo<float>(in, count, s, out, dst);
    case InputKind::F64:
        return convertTo<double>(in, count, s, out, dst);
    }
}

class NiftiVolume final : public VolumeSource {
  public:
    NiftiVolume(const std::string& path, const nifti_1_header& hdr, bool swapped)
        : mPath(path), mInput(inputTypeOf(path, hdr.datatype)), mScaling(scalingOf(path, hdr)),
          mSwapped(swapped) {
        std::uint64_t volumes = 1;
        mInfo.dims = dimsOf(path, hdr, volumes);
        recordScalingOfNativeInput();
        mInfo.type = storedTypeOf(mInput, mScaling);
        mInfo.spacingMm = spacingOf(hdr);
        mInfo.originMm = originOf(hdr);
        validateVolumeInfo(mInfo, path);
        mInfo.description = describe(volumes);
        std::uint64_t dataBytes = 0;
        if (!checkedVolumeBytes(mInfo.dims, mInput.bytes, dataBytes))
            throw FormatError(path, "dims", "byte size of the volume overflows 64 bits");
        const std::uint64_t voxOffset = voxOffsetOf(path, hdr);
        checkFileHolds(path, mInfo, voxOffset, dataBytes);
        open(voxOffset);
    }

    const VolumeInfo& info() const override { return mInfo; }

  private:
    void readNextSlices(std::uint64_t count, std::span<std::byte> out) override {
        const std::size_t voxels = std::size_t(count * mInfo.dims[0] * mInfo.dims[1]);
        if (isNative()) {
            readExact(out.data(), out.size());
            if (mSwapped) swapElements(out.data(), voxels, mInput.bytes);
        } else {
            readConverted(voxels, out.data());
        }
        if (mInfo.type == VoxelType::F32) checkFinite(out.data(), voxels);
    }

    /// A natively stored input whose scaling is not an exact integer map into i16 keeps its
    /// type: the scaling is recorded in VolumeInfo (valueScale/valueOffset) instead of
    /// applied, so CT_AVM's u8 voxels stay u8 rather than growing into f32.
    void recordScalingOfNativeInput() {
        if (mScaling.identity() || isFloat(mInput.kind)) return;
        const bool nativeKind = mInput.kind == InputKind::U8 || mInput.kind == InputKind::U16 ||
                                mInput.kind == InputKind::I16;
        if (!nativeKind || storedTypeOf(mInput, mScaling) == VoxelType::I16) return;
        mInfo.valueScale = mScaling.slope;
        mInfo.valueOffset = mScaling.inter;
        mScaling = {};
    }

    bool isNative() const {
        return mScaling.identity() &&
               (mInput.kind == InputKind::U8 || mInput.kind == InputKind::U16 ||
                mInput.kind == InputKind::I16 || mInput.kind == InputKind::F32);
    }

    std::string describe(std::uint64_t volumes) const {
        std::string text = "NIfTI-1 " + std::filesystem::path(mPath).filename().string() + ", ";
        const std::string stored(voxelTypeName(mInfo.type));
        if (!mScaling.identity())
            text += std::string(mInput.name) + " scaled by scl_slope " +
                    numberText(mScaling.slope) + ", scl_inter " + numberText(mScaling.inter) +
                    " to " + stored;
        else if (isNative())
            text += stored;
        else
            text += std::string(mInput.name) + " converted to " + stored;
        if (mInfo.valueScale != 1.0 || mInfo.valueOffset != 0.0)
            text += " with scl_slope " + numberText(mInfo.valueScale) + ", scl_inter " +
                    numberText(mInfo.valueOffset) + " recorded (physical = stored x slope + inter)";
        if (volumes > 1) text += ", first of " + std::to_string(volumes) + " volumes";
        return text;
    }

    void open(std::uint64_t voxOffset) {
        mFile.reset(znzopen(mPath.c_str(), "rb", 1));
        if (!mFile) throw FormatError(mPath, "file", "cannot open it for reading");
        if (znzseek(mFile.get(), znz_off_t(voxOffset), SEEK_SET) < 0)
            throw FormatError(mPath, "vox_offset",
                              "cannot seek to the voxels at offset " + std::to_string(voxOffset) +
                                  ": the file is shorter");
    }

    void readExact(std::byte* dst, std::size_t bytes) {
        while (bytes > 0) {
            const std::size_t want = std::min(bytes, kMaxReadBytes);
            const std::size_t got = znzread(dst, 1, want, mFile.get());
            if (got != want)
                throw FormatError(
                    mPath, "data",
                    "the voxels end early, at or after slice " + std::to_string(nextSlice()) +
                        " of " + std::to_string(mInfo.dims[2]) + " (truncated or corrupt file)");
            dst += got;
            bytes -= got;
        }
    }

    void readConverted(std::size_t voxels, std::byte* dst) {
        mStaging.resize(std::min(voxels, kChunkVoxels) * mInput.bytes);
        const std::size_t outBytes = voxelBytes(mInfo.type);
        for (std::size_t done = 0; done < voxels;) {
            const std::size_t n = std::min(voxels - done, kChunkVoxels);
            readExact(mStaging.data(), n * mInput.bytes);
            if (mSwapped) swapElements(mStaging.data(), n, mInput.bytes);
            convert(mInput.kind, mStaging.data(), n, mScaling, mInfo.type, dst + done * outBytes);
            done += n;
        }
    }

    void checkFinite(const std::byte* data, std::size_t voxels) const {
        for (std::size_t i = 0; i < voxels; ++i) {
            if (std::isfinite(load<float>(data, i))) continue;
            const std::uint64_t sliceVoxels = mInfo.dims[0] * mInfo.dims[1];
            const std::uint64_t x = i % mInfo.dims[0], y = (i % sliceVoxels) / mInfo.dims[0];
            const std::uint64_t z = nextSlice() + i / sliceVoxels;
            throw FormatError(mPath, "data",
                              "voxel (" + std::to_string(x) + "," + std::to_string(y) + "," +
                                  std::to_string(z) + ") is " + numberText(load<float>(data, i)) +
                                  ", not a finite f32");
        }
    }

    std::string mPath;
    InputType mInput;
    Scaling mScaling;
    bool mSwapped;
    VolumeInfo mInfo;
    ZnzPtr mFile;
    std::vector<std::byte> mStaging; ///< one chunk of file-typed voxels awaiting conversion
};

} // namespace

std::unique_ptr<VolumeSource> openNifti(const std::string& path) {
    detail::requireRegularFile(path);
    bool swapped = false;
    HeaderPtr hdr = readHeader(path, swapped);
    return std::make_unique<NiftiVolume>(path, *hdr, swapped);
}

} // namespace bc::brickstore
