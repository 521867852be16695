// The gzip stream of detail/GzipStream.h: gzip members (or one zlib stream) inflated on the
// fly over any ByteStream, with zlib's error codes translated in one place (zlibCheck).
#include "brickstore/readers/detail/GzipStream.h"
#include "brickstore/Error.h"
#include "brickstore/Readers.h"
#include "brickstore/readers/detail/RawStream.h"

#include <algorithm>
#include <cerrno>
#include <charconv>
#include <climits>
#include <cmath>
#include <cstring>
#include <filesystem>
#include <fstream>
#include <map>
#include <new>
#include <vector>

#include <zlib.h>

namespace bc::brickstore::detail {

namespace {

/// Compressed bytes read from the file at a time.
constexpr std::size_t kGzipInputBytes = std::size_t(1) << 16;

class GzipStream final : public ByteStream {
  public:
    GzipStream(std::unique_ptr<ByteStream> compressed, const std::string& file)
        : mCompressed(std::move(compressed)), mFile(file), mInput(kGzipInputBytes) {
        // 15 + 32: a 32 KiB window, gzip or zlib wrapper detected from the header.
        zlibCheck(inflateInit2(&mZ, 15 + 32), mZ.msg, mFile, "gzip");
    }
    ~GzipStream() override { inflateEnd(&mZ); }
    GzipStream(const GzipStream&) = delete;
    GzipStream& operator=(const GzipStream&) = delete;

    std::size_t read(std::span<std::byte> out) override {
        std::size_t done = 0;
        while (done < out.size()) {
            if (mZ.avail_in == 0 && !mInputEnded) refill();
            if (mMemberEnded) {
                if (mZ.avail_in == 0 && mInputEnded) break;
                zlibCheck(inflateReset(&mZ), mZ.msg, mFile, "gzip"); // another gzip member follows
                mMemberEnded = false;
            }
            std::size_t want = std::min<std::size_t>(out.size() - done, UINT_MAX);
            mZ.next_out = reinterpret_cast<Bytef*>(out.data() + done);
            mZ.avail_out = static_cast<uInt>(want);
            int rc = zlibCheck(inflate(&mZ, Z_NO_FLUSH), mZ.msg, mFile, "gzip");
            std::size_t produced = want - mZ.avail_out;
            done += produced;
            mMemberEnded = rc == Z_STREAM_END;
            if (!mMemberEnded && produced == 0 && mZ.avail_in == 0 && mInputEnded)
                throw FormatError(mFile, "data", "gzip data ends early (stream truncated)");
        }
        mDeliveredBytes += done;
        return done;
    }

    void expectEnd() override {
        std::uint64_t declared = mDeliveredBytes;
        std::byte extra{};
        if (read({&extra, 1}) != 0)
            throw FormatError(mFile, "data",
                              "gzip data inflates past the declared " + std::to_string(declared) +
                                  " bytes");
    }

    const char* kind() const override { return "gzip data"; }

  private:
    void refill() {
        std::size_t n = mCompressed->read(mInput);
        mZ.next_in = reinterpret_cast<Bytef*>(mInput.data());
        mZ.avail_in = static_cast<uInt>(n);
        mInputEnded = n == 0;
    }

    std::unique_ptr<ByteStream> mCompressed;
    std::string mFile;
    std::vector<std::byte> mInput;
    z_stream mZ{};
    bool mInputEnded = false;
    bool mMemberEnded = false;
    std::uint64_t mDeliveredBytes = 0;
};

} // namespace

std::unique_ptr<ByteStream> openGzipStream(std::unique_ptr<ByteStream> compressed,
                                           const std::string& file) {
    return std::make_unique<GzipStream>(std::move(compressed), file);
}

int zlibCheck(int code, const char* message, const std::string& file, const std::string& what) {
    if (code == Z_OK || code == Z_STREAM_END || code == Z_BUF_ERROR) return code;
    if (code == Z_MEM_ERROR) throw std::bad_alloc();
    throw FormatError(file, "data", what + ": " + (message ? message : zError(code)));
}

} // namespace bc::brickstore::detail
