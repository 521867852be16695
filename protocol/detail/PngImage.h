#pragma once
// PNG frame images (codec 4, PROTOCOL.md): 8-bit RGB, the premultiplied colour with alpha
// dropped (the image composited over black, as JPEG frames). libpng's simplified API, so
// libpng's errors come back as its message, never as a longjmp through our frames.
#include <cstdint>
#include <span>
#include <vector>

namespace bc::protocol::detail {

/// Encodes width*height*4 RGBA bytes as an RGB PNG; `small` trades speed for size (libpng's
/// default compression instead of PNG_IMAGE_FLAG_FAST). @throw ProtocolError from libpng.
std::vector<std::uint8_t> encodePng(std::span<const std::uint8_t> rgba8, std::uint16_t width,
                                    std::uint16_t height, bool small);

/// Decodes a PNG frame image of exactly width x height into RGBA (alpha 255 for RGB images);
/// the size in the PNG header is checked before anything is allocated from it.
/// @throw ProtocolError naming what is wrong.
std::vector<std::uint8_t> decodePng(std::span<const std::uint8_t> bytes, std::uint16_t width,
                                    std::uint16_t height);

} // namespace bc::protocol::detail
