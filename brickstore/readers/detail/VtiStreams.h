#pragma once
// The byte streams a .vti array's data passes through (VtiStreams.cpp): a window of a file,
// base64 text decoded on the fly, and vtkZLibDataCompressor's blocks inflated one after the
// other. Each holds one bounded input buffer; blocks inflate straight into the caller's
// buffer, so no block, and never the volume, is held whole.
#include "brickstore/readers/detail/RawStream.h"

#include <array>
#include <cstdint>
#include <memory>
#include <string>
#include <vector>

namespace bc::brickstore::detail {

/// At most `bytes` bytes of `inner`. expectEnd() checks nothing: what follows the window
/// belongs to other arrays or to the XML.
std::unique_ptr<ByteStream> openWindow(std::unique_ptr<ByteStream> inner, std::uint64_t bytes);

/// Bytes decoded from the base64 text of `text`. White space is skipped. A quartet padded
/// with '=' ends the stream, as does, between quartets, the end of the text or a character
/// that is not base64 (the markup after it); inside a quartet either throws
/// FormatError(file, "data").
class Base64Stream final : public ByteStream {
  public:
    Base64Stream(std::unique_ptr<ByteStream> text, const std::string& file);
    std::size_t read(std::span<std::byte> out) override;
    void expectEnd() override {}
    const char* kind() const override { return "base64 data"; }
    /// Characters of `text` used so far (up to the last quartet decoded): where the next
    /// base64 stream of the same text starts.
    std::uint64_t charsConsumed() const { return mBufferStart + mPos; }

  private:
    bool decodeQuartet();
    bool peek(unsigned char& c);

    std::unique_ptr<ByteStream> mText;
    std::string mFile;
    std::vector<std::byte> mBuffer;
    std::size_t mPos = 0, mLen = 0;
    std::uint64_t mBufferStart = 0; ///< characters of `text` before mBuffer
    std::array<std::uint8_t, 3> mPending{};
    std::size_t mPendingPos = 0, mPendingLen = 0;
    bool mEnded = false;
};

/// Reads one number of a VTK binary header: `bytes` (4 or 8) bytes in `endian` order.
/// @throw FormatError(file, field) naming `what` when `in` ends first.
std::uint64_t readHeaderNumber(ByteStream& in, std::uint32_t bytes, Endian endian,
                               const std::string& file, const std::string& field,
                               const std::string& what);

/// The shape of a vtkZLibDataCompressor array: `count` blocks of `blockBytes` each but the
/// last, which holds `lastBytes` (0: a full block).
struct VtiBlocks {
    std::uint64_t count = 0;
    std::uint64_t blockBytes = 0;
    std::uint64_t lastBytes = 0;
    std::uint32_t headerBytes = 4; ///< size of each number in the block header
    Endian endian = Endian::Little;
};

/// The blocks' bytes: `sizes` yields each block's compressed size (as header numbers), `data`
/// the compressed blocks, back to back. Each block must be one zlib stream, exactly its
/// compressed size long, that inflates to exactly its size. @throw FormatError(file, "data").
std::unique_ptr<ByteStream> openZlibBlocks(std::unique_ptr<ByteStream> sizes,
                                           std::unique_ptr<ByteStream> data,
                                           const VtiBlocks& blocks, const std::string& file);

} // namespace bc::brickstore::detail
