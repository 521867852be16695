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

std::optional<PixelRect> overlap(const PixelRect& a, const PixelRect& b) {
    const std::uint64_t x0 = std::max(a.x, b.x), y0 = std::max(a.y, b.y);
    const std::uint64_t x1 = std::min(std::uint64_t(a.x) + a.width, std::uint64_t(b.x) + b.width);
    const std::uint64_t y1 = std::min(std::uint64_t(a.y) + a.height, std::uint64_t(b.y) + b.height);
    if (x0 >= x1 || y0 >= y1) return std::nullopt;
    return PixelRect{std::uint32_t(x0), std::uint32_t(y0), std::uint32_t(x1 - x0),
                     std::uint32_t(y1 - y0)};
}

void clampToUnit(Image& image) {
    for (float& v : image.rgba)
        v = std::clamp(v, 0.0f, 1.0f);
}

void compositeUnder(Image& frame, const PixelRect& frameRect, const PartialImage& back) {
    requireSize(frame, frameRect, "the frame");
    requireSize(back.image, back.rect, "a partial image");
    const auto shared = overlap(frameRect, back.rect);
    if (!shared) return;
    for (std::uint32_t y = shared->y; y < shared->y + shared->height; ++y) {
        float* f = frame.pixel(shared->x - frameRect.x, y - frameRect.y);
        const float* b = back.image.pixel(shared->x - back.rect.x, y - back.rect.y);
        for (std::uint32_t x = 0; x < shared->width; ++x, f += 4, b += 4) {
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
    clampToUnit(frame);
    return frame;
}

} // namespace bc::render
