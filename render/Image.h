#pragma once
// A rendered frame on the host, and its PNG form. Colour is premultiplied by alpha: RGB is
// the image composited over black, A the opacity, so comparing two frames compares what a
// viewer sees over a black background and how opaque each pixel is.
#include <cstddef>
#include <cstdint>
#include <string>
#include <vector>

namespace bc::render {

/// RGBA float image, 4 floats per pixel, row 0 at the top, x fastest, values in [0,1].
struct Image {
    std::uint32_t width = 0, height = 0;
    std::vector<float> rgba;

    Image() = default;
    /// A `w` x `h` image, every channel zero (transparent black).
    Image(std::uint32_t w, std::uint32_t h)
        : width(w), height(h), rgba(std::size_t(w) * std::size_t(h) * 4, 0.0f) {}

    /// The four channels of pixel (x, y); no bounds check.
    float* pixel(std::uint32_t x, std::uint32_t y) {
        return rgba.data() + (std::size_t(y) * width + x) * 4;
    }
    const float* pixel(std::uint32_t x, std::uint32_t y) const {
        return rgba.data() + (std::size_t(y) * width + x) * 4;
    }
};

/// Largest image readPng accepts (pixels), so a forged header cannot ask for gigabytes.
inline constexpr std::uint64_t kMaxPngPixels = std::uint64_t(1) << 28;

/// 8-bit RGBA, each channel round(clamp(v, 0, 1) * 255) (NaN -> 0): what PNGs and frames carry.
std::vector<std::uint8_t> toRgba8(const Image& image);

/// Writes an 8-bit RGBA PNG, each channel round(clamp(v,0,1)*255). Written to a temporary
/// file beside `path` and renamed, so a reader never sees half a file.
/// @throw RenderError naming `path` when it cannot be written.
void writePng(const std::string& path, const Image& image);

/// Reads an 8- or 16-bit gray, gray+alpha, RGB, RGBA or palette PNG as RGBA in [0,1]
/// (16-bit samples become v/65535; a missing alpha reads as 1). The file's colour is taken
/// as already premultiplied, as writePng stores it.
/// @throw RenderInputError naming the file and field ("open", "signature", "IHDR", "data").
Image readPng(const std::string& path);

} // namespace bc::render
