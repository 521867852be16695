// VTK XML image data (.vti): the markup is parsed by expat (detail/VtiXml.h), bounded in size
// and stopping before the appended data; the chosen array's bytes then stream from the file
// (detail/VtiStreams.h): raw or base64, whole or in vtkZLibDataCompressor blocks, each block
// inflated straight into the caller's slices. Memory: the markup (at most 1 MiB while parsed),
// a 64 KiB input buffer per stream and zlib's window, never a block or the volume.
//
// A binary array starts with a header of UInt32 or UInt64 numbers (the file's header_type,
// in its byte order): uncompressed, the array's byte count; compressed, [number of blocks,
// block size, last block's size (0: full), compressed size of each block], then the blocks.
// In base64, an uncompressed array's header and data are one base64 text; a compressed
// array's header is a base64 text of its own (padded) and its blocks follow as another.
#include "brickstore/Error.h"
#include "brickstore/Readers.h"
#include "brickstore/detail/RegularFile.h"
#include "brickstore/readers/detail/RawStream.h"
#include "brickstore/readers/detail/VtiStreams.h"
#include "brickstore/readers/detail/VtiXml.h"

#include <filesystem>
#include <limits>

namespace bc::brickstore {

namespace {

using detail::ByteStream;
using detail::VtiEncoding;
using detail::VtiLayout;

/// Everything a data stream needs to know of the file.
struct VtiFile {
    std::string path;
    VtiLayout layout;
    std::uint64_t declaredBytes = 0; ///< voxels * voxel bytes, from WholeExtent
};

bool isBase64(const VtiLayout& l) {
    return l.encoding != VtiEncoding::AppendedRaw;
}

/// The file's bytes from `from` to the end of the array's region.
std::unique_ptr<ByteStream> region(const VtiFile& f, std::uint64_t from) {
    return detail::openWindow(detail::openFileStream(f.path, from), f.layout.dataEnd - from);
}

/// Binary bytes at most the region from `from` can hold (base64: 3 bytes per 4 characters).
std::uint64_t capacity(const VtiFile& f, std::uint64_t from) {
    const std::uint64_t chars = f.layout.dataEnd - from;
    return isBase64(f.layout) ? chars / 4 * 3 : chars;
}

std::uint64_t readNumber(ByteStream& in, const VtiFile& f, const std::string& field,
                         const std::string& what) {
    return detail::readHeaderNumber(in, f.layout.headerBytes, f.layout.endian, f.path, field, what);
}

std::string arrayText(const VtiFile& f) {
    return "array '" + f.layout.arrayName + "'";
}

/// An uncompressed array: its byte count, then its bytes.
std::unique_ptr<ByteStream> openPlain(const VtiFile& f) {
    const VtiLayout& l = f.layout;
    std::unique_ptr<ByteStream> in = region(f, l.dataBegin);
    if (isBase64(l)) in = std::make_unique<detail::Base64Stream>(std::move(in), f.path);
    const std::uint64_t bytes = readNumber(*in, f, "header", arrayText(f) + "'s byte count");
    if (bytes != f.declaredBytes)
        throw FormatError(f.path, "header",
                          arrayText(f) + " holds " + std::to_string(bytes) +
                              " bytes; WholeExtent " + dimsText(l.info.dims) + " of " +
                              std::string(voxelTypeName(l.info.type)) + " needs " +
                              std::to_string(f.declaredBytes));
    if (bytes > capacity(f, l.dataBegin) - l.headerBytes)
        throw FormatError(f.path, "size",
                          arrayText(f) + " needs " + std::to_string(bytes) +
                              " bytes, the file holds at most " +
                              std::to_string(capacity(f, l.dataBegin) - l.headerBytes) +
                              " after its header (truncated?)");
    return in;
}

/// Reads and checks the first three numbers of a compressed array's header.
detail::VtiBlocks readBlockShape(ByteStream& head, const VtiFile& f) {
    detail::VtiBlocks b;
    b.headerBytes = f.layout.headerBytes;
    b.endian = f.layout.endian;
    b.count = readNumber(head, f, "block header", "number of blocks");
    b.blockBytes = readNumber(head, f, "block header", "block size");
    b.lastBytes = readNumber(head, f, "block header", "last block's size");
    const std::string shape = std::to_string(b.count) + " blocks of " +
                              std::to_string(b.blockBytes) + " bytes, the last " +
                              std::to_string(b.lastBytes);
    if (b.count == 0 || b.blockBytes == 0 || b.lastBytes > b.blockBytes ||
        b.count - 1 > f.declaredBytes / b.blockBytes)
        throw FormatError(f.path, "block header",
                          arrayText(f) + ": " + shape + " cannot hold its " +
                              std::to_string(f.declaredBytes) + " bytes");
    const std::uint64_t total =
        (b.count - 1) * b.blockBytes + (b.lastBytes ? b.lastBytes : b.blockBytes);
    if (total != f.declaredBytes)
        throw FormatError(f.path, "block header",
                          arrayText(f) + ": " + shape + " hold " + std::to_string(total) +
                              " bytes; WholeExtent " + dimsText(f.layout.info.dims) + " needs " +
                              std::to_string(f.declaredBytes));
    return b;
}

/// Sums the blocks' compressed sizes, each checked: at least 1 byte, and able to inflate to
/// its block (zlib expands at most kMaxGzipRatio:1).
std::uint64_t sumBlockSizes(ByteStream& head, const detail::VtiBlocks& b, const VtiFile& f) {
    std::uint64_t sum = 0;
    for (std::uint64_t i = 0; i < b.count; ++i) {
        const std::string what = "compressed size of block " + std::to_string(i);
        const std::uint64_t size = readNumber(head, f, "block header", what);
        const std::uint64_t out = i + 1 == b.count && b.lastBytes ? b.lastBytes : b.blockBytes;
        if (size == 0 || size > std::numeric_limits<std::uint64_t>::max() - sum ||
            size < (out + kMaxGzipRatio - 1) / kMaxGzipRatio)
            throw FormatError(f.path, "block header",
                              what + " is " + std::to_string(size) +
                                  " bytes; it cannot inflate to the block's " +
                                  std::to_string(out));
        sum += size;
    }
    return sum;
}

/// A vtkZLibDataCompressor array: the block header is read twice, once here to check every
/// size against the file before anything is inflated, then block by block while streaming.
std::unique_ptr<ByteStream> openBlocks(const VtiFile& f) {
    const VtiLayout& l = f.layout;
    std::unique_ptr<ByteStream> head = region(f, l.dataBegin);
    detail::Base64Stream* text = nullptr;
    if (isBase64(l)) {
        auto decoded = std::make_unique<detail::Base64Stream>(std::move(head), f.path);
        text = decoded.get();
        head = std::move(decoded);
    }
    const detail::VtiBlocks blocks = readBlockShape(*head, f);
    if (blocks.count + 3 > capacity(f, l.dataBegin) / l.headerBytes)
        throw FormatError(f.path, "block header",
                          arrayText(f) + ": a header of " + std::to_string(blocks.count) +
                              " blocks does not fit in the file (truncated?)");
    const std::uint64_t sum = sumBlockSizes(*head, blocks, f);
    const std::uint64_t dataBegin =
        l.dataBegin + (text ? text->charsConsumed() : (3 + blocks.count) * l.headerBytes);
    if (sum > capacity(f, dataBegin))
        throw FormatError(f.path, "block header",
                          arrayText(f) + ": the compressed sizes of its blocks add up to " +
                              std::to_string(sum) + " bytes, the file holds at most " +
                              std::to_string(capacity(f, dataBegin)) + " after the header");
    checkCompressedPayload(l.info, f.declaredBytes, sum, "zlib", kMaxGzipRatio, f.path,
                           "WholeExtent");
    // The sizes again, from the fourth number on, beside the blocks they describe.
    std::unique_ptr<ByteStream> sizes = region(f, l.dataBegin);
    if (text) sizes = std::make_unique<detail::Base64Stream>(std::move(sizes), f.path);
    for (int i = 0; i < 3; ++i)
        readNumber(*sizes, f, "block header", "block shape");
    std::unique_ptr<ByteStream> data = region(f, dataBegin);
    if (text) data = std::make_unique<detail::Base64Stream>(std::move(data), f.path);
    return detail::openZlibBlocks(std::move(sizes), std::move(data), blocks, f.path);
}

std::string describeVti(const std::string& path, const VtiLayout& l) {
    static const char* kEncodings[] = {"appended raw", "appended base64", "inline base64"};
    return "VTK image data " + std::filesystem::path(path).filename().string() + ", " +
           std::string(voxelTypeName(l.info.type)) + ", array '" + l.arrayName + "', " +
           kEncodings[int(l.encoding)] + (l.zlib ? ", zlib" : "");
}

} // namespace

std::unique_ptr<VolumeSource> openVti(const std::string& path) {
    detail::requireRegularFile(path);
    VtiFile f{path, detail::parseVtiXml(path, detail::fileBytes(path)), 0};
    VolumeInfo& info = f.layout.info;
    info.description = describeVti(path, f.layout);
    validateVolumeInfo(info, path, "WholeExtent");
    f.declaredBytes = info.voxelCount() * voxelBytes(info.type);
    if (capacity(f, f.layout.dataBegin) < f.layout.headerBytes)
        throw FormatError(path, "header",
                          arrayText(f) + ": the file ends before the array's header");
    auto voxels = f.layout.zlib ? openBlocks(f) : openPlain(f);
    return detail::makeRawVoxelSource(std::move(voxels), info, f.layout.endian, path,
                                      arrayText(f) + " of WholeExtent " + dimsText(info.dims) +
                                          " needs");
}

} // namespace bc::brickstore
