#include "render/RefinementEstimate.h"

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

double estimatedPsnrDb(std::span<const std::uint8_t> finer, std::span<const std::uint8_t> coarser) {
    const double between = psnrRgb8(finer, coarser);
    return std::isinf(between) ? kMaxEstimateDb
                               : std::min(between + 20.0 * std::log10(2.0), kMaxEstimateDb);
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
