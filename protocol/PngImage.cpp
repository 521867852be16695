#include "protocol/detail/PngImage.h"

#include "protocol/Error.h"

#include <png.h>
#include <string>

namespace bc::protocol::detail {
namespace {

/// Frees the simplified API's state on every path (a no-op once it has finished).
struct PngImageGuard {
    png_image& image;
    ~PngImageGuard() { png_image_free(&image); }
};

std::string sizeText(png_uint_32 width, png_uint_32 height) {
    return std::to_string(width) + "x" + std::to_string(height);
}

} // namespace

std::vector<std::uint8_t> encodePng(std::span<const std::uint8_t> rgba8, std::uint16_t width,
                                    std::uint16_t height, bool small) {
    const std::size_t pixels = std::size_t{width} * height;
    if (rgba8.size() != pixels * 4)
        throw ProtocolError("PNG encode: " + std::to_string(rgba8.size()) + " bytes for a " +
                            sizeText(width, height) + " RGBA image");
    std::vector<std::uint8_t> rgb(pixels * 3);
    for (std::size_t i = 0; i < pixels; ++i)
        for (int c = 0; c < 3; ++c)
            rgb[3 * i + c] = rgba8[4 * i + c];
    png_image image{};
    image.version = PNG_IMAGE_VERSION;
    image.width = width;
    image.height = height;
    image.format = PNG_FORMAT_RGB;
    image.flags = small ? 0 : PNG_IMAGE_FLAG_FAST;
    PngImageGuard guard{image};
    png_alloc_size_t size = 0;
    // The first call sizes the output, the second writes it.
    if (!png_image_write_to_memory(&image, nullptr, &size, 0, rgb.data(), 0, nullptr))
        throw ProtocolError(std::string("PNG encode: ") + image.message);
    std::vector<std::uint8_t> out(size);
    if (!png_image_write_to_memory(&image, out.data(), &size, 0, rgb.data(), 0, nullptr))
        throw ProtocolError(std::string("PNG encode: ") + image.message);
    out.resize(size);
    return out;
}

std::vector<std::uint8_t> decodePng(std::span<const std::uint8_t> bytes, std::uint16_t width,
                                    std::uint16_t height) {
    png_image image{};
    image.version = PNG_IMAGE_VERSION;
    PngImageGuard guard{image};
    if (!png_image_begin_read_from_memory(&image, bytes.data(), bytes.size()))
        throw ProtocolError(std::string("PNG frame: not a PNG image (") + image.message + ")");
    if (image.width != width || image.height != height)
        throw ProtocolError("PNG frame: the image is " + sizeText(image.width, image.height) +
                            ", the frame header says " + sizeText(width, height));
    image.format = PNG_FORMAT_RGBA;
    std::vector<std::uint8_t> out(std::size_t{width} * height * 4);
    if (!png_image_finish_read(&image, nullptr, out.data(), 0, nullptr))
        throw ProtocolError(std::string("PNG frame: corrupt image (") + image.message + ")");
    return out;
}

} // namespace bc::protocol::detail
