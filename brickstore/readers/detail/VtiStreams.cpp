// The streams of detail/VtiStreams.h. vtkZLibDataCompressor writes each block as its own zlib
// stream, so the inflater is reset at each block and must end exactly where the block header
// says the block ends.
#include "brickstore/readers/detail/VtiStreams.h"
#include "brickstore/Error.h"
#include "brickstore/readers/detail/GzipStream.h"

#include <algorithm>
#include <climits>
#include <cstring>
#include <new>

#include <zlib.h>

namespace bc::brickstore::detail {

namespace {

/// Base64 characters or compressed bytes read at a time.
constexpr std::size_t kInputBytes = std::size_t(1) << 16;

constexpr std::uint8_t kSpace = 64, kPad = 65, kOther = 255;

/// The value of each base64 character; kSpace, kPad or kOther for the rest.
constexpr std::array<std::uint8_t, 256> makeBase64Table() {
    std::array<std::uint8_t, 256> t{};
    for (auto& v : t)
        v = kOther;
    const char* alphabet = "ABCDEFGHIJKLMNOPQRSTUVWXYZabcdefghijklmnopqrstuvwxyz0123456789+/";
    for (std::uint8_t i = 0; i < 64; ++i)
        t[static_cast<unsigned char>(alphabet[i])] = i;
    for (unsigned char c : {' ', '\t', '\r', '\n'})
        t[c] = kSpace;
    t['='] = kPad;
    return t;
}
constexpr std::array<std::uint8_t, 256> kBase64 = makeBase64Table();

class WindowStream final : public ByteStream {
  public:
    WindowStream(std::unique_ptr<ByteStream> inner, std::uint64_t bytes)
        : mInner(std::move(inner)), mLeft(bytes) {}

    std::size_t read(std::span<std::byte> out) override {
        const std::size_t want = std::size_t(std::min<std::uint64_t>(out.size(), mLeft));
        const std::size_t n = mInner->read(out.first(want));
        mLeft -= n;
        return n;
    }
    void expectEnd() override {}
    const char* kind() const override { return mInner->kind(); }

  private:
    std::unique_ptr<ByteStream> mInner;
    std::uint64_t mLeft;
};

std::string blockName(std::uint64_t block) {
    return "zlib block " + std::to_string(block);
}

class ZlibBlockStream final : public ByteStream {
  public:
    ZlibBlockStream(std::unique_ptr<ByteStream> sizes, std::unique_ptr<ByteStream> data,
                    const VtiBlocks& blocks, const std::string& file)
        : mSizes(std::move(sizes)), mData(std::move(data)), mBlocks(blocks), mFile(file),
          mInput(kInputBytes) {
        zlibCheck(inflateInit(&mZ), mZ.msg, mFile, blockName(0));
    }
    ~ZlibBlockStream() override { inflateEnd(&mZ); }
    ZlibBlockStream(const ZlibBlockStream&) = delete;
    ZlibBlockStream& operator=(const ZlibBlockStream&) = delete;

    std::size_t read(std::span<std::byte> out) override {
        std::size_t done = 0;
        while (done < out.size()) {
            if (mOutLeft == 0 && !startBlock()) break;
            if (mZ.avail_in == 0) refill();
            const std::size_t want = std::size_t(
                std::min<std::uint64_t>({out.size() - done, mOutLeft, std::uint64_t(UINT_MAX)}));
            mZ.next_out = reinterpret_cast<Bytef*>(out.data() + done);
            mZ.avail_out = static_cast<uInt>(want);
            const int rc = zlibCheck(inflate(&mZ, Z_NO_FLUSH), mZ.msg, mFile, blockName(mBlock));
            const std::size_t produced = want - mZ.avail_out;
            done += produced;
            mOutLeft -= produced;
            mStreamEnded = rc == Z_STREAM_END;
            if (mStreamEnded && mOutLeft > 0)
                throw FormatError(mFile, "data",
                                  "zlib block " + std::to_string(mBlock) + " inflates to " +
                                      std::to_string(blockBytes(mBlock) - mOutLeft) +
                                      " bytes; its header says " +
                                      std::to_string(blockBytes(mBlock)));
            if (produced == 0 && !mStreamEnded && mZ.avail_in == 0 && mCompressedLeft == 0)
                throwCut();
            if (mOutLeft == 0) finishBlock();
        }
        return done;
    }

    void expectEnd() override {
        if (mBlock + 1 < mBlocks.count)
            throw FormatError(mFile, "size",
                              "zlib blocks hold more than the declared bytes (" +
                                  std::to_string(mBlocks.count - mBlock - 1) + " blocks unread)");
    }

    const char* kind() const override { return "zlib blocks"; }

  private:
    std::uint64_t blockBytes(std::uint64_t block) const {
        const bool last = block + 1 == mBlocks.count;
        return last && mBlocks.lastBytes != 0 ? mBlocks.lastBytes : mBlocks.blockBytes;
    }

    /// Moves to the next block; false after the last.
    bool startBlock() {
        const std::uint64_t next = mStarted ? mBlock + 1 : 0;
        if (next >= mBlocks.count) return false;
        mBlock = next;
        mStarted = true;
        mCompressedLeft =
            readHeaderNumber(*mSizes, mBlocks.headerBytes, mBlocks.endian, mFile, "block header",
                             "compressed size of block " + std::to_string(mBlock));
        mOutLeft = blockBytes(mBlock);
        mStreamEnded = false;
        zlibCheck(inflateReset(&mZ), mZ.msg, mFile, blockName(mBlock));
        return true;
    }

    void refill() {
        const std::size_t want = std::size_t(std::min<std::uint64_t>(kInputBytes, mCompressedLeft));
        const std::size_t n = want == 0 ? 0 : mData->read(std::span(mInput).first(want));
        if (n < want)
            throw FormatError(mFile, "data",
                              "zlib block " + std::to_string(mBlock) +
                                  " is cut short: the data ends " +
                                  std::to_string(mCompressedLeft - n) + " bytes early");
        mCompressedLeft -= n;
        mZ.next_in = reinterpret_cast<Bytef*>(mInput.data());
        mZ.avail_in = static_cast<uInt>(n);
    }

    [[noreturn]] void throwCut() const {
        throw FormatError(mFile, "data",
                          "zlib block " + std::to_string(mBlock) +
                              " ends before its stream does (block truncated, or its "
                              "compressed size is wrong)");
    }

    /// All of the block's bytes are out: its zlib stream must end here, using all its input.
    void finishBlock() {
        while (!mStreamEnded) {
            if (mZ.avail_in == 0) {
                if (mCompressedLeft == 0) throwCut();
                refill();
            }
            std::byte extra{};
            mZ.next_out = reinterpret_cast<Bytef*>(&extra);
            mZ.avail_out = 1;
            const int rc = zlibCheck(inflate(&mZ, Z_NO_FLUSH), mZ.msg, mFile, blockName(mBlock));
            if (mZ.avail_out == 0)
                throw FormatError(mFile, "data",
                                  "zlib block " + std::to_string(mBlock) +
                                      " inflates past its declared " +
                                      std::to_string(blockBytes(mBlock)) + " bytes");
            mStreamEnded = rc == Z_STREAM_END;
        }
        if (mZ.avail_in != 0 || mCompressedLeft != 0)
            throw FormatError(mFile, "data",
                              "zlib block " + std::to_string(mBlock) + " has " +
                                  std::to_string(mZ.avail_in + mCompressedLeft) +
                                  " bytes after its zlib stream; its compressed size is wrong");
    }

    std::unique_ptr<ByteStream> mSizes;
    std::unique_ptr<ByteStream> mData;
    VtiBlocks mBlocks;
    std::string mFile;
    std::vector<std::byte> mInput;
    z_stream mZ{};
    bool mStarted = false;
    std::uint64_t mBlock = 0;
    std::uint64_t mOutLeft = 0;        ///< bytes the current block has yet to give
    std::uint64_t mCompressedLeft = 0; ///< its compressed bytes not yet read
    bool mStreamEnded = false;
};

} // namespace

std::unique_ptr<ByteStream> openWindow(std::unique_ptr<ByteStream> inner, std::uint64_t bytes) {
    return std::make_unique<WindowStream>(std::move(inner), bytes);
}

Base64Stream::Base64Stream(std::unique_ptr<ByteStream> text, const std::string& file)
    : mText(std::move(text)), mFile(file), mBuffer(kInputBytes) {}

bool Base64Stream::peek(unsigned char& c) {
    if (mPos == mLen) {
        mBufferStart += mLen;
        mPos = 0;
        mLen = mText->read(mBuffer);
        if (mLen == 0) return false;
    }
    c = static_cast<unsigned char>(mBuffer[mPos]);
    return true;
}

/// Decodes the next quartet into mPending; false (nothing consumed) at the end of the data.
bool Base64Stream::decodeQuartet() {
    std::array<std::uint8_t, 4> v{};
    std::size_t count = 0;
    while (count < 4) {
        unsigned char c = 0;
        const bool more = peek(c);
        const std::uint8_t value = more ? kBase64[c] : kOther;
        if (value == kSpace) {
            ++mPos;
            continue;
        }
        if (value == kOther && count == 0) return false;
        const bool badPad = value == kPad && count < 2;
        const bool afterPad = value < 64 && count > 2 && v[2] == kPad;
        if (value == kOther || badPad || afterPad)
            throw FormatError(mFile, "data",
                              "base64 data broken at character " + std::to_string(charsConsumed()) +
                                  (more ? "" : " (it ends inside a quartet)"));
        v[count++] = value;
        ++mPos;
    }
    mPendingLen = v[2] == kPad ? 1 : v[3] == kPad ? 2 : 3;
    mEnded = mPendingLen < 3;
    const std::uint32_t bits = std::uint32_t(v[0]) << 18 | std::uint32_t(v[1]) << 12 |
                               std::uint32_t(v[2] & 63) << 6 | std::uint32_t(v[3] & 63);
    mPending = {std::uint8_t(bits >> 16), std::uint8_t(bits >> 8), std::uint8_t(bits)};
    mPendingPos = 0;
    return true;
}

std::size_t Base64Stream::read(std::span<std::byte> out) {
    std::size_t done = 0;
    while (done < out.size()) {
        if (mPendingPos < mPendingLen) {
            out[done++] = std::byte{mPending[mPendingPos++]};
            continue;
        }
        // Whole quartets without white space straight into `out`: the common case.
        auto* dst = reinterpret_cast<std::uint8_t*>(out.data());
        const auto* src = reinterpret_cast<const std::uint8_t*>(mBuffer.data());
        while (!mEnded && done + 3 <= out.size() && mPos + 4 <= mLen) {
            const std::uint8_t a = kBase64[src[mPos]], b = kBase64[src[mPos + 1]],
                               c = kBase64[src[mPos + 2]], d = kBase64[src[mPos + 3]];
            if ((a | b | c | d) >= 64) break;
            const std::uint32_t bits = std::uint32_t(a) << 18 | std::uint32_t(b) << 12 |
                                       std::uint32_t(c) << 6 | std::uint32_t(d);
            dst[done] = std::uint8_t(bits >> 16);
            dst[done + 1] = std::uint8_t(bits >> 8);
            dst[done + 2] = std::uint8_t(bits);
            done += 3;
            mPos += 4;
        }
        if (done == out.size() || mEnded) break;
        if (!decodeQuartet()) {
            mEnded = true;
            break;
        }
    }
    return done;
}

std::uint64_t readHeaderNumber(ByteStream& in, std::uint32_t bytes, Endian endian,
                               const std::string& file, const std::string& field,
                               const std::string& what) {
    std::array<std::uint8_t, 8> b{};
    if (in.read(std::as_writable_bytes(std::span(b).first(bytes))) != bytes)
        throw FormatError(file, field, what + ": the data ends inside the header");
    std::uint64_t v = 0;
    for (std::uint32_t i = 0; i < bytes; ++i)
        v |= std::uint64_t(b[endian == Endian::Little ? i : bytes - 1 - i]) << (8 * i);
    return v;
}

std::unique_ptr<ByteStream> openZlibBlocks(std::unique_ptr<ByteStream> sizes,
                                           std::unique_ptr<ByteStream> data,
                                           const VtiBlocks& blocks, const std::string& file) {
    return std::make_unique<ZlibBlockStream>(std::move(sizes), std::move(data), blocks, file);
}

} // namespace bc::brickstore::detail
