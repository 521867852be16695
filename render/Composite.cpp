#include "render/Composite.h"

#include <algorithm>
#include <stdexcept>
#include <string>

namespace bc::render {

namespace {

void requireSize(const Image& image, const PixelRect& rect, const char* what) {
    if (image.width != rect.width || image.height != rect.height ||
        image.rgba.size() != rect.pixels() * 4)
        throw std::invalid_argument(std::string("composite: ") + what + " is " +
                                    std::to_string(image.width) + "x" +
                                    std::to_string(image.height) + ", its rect " +
                                    std::to_string(rect.width) + "x" + std::to_string(rect.height));
}

} // namespace

void compositeUnder(Image& frame, const PixelRect& frameRect, const PartialImage& back) {
    requireSize(frame, frameRect, "the frame");
    requireSize(back.image, back.rect, "a partial image");
    const std::uint64_t x0 = std::max(frameRect.x, back.rect.x);
    const std::uint64_t y0 = std::max(frameRect.y, back.rect.y);
    const std::uint64_t x1 = std::min(std::uint64_t(frameRect.x) + frameRect.width,
                                      std::uint64_t(back.rect.x) + back.rect.width);
    const std::uint64_t y1 = std::min(std::uint64_t(frameRect.y) + frameRect.height,
                                      std::uint64_t(back.rect.y) + back.rect.height);
    for (std::uint64_t y = y0; y < y1; ++y) {
        float* f = frame.pixel(std::uint32_t(x0 - frameRect.x), std::uint32_t(y - frameRect.y));
        const float* b =
            back.image.rgba.data() + ((y - back.rect.y) * back.rect.width + (x0 - back.rect.x)) * 4;
        for (std::uint64_t x = x0; x < x1; ++x, f += 4, b += 4) {
            const float t = 1.0f - f[3];
            for (int c = 0; c < 4; ++c)
                f[c] += t * b[c];
        }
    }
}

Image compositeFrontToBack(std::uint32_t width, std::uint32_t height,
                           std::span<const PartialImage> frontToBack) {
    Image frame(width, height);
    const PixelRect whole{0, 0, width, height};
    for (const PartialImage& p : frontToBack)
        compositeUnder(frame, whole, p);
    for (float& v : frame.rgba)
        v = std::clamp(v, 0.0f, 1.0f);
    return frame;
}

} // namespace bc::render
