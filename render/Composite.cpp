#include "render/Composite.h"

#include "render/detail/CpuRay.h"

#include "render/TransferFunction.h"

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

/// Runs `pixel(f, b)` over the pixels `back` shares with `frame` (at `frameRect`): f the frame's
/// RGBA, b the back image's.
template <class Pixel>
void forSharedPixels(Image& frame, const PixelRect& frameRect, const PartialImage& back,
                     const Pixel& pixel) {
    requireSize(frame, frameRect, "the frame");
    requireSize(back.image, back.rect, "a partial image");
    const auto shared = overlap(frameRect, back.rect);
    if (!shared) return;
    for (std::uint32_t y = shared->y; y < shared->y + shared->height; ++y) {
        float* f = frame.pixel(shared->x - frameRect.x, y - frameRect.y);
        const float* b = back.image.pixel(shared->x - back.rect.x, y - back.rect.y);
        for (std::uint32_t x = 0; x < shared->width; ++x, f += 4, b += 4)
            pixel(f, b);
    }
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

PartsCombine combineFor(BlendMode mode) {
    switch (mode) {
    case BlendMode::Maximum:
        return PartsCombine::Maximum;
    case BlendMode::Minimum:
        return PartsCombine::Minimum;
    case BlendMode::Average:
        return PartsCombine::Sum;
    case BlendMode::Composite:
    case BlendMode::Isosurface:
        break;
    }
    return PartsCombine::Over;
}

void resolveProjections(Image& image, BlendMode mode, const TransferFunctionTable& table) {
    // The CPU raycaster's classify(), through a Frame of the table alone (its tfScale and
    // tfOffset as the raycaster sets them).
    detail::Frame f;
    const double span = table.domainMax - table.domainMin, last = double(table.entries - 1);
    f.tf = table.rgba.data();
    f.entries = int(table.entries);
    f.tfScale = float(last / span);
    f.tfOffset = float(-table.domainMin * last / span);
    for (std::size_t p = 0; p + 3 < image.rgba.size(); p += 4) {
        float* px = &image.rgba[p];
        const float count = px[1];
        if (!(count > 0.0f)) {
            std::fill(px, px + 4, 0.0f);
            continue;
        }
        const detail::Rgba c =
            detail::classify(f, mode == BlendMode::Average ? px[0] / count : px[0]);
        px[0] = std::clamp(c.r * c.a, 0.0f, 1.0f);
        px[1] = std::clamp(c.g * c.a, 0.0f, 1.0f);
        px[2] = std::clamp(c.b * c.a, 0.0f, 1.0f);
        px[3] = std::clamp(c.a, 0.0f, 1.0f);
    }
}

void combineUnder(Image& frame, const PixelRect& frameRect, const PartialImage& back,
                  PartsCombine how) {
    if (how == PartsCombine::Over) return compositeUnder(frame, frameRect, back);
    forSharedPixels(frame, frameRect, back, [how](float* f, const float* b) {
        if (!(b[1] > 0.0f)) return; // no samples behind
        if (!(f[1] > 0.0f) || how == PartsCombine::Sum)
            f[0] = f[1] > 0.0f ? f[0] + b[0] : b[0];
        else if (how == PartsCombine::Maximum ? b[0] > f[0] : b[0] < f[0])
            f[0] = b[0];
        f[1] += b[1];
    });
}

void compositeUnder(Image& frame, const PixelRect& frameRect, const PartialImage& back) {
    forSharedPixels(frame, frameRect, back, [](float* f, const float* b) {
        const float t = 1.0f - f[3];
        for (int c = 0; c < 4; ++c)
            f[c] += t * b[c];
    });
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

Image compositeFrontToBack(std::uint32_t width, std::uint32_t height,
                           std::span<const PartialImage> frontToBack, PartsCombine how) {
    if (how == PartsCombine::Over) return compositeFrontToBack(width, height, frontToBack);
    Image frame(width, height);
    const PixelRect whole{0, 0, width, height};
    for (const PartialImage& p : frontToBack)
        combineUnder(frame, whole, p, how);
    return frame;
}

} // namespace bc::render
