#include "protocol/Decoder.h"

#include "protocol/detail/ByteIo.h"
#include "protocol/detail/MessageRules.h"

#include <algorithm>
#include <optional>

namespace bc::protocol {
namespace {

/// The framing error of a complete header, if any: these leave no way to find the next message.
std::optional<DecodeError> framingError(std::span<const std::uint8_t> bytes,
                                        std::uint32_t maxPayloadBytes) {
    const std::uint32_t magic = detail::ByteReader(bytes).u32();
    if (magic != kMagic)
        return DecodeError{ErrorCode::BadMagic, true, 0, 0,
                           "header.magic: " + detail::hex(magic) + " is not " +
                               detail::hex(kMagic) + " ('BCST')"};
    const Header h = readHeader(bytes);
    if (h.version != kVersion)
        return DecodeError{ErrorCode::UnsupportedVersion, true, h.type, h.request,
                           "header.version: " + std::to_string(h.version) + " is not " +
                               std::to_string(kVersion)};
    if (h.length > maxPayloadBytes)
        return DecodeError{ErrorCode::TooLarge, true, h.type, h.request,
                           "header.length: " + std::to_string(h.length) +
                               " bytes is over the limit of " + std::to_string(maxPayloadBytes)};
    return std::nullopt;
}

} // namespace

Header readHeader(std::span<const std::uint8_t> bytes) {
    detail::ByteReader in(bytes.first(kHeaderBytes));
    in.u32(); // magic
    Header h;
    h.version = in.u8();
    h.type = in.u8();
    h.flags = in.u16();
    h.length = in.u32();
    h.request = in.u32();
    return h;
}

Decoder::Decoder(std::uint32_t maxPayloadBytes) : mMaxPayloadBytes(maxPayloadBytes) {}

void Decoder::feed(std::span<const std::uint8_t> bytes) {
    if (mFailed) return;
    if (const std::size_t have = buffered(); have < kHeaderBytes) {
        // Complete the front header and check it before taking any of its payload.
        const auto head = bytes.first(std::min(bytes.size(), kHeaderBytes - have));
        mBuffer.insert(mBuffer.end(), head.begin(), head.end());
        bytes = bytes.subspan(head.size());
        if (buffered() < kHeaderBytes) return;
        if (auto error = framingError(pending(), mMaxPayloadBytes)) {
            fail(std::move(*error));
            return;
        }
    }
    mBuffer.insert(mBuffer.end(), bytes.begin(), bytes.end());
}

Decoder::Result Decoder::next() {
    if (mFailed) return Result{Status::Error, mFatal.request, {}, mFatal};
    const auto bytes = pending();
    if (bytes.size() < kHeaderBytes) return needMore(kHeaderBytes);
    if (auto error = framingError(bytes, mMaxPayloadBytes)) return fail(std::move(*error));
    const Header h = readHeader(bytes);
    const std::size_t total = kHeaderBytes + h.length;
    if (bytes.size() < total) return needMore(total);

    auto decoded = decodePayload(h.type, h.flags, bytes.subspan(kHeaderBytes, h.length));
    consume(total);
    Result result;
    result.request = h.request;
    if (auto* message = std::get_if<Message>(&decoded)) {
        result.status = Status::Message;
        result.message = std::move(*message);
    } else {
        result.status = Status::Error;
        result.error = std::move(std::get<DecodeError>(decoded));
        result.error.request = h.request;
    }
    return result;
}

std::size_t Decoder::buffered() const {
    return mBuffer.size() - mReadPos;
}

bool Decoder::midMessage() const {
    const auto bytes = pending();
    if (mFailed || bytes.empty()) return false;
    if (bytes.size() < kHeaderBytes) return true;
    if (framingError(bytes, mMaxPayloadBytes)) return false; // an error is ready, not awaited
    return bytes.size() < kHeaderBytes + readHeader(bytes).length;
}

std::span<const std::uint8_t> Decoder::pending() const {
    return std::span<const std::uint8_t>(mBuffer).subspan(mReadPos);
}

Decoder::Result Decoder::fail(DecodeError error) {
    mFailed = true;
    mFatal = std::move(error);
    mBuffer = {};
    mReadPos = 0;
    return Result{Status::Error, mFatal.request, {}, mFatal};
}

void Decoder::consume(std::size_t bytes) {
    mReadPos += bytes;
    if (mReadPos == mBuffer.size()) {
        mBuffer.clear();
        mReadPos = 0;
    }
}

/// Drops consumed bytes (the rest is a part of one message, so each byte moves at most once)
/// and makes room for the whole message, whose size is known and within the limit.
Decoder::Result Decoder::needMore(std::size_t messageBytes) {
    if (mReadPos > 0) {
        mBuffer.erase(mBuffer.begin(), mBuffer.begin() + std::ptrdiff_t(mReadPos));
        mReadPos = 0;
    }
    if (messageBytes > mBuffer.capacity()) mBuffer.reserve(messageBytes);
    return Result{};
}

} // namespace bc::protocol
