#pragma once
// Decoding of protocol/PROTOCOL.md: one payload (decodePayload), or a byte stream cut into
// messages (Decoder). Bytes in, messages out: no sockets, and nothing here throws on what a
// peer sends; every bad input is a DecodeError saying which field broke which rule.
#include "protocol/Messages.h"
#include "protocol/Wire.h"

#include <cstddef>
#include <cstdint>
#include <span>
#include <string>
#include <variant>
#include <vector>

namespace bc::protocol {

/// The 16 header bytes, as read (not yet validated).
struct Header {
    std::uint8_t version = 0;
    std::uint8_t type = 0;
    std::uint16_t flags = 0;
    std::uint32_t length = 0;
    std::uint32_t request = 0;
};

/// What is wrong with a message: the Error to answer it with (code, fatal, offending type,
/// request id) and a message naming the message and field ("SetRenderOptions.width: 0 is
/// outside 1..4096"). The message is printable ASCII and fits kMaxErrorMessageBytes.
struct DecodeError {
    ErrorCode code = ErrorCode::Internal;
    bool fatal = false;
    std::uint8_t type = 0;
    std::uint32_t request = 0;
    std::string message;
    bool operator==(const DecodeError&) const = default;
};

/// Validates and decodes one payload of `type`: exact size, every enum, bool, range and string
/// limit of PROTOCOL.md. The error's request is 0 (the caller knows it).
std::variant<Message, DecodeError> decodePayload(std::uint8_t type, std::uint16_t flags,
                                                 std::span<const std::uint8_t> payload);

/// Incremental decoder of one connection's byte stream, in the style of Asio's request_parser.
/// Magic, version and length are checked against maxPayloadBytes from the 16 header bytes
/// alone, before any payload is buffered. A fatal (framing) error sticks: next() returns it
/// again and fed bytes are dropped. A non-fatal error consumes its message and decoding goes
/// on with the next one. Not thread-safe.
class Decoder {
  public:
    enum class Status { NeedMore, Message, Error };
    struct Result {
        Status status = Status::NeedMore;
        std::uint32_t request = 0;
        Message message;   ///< set when status is Message
        DecodeError error; ///< set when status is Error
    };

    /// A decoder that accepts payloads up to maxPayloadBytes (kMaxClientPayloadBytes on the
    /// server, kDefaultMaxServerPayloadBytes or the user's choice on a client).
    explicit Decoder(std::uint32_t maxPayloadBytes);

    /// Appends bytes from the peer; dropped once failed().
    void feed(std::span<const std::uint8_t> bytes);
    /// The next complete message or error, or NeedMore. Call until NeedMore after each feed.
    Result next();
    /// Bytes held: at most kHeaderBytes + maxPayloadBytes, plus what was fed past the current
    /// message and not yet taken by next().
    std::size_t buffered() const;
    /// True after a fatal error.
    bool failed() const { return mFailed; }
    /// True while a message has started but is incomplete (for the daemon's trickle timeout).
    bool midMessage() const;

  private:
    std::span<const std::uint8_t> pending() const;
    Result fail(DecodeError error);
    void consume(std::size_t bytes);
    Result needMore(std::size_t messageBytes);

    std::uint32_t mMaxPayloadBytes;
    std::vector<std::uint8_t> mBuffer;
    std::size_t mReadPos = 0; ///< bytes of mBuffer already consumed
    bool mFailed = false;
    DecodeError mFatal;
};

/// The header at the front of `bytes` (which holds at least kHeaderBytes), magic not checked.
Header readHeader(std::span<const std::uint8_t> bytes);

} // namespace bc::protocol
