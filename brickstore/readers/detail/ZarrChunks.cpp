// Zarr chunk files: found by key inside the array's folder, bounded before they are read, and
// decoded in one call each into a chunk-sized buffer. Each C library's errors become
// FormatError in one place: zlibDecode, zstdDecode, bloscDecode.
#include "brickstore/readers/detail/ZarrChunks.h"
#include "brickstore/Error.h"
#include "brickstore/detail/RegularFile.h"

#include <cerrno>
#include <cstring>
#include <filesystem>
#include <utility>

#include <blosc.h>
#include <fcntl.h>
#include <sys/stat.h>
#include <unistd.h>
#include <zlib.h>
#include <zstd.h>

namespace bc::brickstore::detail {

namespace {

namespace fs = std::filesystem;

/// An owned file descriptor, closed when it goes.
class Fd {
  public:
    explicit Fd(int fd) : mFd(fd) {}
    Fd(Fd&& other) noexcept : mFd(std::exchange(other.mFd, -1)) {}
    ~Fd() {
        if (mFd >= 0) ::close(mFd);
    }
    Fd(const Fd&) = delete;
    Fd& operator=(const Fd&) = delete;
    int get() const { return mFd; }

  private:
    int mFd;
};

[[noreturn]] void badChunk(const std::string& path, const std::string& why) {
    throw FormatError(path, "chunk", why);
}

/// Largest file the array's codec makes of one chunk: deflate's bound (zlib's compressBound,
/// plus the 12 bytes by which gzip's wrapper outgrows zlib's), zstd's, blosc's 16-byte
/// header over incompressible data; exactly the chunk when uncompressed.
std::uint64_t fileBound(const ZarrArray& a) {
    switch (a.codec) {
    case ZarrCodec::None:
        return a.chunkBytes;
    case ZarrCodec::Zlib:
        return compressBound(uLong(a.chunkBytes));
    case ZarrCodec::Gzip:
        return compressBound(uLong(a.chunkBytes)) + 12;
    case ZarrCodec::Zstd:
        return ZSTD_compressBound(a.chunkBytes);
    case ZarrCodec::Blosc:
        return a.chunkBytes + BLOSC_MAX_OVERHEAD;
    }
    return 0;
}

void zlibDecode(std::span<const std::byte> in, std::span<std::byte> out, bool gzip,
                const std::string& path) {
    z_stream z{};
    if (inflateInit2(&z, gzip ? 15 + 16 : 15) != Z_OK) badChunk(path, "zlib cannot start");
    z.next_in = reinterpret_cast<Bytef*>(const_cast<std::byte*>(in.data()));
    z.avail_in = uInt(in.size());
    z.next_out = reinterpret_cast<Bytef*>(out.data());
    z.avail_out = uInt(out.size());
    const int rc = inflate(&z, Z_FINISH);
    const std::string msg = z.msg ? z.msg : "";
    const uLong produced = z.total_out, left = z.avail_in, room = z.avail_out;
    inflateEnd(&z);
    const char* codec = gzip ? "gzip" : "zlib";
    if (rc == Z_STREAM_END && produced == out.size() && left == 0) return;
    if (rc == Z_STREAM_END && left != 0)
        badChunk(path, std::string(codec) + " data ends " + std::to_string(left) +
                           " bytes before the file does");
    if (rc == Z_STREAM_END)
        badChunk(path, std::string(codec) + " data inflates to " + std::to_string(produced) +
                           " bytes; a chunk holds " + std::to_string(out.size()));
    // Output full with input left: the data goes on past the chunk. Input used up before the
    // stream's end: the file is cut short.
    if (rc == Z_BUF_ERROR && room == 0 && left != 0)
        badChunk(path, std::string(codec) + " data inflates past the chunk's " +
                           std::to_string(out.size()) + " bytes");
    if (rc == Z_BUF_ERROR)
        badChunk(path, std::string(codec) + " data is truncated: it ends after " +
                           std::to_string(produced) + " of the chunk's " +
                           std::to_string(out.size()) + " bytes");
    badChunk(path, std::string(codec) + " data is corrupt: " + (msg.empty() ? "error" : msg));
}

void zstdDecode(ZSTD_DCtx* ctx, std::span<const std::byte> in, std::span<std::byte> out,
                const std::string& path) {
    const unsigned long long content = ZSTD_getFrameContentSize(in.data(), in.size());
    if (content == ZSTD_CONTENTSIZE_ERROR)
        badChunk(path, "does not start with a zstd frame header (corrupt or truncated)");
    if (content == ZSTD_CONTENTSIZE_UNKNOWN)
        badChunk(path, "the zstd frame declares no content size");
    if (content != out.size())
        badChunk(path, "the zstd frame declares " + std::to_string(content) +
                           " bytes; a chunk holds " + std::to_string(out.size()));
    const std::size_t n = ZSTD_decompressDCtx(ctx, out.data(), out.size(), in.data(), in.size());
    if (ZSTD_isError(n))
        badChunk(path, std::string("zstd data is corrupt or truncated: ") + ZSTD_getErrorName(n));
    if (n != out.size())
        badChunk(path, "zstd data decodes to " + std::to_string(n) + " bytes; a chunk holds " +
                           std::to_string(out.size()));
}

/// blosc_decompress_ctx trusts the buffer's header for the input's length, so the header is
/// validated against the file's real size first.
void bloscDecode(std::span<const std::byte> in, std::span<std::byte> out, const std::string& path) {
    std::size_t nbytes = 0, cbytes = 0, blockBytes = 0;
    if (in.size() < BLOSC_MIN_HEADER_LENGTH ||
        blosc_cbuffer_validate(in.data(), in.size(), &nbytes) < 0) {
        if (in.size() >= BLOSC_MIN_HEADER_LENGTH)
            blosc_cbuffer_sizes(in.data(), &nbytes, &cbytes, &blockBytes);
        badChunk(path, "not a whole blosc buffer: the file holds " + std::to_string(in.size()) +
                           " bytes, its header says " + std::to_string(cbytes) +
                           " (truncated or corrupt)");
    }
    if (nbytes != out.size())
        badChunk(path, "the blosc header declares " + std::to_string(nbytes) +
                           " bytes; a chunk holds " + std::to_string(out.size()));
    const int n = blosc_decompress_ctx(in.data(), out.data(), out.size(), 1);
    if (n < 0 || std::size_t(n) != out.size())
        badChunk(path,
                 "blosc data is corrupt (blosc_decompress_ctx returned " + std::to_string(n) + ")");
}

} // namespace

ZarrFolder::ZarrFolder(const ZarrArray& array)
    : mFd(::open(array.folder.c_str(), O_RDONLY | O_DIRECTORY | O_CLOEXEC)) {
    if (mFd < 0)
        throw FormatError(array.metaFile, "path",
                          "cannot open the array's folder: " + std::string(std::strerror(errno)));
}

ZarrFolder::~ZarrFolder() {
    ::close(mFd);
}

ZarrChunkReader::ZarrChunkReader(const ZarrArray& array, const ZarrFolder& folder)
    : mArray(array), mFolder(folder), mZstd(ZSTD_createDCtx()) {
    if (!mZstd) throw std::bad_alloc();
}

ZarrChunkReader::~ZarrChunkReader() {
    ZSTD_freeDCtx(mZstd);
}

std::string ZarrChunkReader::chunkKey(const ZarrChunkIndex& index) const {
    std::string key;
    for (std::size_t i = 0; i + 3 < mArray.shape.size(); ++i)
        key += std::string("0") + mArray.separator;
    return key + std::to_string(index[0]) + mArray.separator + std::to_string(index[1]) +
           mArray.separator + std::to_string(index[2]);
}

std::string ZarrChunkReader::chunkPath(const ZarrChunkIndex& index) const {
    return (fs::path(mArray.displayFolder) / chunkKey(index)).string();
}

/// Opens a chunk's file, following no symlink on the way (the fast path: a store holds plain
/// files); a symlink is followed only once it is found to stay in the store. -1: no such file.
int ZarrChunkReader::openChunk(const std::string& key, const std::string& path) const {
    std::vector<Fd> folders; // the nested folders of a "/" key, open down to the chunk's
    int fd = -1, err = 0;
    for (std::size_t from = 0;;) {
        const std::size_t to = key.find('/', from);
        const int dir = folders.empty() ? mFolder.fd() : folders.back().get();
        const std::string part = key.substr(from, to == std::string::npos ? to : to - from);
        // O_NONBLOCK: a FIFO's open would wait for a writer; read() checks what was opened.
        const int flags =
            O_RDONLY | O_NOFOLLOW | O_NONBLOCK | O_CLOEXEC | (to == key.npos ? 0 : O_DIRECTORY);
        fd = ::openat(dir, part.c_str(), flags);
        err = errno;
        if (fd < 0 || to == std::string::npos) break;
        folders.emplace_back(fd);
        from = to + 1;
    }
    if (fd >= 0) return fd;
    if (err == ENOENT) return -1;
    if (err != ELOOP && err != ENOTDIR)
        badChunk(path, std::string("cannot open: ") + std::strerror(err));
    const std::string rel =
        (fs::path(mArray.folder).lexically_relative(mArray.root) / key).lexically_normal().string();
    const std::string real = resolveInside(mArray.root, rel, path, "chunk");
    fd = ::open(real.c_str(), O_RDONLY | O_NONBLOCK | O_CLOEXEC);
    if (fd < 0 && errno == ENOENT) return -1;
    if (fd < 0) badChunk(path, std::string("cannot open: ") + std::strerror(errno));
    return fd;
}

bool ZarrChunkReader::read(const ZarrChunkIndex& index, std::span<std::byte> out) {
    const std::string key = chunkKey(index);
    const std::string path = (fs::path(mArray.displayFolder) / key).string();
    const Fd fd(openChunk(key, path));
    if (fd.get() < 0) return false;
    struct stat st {};
    if (::fstat(fd.get(), &st) != 0 || !S_ISREG(st.st_mode))
        badChunk(path, "not a regular file (" + fileKindText(st.st_mode) + ")");
    const std::uint64_t bytes = std::uint64_t(st.st_size), bound = fileBound(mArray);
    if (mArray.codec == ZarrCodec::None && bytes != mArray.chunkBytes)
        badChunk(path, "holds " + std::to_string(bytes) + " bytes; an uncompressed chunk holds " +
                           "exactly " + std::to_string(mArray.chunkBytes));
    if (bytes > bound)
        badChunk(path, "holds " + std::to_string(bytes) + " bytes, more than the " +
                           std::to_string(bound) + " that " + mArray.codecName +
                           " makes of a chunk of " + std::to_string(mArray.chunkBytes));
    std::span<std::byte> in = out;
    if (mArray.codec != ZarrCodec::None) {
        if (mCompressed.size() < bytes) mCompressed.resize(bytes);
        in = std::span(mCompressed).first(bytes);
    }
    for (std::uint64_t done = 0; done < bytes;) {
        const ssize_t n = ::pread(fd.get(), in.data() + done, bytes - done, off_t(done));
        if (n < 0 && errno == EINTR) continue;
        if (n <= 0)
            badChunk(path, "read error after " + std::to_string(done) +
                               " bytes: " + (n < 0 ? std::strerror(errno) : "the file shrank"));
        done += std::uint64_t(n);
    }
    if (mArray.codec != ZarrCodec::None) decode(in, out, path);
    return true;
}

void ZarrChunkReader::decode(std::span<const std::byte> in, std::span<std::byte> out,
                             const std::string& path) {
    switch (mArray.codec) {
    case ZarrCodec::None:
        return;
    case ZarrCodec::Zlib:
        return zlibDecode(in, out, false, path);
    case ZarrCodec::Gzip:
        return zlibDecode(in, out, true, path);
    case ZarrCodec::Zstd:
        return zstdDecode(mZstd, in, out, path);
    case ZarrCodec::Blosc:
        return bloscDecode(in, out, path);
    }
}

} // namespace bc::brickstore::detail
