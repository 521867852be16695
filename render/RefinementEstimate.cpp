#include "render/RefinementEstimate.h"

#include "render/RenderTypes.h"

#include <algorithm>
#include <cmath>
#include <limits>
#include <stdexcept>
#include <string>

namespace bc::render {

double psnrRgb8(std::span<const std::uint8_t> a, std::span<const std::uint8_t> b) {
    if (a.size() != b.size() || a.size() % 4 != 0)
        throw std::invalid_argument("psnrRgb8: images of " + std::to_string(a.size()) + " and " +
                                    std::to_string(b.size()) + " bytes (RGBA of equal size)");
    std::uint64_t squares = 0;
    for (std::size_t i = 0; i < a.size(); i += 4)
        for (std::size_t c = 0; c < 3; ++c) {
            const int d = int(a[i + c]) - int(b[i + c]);
            squares += std::uint64_t(d * d);
        }
    if (squares == 0 || a.empty()) return std::numeric_limits<double>::infinity();
    const double mse = double(squares) / (double(a.size() / 4) * 3.0) / (255.0 * 255.0);
    return -10.0 * std::log10(mse);
}

double estimatedPsnrDb(std::span<const std::uint8_t> finer, std::span<const std::uint8_t> coarser,
                       double gainDb) {
    const double between = psnrRgb8(finer, coarser);
    return std::isinf(between) ? kMaxEstimateDb : std::min(between + gainDb, kMaxEstimateDb);
}

std::uint32_t checkStride(std::uint32_t width, std::uint32_t height) {
    auto pixels = [&](std::uint32_t stride) {
        const PixelLattice l{stride};
        return std::uint64_t(l.first(width)) * l.first(height);
    };
    std::uint32_t stride = 1;
    while (pixels(stride + 1) >= kCheckPixels)
        ++stride;
    return stride;
}

std::vector<std::uint8_t> latticeOf(std::span<const std::uint8_t> rgba8, std::uint32_t width,
                                    std::uint32_t height, std::uint32_t stride) {
    if (rgba8.size() != std::size_t(width) * height * 4)
        throw std::invalid_argument("latticeOf: " + std::to_string(rgba8.size()) +
                                    " bytes are not " + std::to_string(width) + "x" +
                                    std::to_string(height) + " RGBA pixels");
    const PixelLattice l{std::max(stride, 1u)};
    const std::uint32_t w = l.first(width), h = l.first(height);
    std::vector<std::uint8_t> out(std::size_t(w) * h * 4);
    for (std::uint32_t j = 0; j < h; ++j)
        for (std::uint32_t i = 0; i < w; ++i)
            std::copy_n(&rgba8[(std::size_t(l.pixel(j)) * width + l.pixel(i)) * 4], 4,
                        &out[(std::size_t(j) * w + i) * 4]);
    return out;
}

double refinementStep(double step, std::uint32_t pass) {
    return std::ldexp(step, -int(std::min<std::uint32_t>(pass, 60)));
}

bool refineFurther(double estimateDb, double boundDb, double step) {
    if (!(boundDb > 0)) return false;
    if (estimateDb >= boundDb) return false;
    return step / 2.0 >= kFinestRefinementStep;
}

} // namespace bc::render
