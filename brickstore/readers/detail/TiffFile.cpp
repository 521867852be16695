// libtiff under the TIFF reader (TiffFile.h): opening with per-open limits and error handlers,
// page layouts checked against what brickcast reads, strips and tiles decoded into a slice.
#include "brickstore/readers/detail/TiffFile.h"

#include "brickstore/Error.h"
#include "brickstore/VolumeSource.h"

#include <algorithm>
#include <cerrno>
#include <cstdio>
#include <cstring>
#include <new>

#include <fcntl.h>
#include <sys/stat.h>
#include <tiffio.h>
#include <unistd.h>

namespace bc::brickstore::detail {
namespace {

/// libtiff's largest single allocation: a compressed strip or tile it reads whole, a tag's
/// array. Uncompressed data goes straight into the caller's slice and needs none.
constexpr std::uint64_t kMaxLibtiffAllocBytes = 512ull << 20;
/// Largest tile the reader buffers; real writers use 16..1024-voxel tiles, far below.
constexpr std::uint64_t kMaxTileBytes = 256ull << 20;
/// An ImageDescription longer than this is not read further (a spacing is near its start).
constexpr std::size_t kMaxDescriptionBytes = 64 << 10;

/// libtiff's warnings (unknown private tags of ImageJ or tifffile, say) are not errors and
/// must not reach the user's terminal.
int ignoreWarning(TIFF*, void*, const char*, const char*, va_list) {
    return 1;
}

std::string count(std::uint64_t n, const char* what) {
    return std::to_string(n) + " " + what + (n == 1 ? "" : "s");
}

/// The voxel type of a supported (bits, format) pair, or nothing.
bool voxelTypeOf(std::uint16_t bits, std::uint16_t format, VoxelType& type) {
    if (bits == 8 && format == SAMPLEFORMAT_UINT)
        type = VoxelType::U8;
    else if (bits == 16 && format == SAMPLEFORMAT_UINT)
        type = VoxelType::U16;
    else if (bits == 16 && format == SAMPLEFORMAT_INT)
        type = VoxelType::I16;
    else if (bits == 32 && format == SAMPLEFORMAT_IEEEFP)
        type = VoxelType::F32;
    else
        return false;
    return true;
}

const char* sampleFormatName(std::uint16_t format) {
    switch (format) {
    case SAMPLEFORMAT_UINT:
        return "unsigned integer";
    case SAMPLEFORMAT_INT:
        return "signed integer";
    case SAMPLEFORMAT_IEEEFP:
        return "floating-point";
    default:
        return "other";
    }
}

bool isSupportedCompression(std::uint16_t compression) {
    switch (compression) {
    case COMPRESSION_NONE:
    case COMPRESSION_LZW:
    case COMPRESSION_ADOBE_DEFLATE:
    case COMPRESSION_DEFLATE:
    case COMPRESSION_ZSTD:
        return TIFFIsCODECConfigured(compression) != 0;
    default:
        return false;
    }
}

} // namespace

const char* compressionName(std::uint16_t compression) {
    switch (compression) {
    case COMPRESSION_NONE:
        return "uncompressed";
    case COMPRESSION_LZW:
        return "LZW";
    case COMPRESSION_ADOBE_DEFLATE:
    case COMPRESSION_DEFLATE:
        return "deflate";
    case COMPRESSION_ZSTD:
        return "zstd";
    default:
        return "unsupported";
    }
}

TiffFile::TiffFile(const std::string& path, bool namePages) : mPath(path), mNamePages(namePages) {
    TIFFOpenOptions* options = TIFFOpenOptionsAlloc();
    if (!options) throw std::bad_alloc();
    TIFFOpenOptionsSetMaxSingleMemAlloc(options, tmsize_t(kMaxLibtiffAllocBytes));
    TIFFOpenOptionsSetErrorHandlerExtR(options, &TiffFile::onError, this);
    TIFFOpenOptionsSetWarningHandlerExtR(options, &ignoreWarning, nullptr);
    // "m": no memory mapping, so a file larger than the sandbox's address space still reads;
    // "O": strip and tile offsets are read when a strip is, not all with the page header.
    mTiff = TIFFOpenExt(path.c_str(), "rmO", options);
    TIFFOpenOptionsFree(options);
    if (!mTiff)
        throw FormatError(path, "header",
                          "libtiff cannot open it as a TIFF file (libtiff: " + mError + ")");
    struct stat st {};
    if (::fstat(TIFFFileno(mTiff), &st) != 0) {
        TIFFClose(mTiff);
        throw FormatError(path, "path", std::string("cannot stat: ") + std::strerror(errno));
    }
    mFileBytes = std::uint64_t(st.st_size);
}

TiffFile::~TiffFile() {
    mAhead.reset(); // its thread reads the file's descriptor
    if (mTiff) TIFFClose(mTiff);
}

int TiffFile::onError(TIFF*, void* self, const char*, const char* format, va_list args) {
    std::string& error = static_cast<TiffFile*>(self)->mError;
    if (!error.empty()) return 1; // the first error says why; the later ones say what failed
    char text[400];
    std::vsnprintf(text, sizeof text, format, args);
    error = text;
    return 1;
}

bool TiffFile::bigTiff() const {
    return TIFFIsBigTIFF(mTiff) != 0;
}

std::string TiffFile::where() const {
    return mNamePages ? "page " + std::to_string(mPage + 1) + ": " : "";
}

void TiffFile::fail(const std::string& field, const std::string& why) const {
    const std::string libtiff = mError.empty() ? "" : " (libtiff: " + mError + ")";
    mError.clear();
    throw FormatError(mPath, field, where() + why + libtiff);
}

bool TiffFile::nextPage() {
    if (TIFFLastDirectory(mTiff)) return false;
    mError.clear();
    ++mPage;
    if (!TIFFReadDirectory(mTiff)) fail("header", "the page's header (IFD) cannot be read");
    return true;
}

void TiffFile::rewind() {
    mError.clear();
    mPage = 0;
    if (!TIFFSetDirectory(mTiff, 0)) fail("header", "the first page's header cannot be read");
}

TiffPage TiffFile::layout() const {
    TiffPage p;
    std::uint16_t samples = 1, photometric = PHOTOMETRIC_MINISBLACK;
    std::uint32_t depth = 1;
    if (!TIFFGetField(mTiff, TIFFTAG_IMAGEWIDTH, &p.width)) fail("ImageWidth", "is missing");
    if (!TIFFGetField(mTiff, TIFFTAG_IMAGELENGTH, &p.length)) fail("ImageLength", "is missing");
    TIFFGetFieldDefaulted(mTiff, TIFFTAG_SAMPLESPERPIXEL, &samples);
    TIFFGetFieldDefaulted(mTiff, TIFFTAG_BITSPERSAMPLE, &p.bitsPerSample);
    TIFFGetFieldDefaulted(mTiff, TIFFTAG_SAMPLEFORMAT, &p.sampleFormat);
    TIFFGetFieldDefaulted(mTiff, TIFFTAG_COMPRESSION, &p.compression);
    TIFFGetFieldDefaulted(mTiff, TIFFTAG_IMAGEDEPTH, &depth);
    TIFFGetField(mTiff, TIFFTAG_PHOTOMETRIC, &photometric);
    if (depth != 1)
        fail("ImageDepth", std::to_string(depth) + "-deep volumetric pages are not supported");
    p.tiled = TIFFIsTiled(mTiff) != 0;
    if (p.tiled) {
        TIFFGetField(mTiff, TIFFTAG_TILEWIDTH, &p.tileWidth);
        TIFFGetField(mTiff, TIFFTAG_TILELENGTH, &p.tileLength);
    } else {
        TIFFGetFieldDefaulted(mTiff, TIFFTAG_ROWSPERSTRIP, &p.rowsPerStrip);
    }
    checkSupported(p, samples, photometric);
    voxelTypeOf(p.bitsPerSample, p.sampleFormat, p.type);
    return p;
}

void TiffFile::checkSupported(const TiffPage& p, std::uint16_t samples,
                              std::uint16_t photometric) const {
    if (samples != 1)
        fail("SamplesPerPixel", std::to_string(samples) +
                                    " samples per pixel (colour or alpha); brickcast reads "
                                    "greyscale, one sample per pixel");
    const char* kTypes = "; brickcast reads 8- and 16-bit unsigned, 16-bit signed and 32-bit "
                         "floating-point samples";
    if (p.bitsPerSample != 8 && p.bitsPerSample != 16 && p.bitsPerSample != 32)
        fail("BitsPerSample", std::to_string(p.bitsPerSample) + " bits per sample" + kTypes);
    VoxelType type;
    if (!voxelTypeOf(p.bitsPerSample, p.sampleFormat, type))
        fail("SampleFormat", std::to_string(p.bitsPerSample) + "-bit " +
                                 sampleFormatName(p.sampleFormat) + " samples (SampleFormat " +
                                 std::to_string(p.sampleFormat) + ")" + kTypes);
    if (photometric != PHOTOMETRIC_MINISBLACK)
        fail("PhotometricInterpretation",
             std::to_string(photometric) +
                 (photometric == PHOTOMETRIC_PALETTE ? " (palette colour)" : "") +
                 "; brickcast reads min-is-black (1) greyscale");
    if (!isSupportedCompression(p.compression))
        fail("Compression", std::to_string(p.compression) +
                                " is not read; brickcast reads uncompressed (1), LZW (5), "
                                "deflate (8, 32946) and zstd (50000) pages");
    if (!p.tiled && p.rowsPerStrip == 0) fail("RowsPerStrip", "is 0");
    if (!p.tiled) return;
    if (p.tileWidth == 0 || p.tileWidth > kMaxDimVoxels)
        fail("TileWidth", std::to_string(p.tileWidth) + " is not a usable tile width");
    if (p.tileLength == 0 || p.tileLength > kMaxDimVoxels)
        fail("TileLength", std::to_string(p.tileLength) + " is not a usable tile length");
    const std::uint64_t tileBytes = std::uint64_t(p.tileWidth) * p.tileLength * voxelBytes(type);
    if (tileBytes > kMaxTileBytes)
        fail("TileWidth", "tiles of " + std::to_string(p.tileWidth) + "x" +
                              std::to_string(p.tileLength) + " voxels exceed the limit of " +
                              bytesText(double(kMaxTileBytes)) + " per tile");
}

std::string TiffFile::description() const {
    const char* text = nullptr;
    if (!TIFFGetField(mTiff, TIFFTAG_IMAGEDESCRIPTION, &text) || !text) return {};
    return std::string(text, ::strnlen(text, kMaxDescriptionBytes));
}

TiffResolution TiffFile::resolution() const {
    TiffResolution r;
    float x = 0, y = 0;
    if (!TIFFGetField(mTiff, TIFFTAG_XRESOLUTION, &x)) return r;
    r.present = true;
    r.x = x;
    r.y = TIFFGetField(mTiff, TIFFTAG_YRESOLUTION, &y) ? y : x;
    TIFFGetFieldDefaulted(mTiff, TIFFTAG_RESOLUTIONUNIT, &r.unit);
    return r;
}

std::uint64_t TiffFile::checkStrile(std::uint32_t index, bool tiled, const char* kind) const {
    int offsetError = 0, bytesError = 0;
    const std::uint64_t offset = TIFFGetStrileOffsetWithErr(mTiff, index, &offsetError);
    const std::uint64_t bytes = TIFFGetStrileByteCountWithErr(mTiff, index, &bytesError);
    const std::string name = std::string(kind) + " " + std::to_string(index);
    if (offsetError || bytesError)
        fail(tiled ? "TileOffsets" : "StripOffsets", name + " has no offset or byte count");
    if (offset > mFileBytes || bytes > mFileBytes - offset)
        fail(tiled ? "TileByteCounts" : "StripByteCounts",
             name + " (" + std::to_string(bytes) + " bytes at offset " + std::to_string(offset) +
                 ") runs past the end of the file (" + std::to_string(mFileBytes) +
                 " bytes); is it truncated?");
    return offset + bytes;
}

void TiffFile::readAhead() {
    if (!mAhead) mAhead = std::make_unique<ReadAhead>(TIFFFileno(mTiff), mReadEnd, mFileBytes);
    mAhead->reached(mReadEnd);
}

void TiffFile::readPage(const TiffPage& page, std::span<std::byte> out) {
    if (page.tiled)
        readTiles(page, out);
    else
        readStrips(page, out);
}

void TiffFile::readStrips(const TiffPage& page, std::span<std::byte> out) {
    const std::uint64_t rowBytes = std::uint64_t(page.width) * voxelBytes(page.type);
    const std::uint64_t rows = std::min<std::uint64_t>(page.rowsPerStrip, page.length);
    const std::uint64_t strips = checkStrips(page);
    for (std::uint32_t s = 0; s < strips; ++s) {
        const std::uint64_t first = s * rows, n = std::min(rows, page.length - first);
        mReadEnd = std::max(mReadEnd, checkStrile(s, false, "strip"));
        mError.clear();
        const auto want = tmsize_t(n * rowBytes);
        if (TIFFReadEncodedStrip(mTiff, s, out.data() + first * rowBytes, want) != want)
            fail("data", "strip " + std::to_string(s) + " (" + compressionName(page.compression) +
                             ") cannot be read or decoded");
    }
}

std::uint64_t TiffFile::checkStrips(const TiffPage& page) const {
    const std::uint64_t rows = std::min<std::uint64_t>(page.rowsPerStrip, page.length);
    const std::uint64_t strips = (page.length + rows - 1) / rows;
    if (TIFFNumberOfStrips(mTiff) < strips)
        fail("StripOffsets", "holds " + count(TIFFNumberOfStrips(mTiff), "strip") + ", not the " +
                                 std::to_string(strips) + " ImageLength and RowsPerStrip need");
    return strips;
}

bool TiffFile::locateStrips(const TiffPage& page, std::uint32_t file,
                            std::vector<FileExtent>& out) {
    std::uint16_t fillOrder = FILLORDER_MSB2LSB;
    TIFFGetFieldDefaulted(mTiff, TIFFTAG_FILLORDER, &fillOrder);
    // libtiff reverses the bits of LSB-first bytes and swaps the bytes of a file in the other
    // byte order: such pages are decoded, as are compressed and tiled ones.
    if (page.tiled || page.compression != COMPRESSION_NONE || fillOrder != FILLORDER_MSB2LSB ||
        (TIFFIsByteSwapped(mTiff) && voxelBytes(page.type) > 1))
        return false;
    const std::uint64_t rowBytes = std::uint64_t(page.width) * voxelBytes(page.type);
    const std::uint64_t rows = std::min<std::uint64_t>(page.rowsPerStrip, page.length);
    const std::uint64_t strips = checkStrips(page);
    for (std::uint32_t s = 0; s < strips; ++s) {
        const std::uint64_t want = std::min(rows, page.length - s * rows) * rowBytes;
        const std::uint64_t end = checkStrile(s, false, "strip");
        const std::uint64_t offset = TIFFGetStrileOffset(mTiff, s);
        // libtiff refuses an uncompressed strip shorter than its rows ("Not enough data").
        if (end - offset < want)
            fail("StripByteCounts", "strip " + std::to_string(s) + " holds " +
                                        std::to_string(end - offset) + " bytes; its rows need " +
                                        std::to_string(want) + " uncompressed");
        mReadEnd = std::max(mReadEnd, end);
        if (!out.empty() && out.back().file == file &&
            out.back().offset + out.back().bytes == offset)
            out.back().bytes += want;
        else
            out.push_back({file, offset, want});
    }
    return true;
}

void TiffFile::readTiles(const TiffPage& page, std::span<std::byte> out) {
    const std::size_t voxel = voxelBytes(page.type);
    const std::uint64_t tileRowBytes = std::uint64_t(page.tileWidth) * voxel;
    const auto tileBytes = tmsize_t(tileRowBytes * page.tileLength);
    const std::uint64_t across = (page.width + page.tileWidth - 1) / page.tileWidth,
                        down = (page.length + page.tileLength - 1) / page.tileLength;
    if (TIFFNumberOfTiles(mTiff) < across * down)
        fail("TileOffsets", "holds " + count(TIFFNumberOfTiles(mTiff), "tile") + ", not the " +
                                std::to_string(across * down) + " the image and tile sizes need");
    mTile.resize(std::size_t(tileBytes));
    const std::uint64_t rowBytes = std::uint64_t(page.width) * voxel;
    for (std::uint32_t y = 0; y < page.length; y += page.tileLength) {
        const std::uint32_t rows = std::min(page.tileLength, page.length - y);
        for (std::uint32_t x = 0; x < page.width; x += page.tileWidth) {
            const std::uint32_t tile = TIFFComputeTile(mTiff, x, y, 0, 0);
            mReadEnd = std::max(mReadEnd, checkStrile(tile, true, "tile"));
            mError.clear();
            if (TIFFReadEncodedTile(mTiff, tile, mTile.data(), tileBytes) != tileBytes)
                fail("data", "tile " + std::to_string(tile) + " (" +
                                 compressionName(page.compression) + ") cannot be read or decoded");
            const std::uint64_t width = std::min(page.tileWidth, page.width - x) * voxel;
            for (std::uint32_t r = 0; r < rows; ++r)
                std::memcpy(out.data() + (y + r) * rowBytes + x * voxel,
                            mTile.data() + r * tileRowBytes, width);
        }
    }
}

} // namespace bc::brickstore::detail
