#pragma once
// The frame image codecs of PROTOCOL.md ("Frame images"): raw, zstd, zstd delta, JPEG and PNG.
// The server encodes with one FrameEncoder per connection, the client decodes with one
// FrameImageDecoder; each keeps the delta base of its side and one reusable zstd and
// turbojpeg context (kept out of this header).
#include "protocol/Wire.h"

#include <cstdint>
#include <memory>
#include <span>
#include <vector>

namespace bc::protocol {

/// The default zstd level (codecQuality 0): on rendered 256^2..512^2 frames level 1 encodes
/// 2-3x faster than level 3 for 6-10% more bytes, and a frame's encode time is latency.
inline constexpr int kDefaultZstdLevel = 1;
inline constexpr int kMaxZstdLevel = 19;
/// The default JPEG quality (codecQuality 0).
inline constexpr int kDefaultJpegQuality = 85;
/// From this JPEG quality on chroma is not subsampled (4:4:4 instead of 4:2:0): asking for
/// that much quality means colour edges matter more than ~40% more bytes (as GIMP does).
inline constexpr int kJpegFullChromaQuality = 90;

/// Encodes a connection's frames; keeps the previous ZstdDelta frame as the delta base.
/// A frame of another codec or size ends the chain: the next delta frame is a keyframe.
/// Not thread-safe: one per connection.
class FrameEncoder {
  public:
    struct Encoded {
        std::vector<std::uint8_t> bytes;
        bool keyframe = false; ///< ZstdDelta: the base was all zeros; false for other codecs
        double encodeMs = 0;
    };

    FrameEncoder();
    ~FrameEncoder();
    FrameEncoder(FrameEncoder&&) noexcept;
    FrameEncoder& operator=(FrameEncoder&&) noexcept;

    /// rgba8: width*height*4 premultiplied RGBA bytes, rows top to bottom. quality: JPEG
    /// 1..100 or zstd level 1..19, 0 = the codec default; PNG 0 fast, 1 small; ignored by Raw.
    /// @throw ProtocolError on an edge outside 1..kMaxImageEdge, a span of the wrong size, a
    /// quality out of range or an unknown codec (the delta base is then unchanged).
    Encoded encode(std::span<const std::uint8_t> rgba8, std::uint16_t width, std::uint16_t height,
                   Codec codec, std::uint8_t quality);
    /// The next ZstdDelta frame is a keyframe (the client lost its base, a frame was dropped).
    void resetDelta();

  private:
    struct Impl;
    std::unique_ptr<Impl> mImpl;
};

/// Decodes frame images on the client side, keeping the delta base: the last ZstdDelta
/// frame. A frame of another codec or a failed decode drops it; a client whose next delta
/// frame then fails asks for a keyframe (SetRenderOptions). Not thread-safe.
class FrameImageDecoder {
  public:
    FrameImageDecoder();
    ~FrameImageDecoder();
    FrameImageDecoder(FrameImageDecoder&&) noexcept;
    FrameImageDecoder& operator=(FrameImageDecoder&&) noexcept;

    /// Returns width*height*4 RGBA bytes (JPEG, PNG: alpha 255); keyframe matters for ZstdDelta
    /// only. Allocates at most that much
    /// whatever the bytes claim. @throw ProtocolError naming what is wrong: bad edge, zstd
    /// content size missing or not width*height*4, corrupt or trailing data, a non-keyframe
    /// delta without a base of this size, JPEG dimensions not those of the header.
    std::vector<std::uint8_t> decode(Codec codec, std::uint16_t width, std::uint16_t height,
                                     bool keyframe, std::span<const std::uint8_t> bytes);

  private:
    struct Impl;
    std::unique_ptr<Impl> mImpl;
};

} // namespace bc::protocol
