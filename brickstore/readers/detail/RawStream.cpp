// The byte streams of detail/RawStream.h: a plain file, a zstd stream, and the slice source
// over raw voxels. Everything reads forwards in bounded chunks: a 100 GB input costs one
// zstd input buffer and the caller's slice buffer, never the volume.
#include "brickstore/readers/detail/RawStream.h"
#include "brickstore/Error.h"
#include "brickstore/Readers.h"
#include "brickstore/detail/RegularFile.h"
#include "brickstore/readers/detail/ReadAhead.h"

#include <algorithm>
#include <array>
#include <bit>
#include <cerrno>
#include <cmath>
#include <cstdio>
#include <cstring>
#include <filesystem>
#include <fstream>
#include <limits>
#include <new>
#include <vector>

#include <sys/stat.h>
#include <sys/types.h>
#include <unistd.h>
// ZSTD_getFrameHeader: exported by libzstd, declared only in the static section.
#define ZSTD_STATIC_LINKING_ONLY
#include <zstd.h>

namespace bc::brickstore::detail {

namespace {

/// Bytes read and checked at a time within one readNextSlices (a multiple of every voxel size).
constexpr std::size_t kChunkBytes = std::size_t(1) << 20;
/// Longest zstd frame header (ZSTD_FRAMEHEADERSIZE_MAX, which zstd.h keeps static-only).
constexpr std::size_t kZstdFrameHeaderMaxBytes = 18;

/// The one place zstd error codes become exceptions.
std::size_t zstdCheck(std::size_t code, const std::string& file) {
    if (ZSTD_isError(code))
        throw FormatError(file, "data", std::string("zstd: ") + ZSTD_getErrorName(code));
    return code;
}

struct FileCloser {
    void operator()(std::FILE* f) const { std::fclose(f); }
};

/// Files at least this large are read ahead (ReadAhead); smaller ones are left to the
/// kernel's own read-ahead.
constexpr std::uint64_t kReadAheadMinBytes = 64ull << 20;

class FileStream final : public ByteStream {
  public:
    /// `readAhead`: a large file is read ahead of this stream on a thread of its own.
    FileStream(const std::string& path, std::uint64_t offsetBytes, bool readAhead = false)
        : mPath(path), mFile(openFile(path)), mPosition(offsetBytes) {
        if (offsetBytes > std::uint64_t(std::numeric_limits<off_t>::max()) ||
            ::fseeko(mFile.get(), off_t(offsetBytes), SEEK_SET) != 0)
            throw FormatError(path, "path", "cannot seek to byte " + std::to_string(offsetBytes));
        struct stat st {};
        if (readAhead && ::fstat(::fileno(mFile.get()), &st) == 0 && S_ISREG(st.st_mode) &&
            std::uint64_t(st.st_size) >= kReadAheadMinBytes)
            mAhead = std::make_unique<ReadAhead>(::fileno(mFile.get()), offsetBytes,
                                                 std::uint64_t(st.st_size));
    }

    /// The file, never blocking on a FIFO (which would wait for a writer forever).
    static std::FILE* openFile(const std::string& path) {
        std::string why;
        const int fd = openRegularFile(path, why);
        if (fd < 0) throw FormatError(path, "path", "cannot open: " + why);
        std::FILE* file = ::fdopen(fd, "rb");
        if (!file) {
            why = std::strerror(errno);
            ::close(fd);
            throw FormatError(path, "path", "cannot open: " + why);
        }
        return file;
    }

    std::size_t read(std::span<std::byte> out) override {
        std::size_t n = std::fread(out.data(), 1, out.size(), mFile.get());
        if (n < out.size() && std::ferror(mFile.get()))
            throw FormatError(mPath, "data", std::string("read error: ") + std::strerror(errno));
        mPosition += n;
        if (mAhead) mAhead->reached(mPosition);
        return n;
    }

    void expectEnd() override {
        if (std::fgetc(mFile.get()) != EOF)
            throw FormatError(mPath, "size",
                              "file holds more bytes than declared (it grew while read?)");
    }

    const char* kind() const override { return "file"; }

  private:
    std::string mPath;
    std::unique_ptr<std::FILE, FileCloser> mFile;
    std::uint64_t mPosition;
    std::unique_ptr<ReadAhead> mAhead; ///< after mFile: it stops before the file closes
};

struct DCtxDeleter {
    void operator()(ZSTD_DCtx* c) const { ZSTD_freeDCtx(c); }
};

class ZstdStream final : public ByteStream {
  public:
    ZstdStream(std::unique_ptr<ByteStream> compressed, const std::string& file)
        : mCompressed(std::move(compressed)), mFile(file), mCtx(ZSTD_createDCtx()),
          mInput(ZSTD_DStreamInSize()) {
        if (!mCtx) throw std::bad_alloc();
    }

    std::size_t read(std::span<std::byte> out) override {
        ZSTD_outBuffer dst{out.data(), out.size(), 0};
        while (dst.pos < dst.size) {
            if (mIn.pos == mIn.size && !mInputEnded) refill();
            const std::size_t inBefore = mIn.pos, outBefore = dst.pos;
            std::size_t hint = zstdCheck(ZSTD_decompressStream(mCtx.get(), &dst, &mIn), mFile);
            const bool progressed = mIn.pos != inBefore || dst.pos != outBefore;
            // 0: a frame is complete and flushed, so the stream may end here. A call that
            // moves nothing says nothing (it asks for the next frame's header).
            if (progressed || hint == 0) mBetweenFrames = hint == 0;
            if (progressed || mIn.pos != mIn.size || !mInputEnded) continue;
            if (!mBetweenFrames)
                throw FormatError(mFile, "data",
                                  "zstd stream ends inside a frame (file truncated)");
            break;
        }
        mDeliveredBytes += dst.pos;
        return dst.pos;
    }

    void expectEnd() override {
        std::uint64_t declared = mDeliveredBytes;
        std::byte extra{};
        if (read({&extra, 1}) != 0)
            throw FormatError(mFile, "size",
                              "zstd stream holds more than the declared " +
                                  std::to_string(declared) + " bytes");
    }

    const char* kind() const override { return "zstd stream"; }

  private:
    void refill() {
        std::size_t n = mCompressed->read(mInput);
        mIn = ZSTD_inBuffer{mInput.data(), n, 0};
        mInputEnded = n == 0;
    }

    std::unique_ptr<ByteStream> mCompressed;
    std::string mFile;
    std::unique_ptr<ZSTD_DCtx, DCtxDeleter> mCtx;
    std::vector<std::byte> mInput;
    ZSTD_inBuffer mIn{nullptr, 0, 0};
    bool mInputEnded = false;
    bool mBetweenFrames = false; ///< false until a first frame completes
    std::uint64_t mDeliveredBytes = 0;
};

/// Reverses the bytes of each `voxelBytes`-byte voxel in place.
void swapVoxelBytes(std::span<std::byte> bytes, std::size_t voxelBytes) {
    if (voxelBytes == 2) {
        for (std::size_t i = 0; i + 2 <= bytes.size(); i += 2)
            std::swap(bytes[i], bytes[i + 1]);
    } else if (voxelBytes == 4) {
        for (std::size_t i = 0; i + 4 <= bytes.size(); i += 4) {
            std::uint32_t v;
            std::memcpy(&v, bytes.data() + i, 4);
            v = __builtin_bswap32(v);
            std::memcpy(bytes.data() + i, &v, 4);
        }
    }
}

class RawVoxelSource final : public VolumeSource {
  public:
    RawVoxelSource(std::unique_ptr<ByteStream> voxels, const VolumeInfo& info, Endian endian,
                   const std::string& file, const std::string& sizeClaim)
        : mInfo(info), mVoxels(std::move(voxels)), mFile(file), mSizeClaim(sizeClaim),
          mSwap(voxelBytes(info.type) > 1 &&
                (endian == Endian::Big) != (std::endian::native == std::endian::big)),
          mTotalBytes(info.voxelCount() * voxelBytes(info.type)) {}

    const VolumeInfo& info() const override { return mInfo; }

  private:
    void readNextSlices(std::uint64_t count, std::span<std::byte> out) override {
        for (std::size_t done = 0; done < out.size();) {
            std::size_t n = std::min(kChunkBytes, out.size() - done);
            readChunk(out.subspan(done, n));
            done += n;
        }
        if (count > 0 && nextSlice() + count == mInfo.dims[2]) mVoxels->expectEnd();
    }

    void readChunk(std::span<std::byte> chunk) {
        std::size_t n = mVoxels->read(chunk);
        if (n < chunk.size())
            throw FormatError(mFile, "size",
                              mSizeClaim + " " + std::to_string(mTotalBytes) + " bytes, " +
                                  mVoxels->kind() + " ends after " +
                                  std::to_string(mDoneBytes + n));
        if (mSwap) swapVoxelBytes(chunk, voxelBytes(mInfo.type));
        if (mInfo.type == VoxelType::F32) checkFinite(chunk);
        mDoneBytes += n;
    }

    /// NaN or infinity would poison every min/max and average the store keeps.
    void checkFinite(std::span<const std::byte> chunk) const {
        for (std::size_t i = 0; i + 4 <= chunk.size(); i += 4) {
            float v;
            std::memcpy(&v, chunk.data() + i, 4);
            if (std::isfinite(v)) continue;
            std::uint64_t voxel = (mDoneBytes + i) / 4;
            std::uint64_t x = voxel % mInfo.dims[0], y = voxel / mInfo.dims[0] % mInfo.dims[1];
            std::uint64_t z = voxel / (mInfo.dims[0] * mInfo.dims[1]);
            throw FormatError(mFile, "data",
                              "voxel (" + std::to_string(x) + "," + std::to_string(y) + "," +
                                  std::to_string(z) + ") is " +
                                  (std::isnan(v) ? "NaN" : "infinite") +
                                  "; float volumes must be finite");
        }
    }

    VolumeInfo mInfo;
    std::unique_ptr<ByteStream> mVoxels;
    std::string mFile;
    std::string mSizeClaim;
    bool mSwap;
    std::uint64_t mTotalBytes;
    std::uint64_t mDoneBytes = 0;
};

} // namespace

std::unique_ptr<ByteStream> openFileStream(const std::string& path, std::uint64_t offsetBytes) {
    return std::make_unique<FileStream>(path, offsetBytes, /*readAhead=*/true);
}

std::unique_ptr<ByteStream> openZstdStream(std::unique_ptr<ByteStream> compressed,
                                           const std::string& file) {
    return std::make_unique<ZstdStream>(std::move(compressed), file);
}

std::optional<std::uint64_t> zstdFirstFrameBytes(const std::string& path) {
    std::array<std::byte, kZstdFrameHeaderMaxBytes> head{};
    std::size_t n = FileStream(path, 0).read(head);
    unsigned long long size = ZSTD_getFrameContentSize(head.data(), n);
    if (size == ZSTD_CONTENTSIZE_ERROR)
        throw FormatError(path, "data", "not a zstd stream (no valid frame header at its start)");
    if (size == ZSTD_CONTENTSIZE_UNKNOWN) return std::nullopt;
    return size;
}

namespace {

/// Reads `out.size()` bytes at `offset`; false when the file ends first.
bool readAt(std::ifstream& in, std::uint64_t offset, std::span<std::byte> out) {
    in.clear();
    in.seekg(std::streamoff(offset));
    in.read(reinterpret_cast<char*>(out.data()), std::streamsize(out.size()));
    return std::size_t(in.gcount()) == out.size();
}

/// Offset just past the blocks (and checksum) of the frame whose blocks start at `offset`.
std::uint64_t skipBlocks(std::ifstream& in, std::uint64_t offset, const ZSTD_frameHeader& frame,
                         const std::string& path) {
    for (bool last = false; !last;) {
        std::array<std::byte, 3> head{};
        if (!readAt(in, offset, head))
            throw FormatError(path, "data", "zstd stream ends inside a frame (file truncated)");
        const std::uint32_t bits =
            std::uint32_t(head[0]) | std::uint32_t(head[1]) << 8 | std::uint32_t(head[2]) << 16;
        last = (bits & 1u) != 0;
        const std::uint32_t type = (bits >> 1) & 3u, size = bits >> 3;
        if (type == 3)
            throw FormatError(path, "data",
                              "reserved zstd block type at byte " + std::to_string(offset));
        offset += 3 + (type == 1 ? 1 : size); // an RLE block stores its one byte
    }
    return offset + (frame.checksumFlag ? 4 : 0);
}

} // namespace

ZstdFrames zstdFrames(const std::string& path) {
    ZstdFrames out;
    out.fileBytes = fileBytes(path);
    std::ifstream in(path, std::ios::binary);
    if (!in) throw FormatError(path, "path", std::string("cannot open: ") + std::strerror(errno));
    std::uint64_t total = 0;
    bool known = true;
    for (std::uint64_t offset = 0; offset < out.fileBytes;) {
        std::array<std::byte, kZstdFrameHeaderMaxBytes> head{};
        const std::size_t n =
            std::size_t(std::min<std::uint64_t>(head.size(), out.fileBytes - offset));
        readAt(in, offset, std::span(head).first(n));
        ZSTD_frameHeader frame{};
        if (ZSTD_getFrameHeader(&frame, head.data(), n) != 0)
            throw FormatError(path, "data",
                              "no valid zstd frame header at byte " + std::to_string(offset));
        if (frame.frameType == ZSTD_skippableFrame) {
            offset += frame.headerSize + frame.frameContentSize;
            continue;
        }
        if (frame.frameContentSize == ZSTD_CONTENTSIZE_UNKNOWN)
            known = false;
        else
            total += frame.frameContentSize;
        offset = skipBlocks(in, offset + frame.headerSize, frame, path);
        if (offset > out.fileBytes)
            throw FormatError(path, "data", "zstd stream ends inside a frame (file truncated)");
    }
    if (known) out.contentBytes = total;
    return out;
}

std::uint64_t fileBytes(const std::string& path) {
    std::error_code ec;
    std::uint64_t size = std::filesystem::file_size(path, ec);
    if (ec) throw FormatError(path, "path", "cannot read size: " + ec.message());
    return size;
}

std::unique_ptr<VolumeSource> makeRawVoxelSource(std::unique_ptr<ByteStream> voxels,
                                                 const VolumeInfo& info, Endian endian,
                                                 const std::string& file,
                                                 const std::string& sizeClaim) {
    return std::make_unique<RawVoxelSource>(std::move(voxels), info, endian, file, sizeClaim);
}

} // namespace bc::brickstore::detail
