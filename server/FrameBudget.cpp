#include "server/FrameBudget.h"

#include <algorithm>
#include <stdexcept>

namespace bc::server {

InteractiveBudget::InteractiveBudget(double targetMs) : mTargetMs(targetMs) {
    if (!(targetMs > 0)) throw std::invalid_argument("interactive frame budget: target ms <= 0");
}

double InteractiveBudget::expectedMs(const std::string& volume, const std::string& renderer,
                                     std::uint64_t pixels) const {
    const auto it = mMsPerPixel.find({volume, renderer});
    return it == mMsPerPixel.end() ? -1.0 : it->second * double(pixels);
}

std::uint32_t InteractiveBudget::divisor(const std::string& volume, const std::string& renderer,
                                         std::uint32_t width, std::uint32_t height) const {
    const auto it = mMsPerPixel.find({volume, renderer});
    if (it == mMsPerPixel.end()) return kFirstDivisor;
    std::uint32_t chosen = 1;
    for (const std::uint32_t d : kDivisors) {
        // Past the smallest edge allowed, a larger divisor draws no smaller an image.
        if (d > 1 && std::min(drawnEdge(width, d), drawnEdge(height, d)) < kMinEdge) break;
        chosen = d;
        const double pixels = double(drawnEdge(width, d)) * double(drawnEdge(height, d));
        if (it->second * pixels <= mTargetMs) break;
    }
    return chosen;
}

void InteractiveBudget::record(const std::string& volume, const std::string& renderer,
                               std::uint64_t pixels, double ms) {
    if (pixels == 0 || !(ms >= 0)) return;
    const double rate = ms / double(pixels);
    auto [it, fresh] = mMsPerPixel.try_emplace({volume, renderer}, rate);
    if (!fresh) it->second = rate > it->second ? rate : 0.5 * (it->second + rate);
}

} // namespace bc::server
