// Image error figures. SSIM filters the five local moments (a, b, a^2, b^2, ab) with a
// separable Gaussian, in double: a variance is E[a^2] - E[a]^2, and float's cancellation
// there (~1e-7) shows against C2 ~1e-3 as an SSIM error of ~1e-4.
#include "render/ImageMetrics.h"

#include <algorithm>
#include <array>
#include <cmath>
#include <limits>
#include <stdexcept>
#include <string>
#include <vector>

// The filter loops are most of the time; where the compiler can, it also builds an AVX2
// version of them, picked at load time on CPUs that have it (about twice as fast).
#if defined(__GNUC__) && defined(__x86_64__) && defined(__linux__)
#define BC_SIMD_CLONES __attribute__((target_clones("arch=x86-64-v3", "default")))
#else
#define BC_SIMD_CLONES
#endif

namespace bc::render {
namespace {

constexpr std::uint32_t kSsimWindow = 11;
constexpr double kSsimSigma = 1.5;
constexpr double kSsimC1 = 0.01 * 0.01;
constexpr double kSsimC2 = 0.03 * 0.03;
constexpr int kColourChannels = 3;
constexpr int kMoments = 5; // a, b, a^2, b^2, ab

std::string sizeOf(const Image& image) {
    return std::to_string(image.width) + "x" + std::to_string(image.height);
}

void checkShape(const Image& image, const char* which) {
    if (image.rgba.size() != std::size_t(image.width) * image.height * 4)
        throw std::invalid_argument(std::string("image ") + which + " (" + sizeOf(image) +
                                    ") does not hold width*height*4 floats");
}

void checkSameSize(const Image& a, const Image& b, const char* what) {
    checkShape(a, "a");
    checkShape(b, "b");
    if (a.width != b.width || a.height != b.height)
        throw std::invalid_argument(std::string(what) + ": image sizes differ: " + sizeOf(a) +
                                    " vs " + sizeOf(b));
}

/// True when `d` should replace `best` as the largest difference; a NaN wins once.
bool isWorse(double d, double best) {
    return d > best || (std::isnan(d) && !std::isnan(best));
}

/// A 1-D Gaussian of up to kSsimWindow taps, zero-padded to kSsimWindow so every filter
/// runs the same fixed-length loop (which the compiler unrolls and vectorises).
using Kernel = std::array<double, kSsimWindow>;
using KernelRows = std::array<const double*, kSsimWindow>;

/// Normalised Gaussian of `taps` weights (at most kSsimWindow) centred on the first `taps`.
Kernel gaussianKernel(std::uint32_t taps) {
    Kernel w{};
    const double centre = (double(taps) - 1.0) / 2.0;
    double sum = 0.0;
    for (std::uint32_t i = 0; i < taps; ++i) {
        const double r = double(i) - centre;
        sum += w[i] = std::exp(-r * r / (2.0 * kSsimSigma * kSsimSigma));
    }
    for (double& v : w)
        v /= sum;
    return w;
}

/// out[x] = sum_k w[k] * in[k][x] for x < n: a horizontal pass when in[k] = row + k, a
/// vertical one when in[k] are consecutive rows.
BC_SIMD_CLONES void filterRows(const KernelRows& in, const Kernel& w, double* __restrict out,
                               std::size_t n) {
    for (std::size_t x = 0; x < n; ++x) {
        double sum = 0.0;
        for (std::size_t k = 0; k < kSsimWindow; ++k)
            sum += w[k] * in[k][x];
        out[x] = sum;
    }
}

/// The five moments of row y of one channel, filtered along x into `out` (kMoments rows of
/// `outWidth` values). `raw` holds kMoments rows of a.width + kSsimWindow values, the
/// padding zero, so a shrunk kernel's zero taps read zeros.
void momentsAlongX(const Image& a, const Image& b, int channel, std::uint32_t y, const Kernel& wx,
                   std::size_t outWidth, double* raw, double* out) {
    const std::size_t width = a.width, stride = width + kSsimWindow;
    const float* pa = a.pixel(0, y) + channel;
    const float* pb = b.pixel(0, y) + channel;
    for (std::size_t x = 0; x < width; ++x) {
        const double va = pa[4 * x], vb = pb[4 * x];
        raw[x] = va;
        raw[stride + x] = vb;
        raw[2 * stride + x] = va * va;
        raw[3 * stride + x] = vb * vb;
        raw[4 * stride + x] = va * vb;
    }
    for (int p = 0; p < kMoments; ++p) {
        KernelRows rows;
        for (std::size_t k = 0; k < kSsimWindow; ++k)
            rows[k] = raw + p * stride + k;
        filterRows(rows, wx, out + p * outWidth, outWidth);
    }
}

/// SSIM of one window from its moments. Written so that swapping a and b, or fusing any
/// multiply-add, gives the same bits: SSIM is exactly symmetric, and exactly 1 for equal
/// images (muA^2 + muB^2 is formed as (muA - muB)^2 + 2 muA muB).
double ssimAt(double muA, double muB, double aa, double bb, double ab) {
    const double varA = aa - muA * muA, varB = bb - muB * muB, cov = ab - muA * muB;
    const double apart = muA - muB;
    const double luminanceNum = 2.0 * (muA * muB) + kSsimC1;
    const double luminanceDen = apart * apart + luminanceNum;
    return (luminanceNum * (2.0 * cov + kSsimC2)) / (luminanceDen * (varA + varB + kSsimC2));
}

/// Sum of the SSIM map over one output row; `m` holds the kMoments filtered rows.
BC_SIMD_CLONES double ssimRowSum(const double* m, std::size_t n) {
    double sums[4] = {}; // independent chains, so the adds overlap
    std::size_t x = 0;
    for (; x + 4 <= n; x += 4)
        for (std::size_t i = 0; i < 4; ++i)
            sums[i] += ssimAt(m[x + i], m[n + x + i], m[2 * n + x + i], m[3 * n + x + i],
                              m[4 * n + x + i]);
    for (; x < n; ++x)
        sums[0] += ssimAt(m[x], m[n + x], m[2 * n + x], m[3 * n + x], m[4 * n + x]);
    return (sums[0] + sums[1]) + (sums[2] + sums[3]);
}

/// Mean SSIM of one channel over all valid window positions. Rows filtered along x go
/// into a ring of `ky` rows, from which each output row is filtered along y, so the
/// working set stays in cache.
double channelSsim(const Image& a, const Image& b, int channel, const Kernel& wx, const Kernel& wy,
                   std::size_t kx, std::size_t ky) {
    const std::size_t outWidth = a.width - kx + 1, rowValues = kMoments * outWidth;
    std::vector<double> raw(kMoments * (a.width + kSsimWindow), 0.0);
    std::vector<double> ring(ky * rowValues), zeros(rowValues, 0.0), m(rowValues);
    double sum = 0.0;
    for (std::uint32_t y = 0; y < a.height; ++y) {
        momentsAlongX(a, b, channel, y, wx, outWidth, raw.data(),
                      ring.data() + (y % ky) * rowValues);
        if (y + 1 < ky) continue;
        KernelRows rows; // image rows y + 1 - ky .. y, then zero rows for the padding taps
        for (std::size_t k = 0; k < kSsimWindow; ++k)
            rows[k] = k < ky ? ring.data() + ((y + 1 + k) % ky) * rowValues : zeros.data();
        filterRows(rows, wy, m.data(), rowValues);
        sum += ssimRowSum(m.data(), outWidth);
    }
    return sum / double((a.height - ky + 1) * outWidth);
}

double ssim(const Image& a, const Image& b) {
    if (a.width == 0 || a.height == 0) return 1.0;
    const std::uint32_t kx = std::min(a.width, kSsimWindow), ky = std::min(a.height, kSsimWindow);
    const Kernel wx = gaussianKernel(kx), wy = gaussianKernel(ky);
    double sum = 0.0;
    for (int c = 0; c < kColourChannels; ++c)
        sum += channelSsim(a, b, c, wx, wy, kx, ky);
    return sum / kColourChannels;
}

/// Pixel of row y with the largest |a-b| if it beats c.maxAbs (the first such; a NaN wins).
void locateInRow(const Image& a, const Image& b, std::uint32_t y, ImageComparison& c) {
    const float* pa = a.pixel(0, y);
    const float* pb = b.pixel(0, y);
    for (std::size_t i = 0; i < std::size_t(a.width) * 4; ++i) {
        const double d = std::fabs(double(pa[i]) - double(pb[i]));
        if (!isWorse(d, c.maxAbs)) continue;
        c.maxAbs = d;
        c.maxAbsX = std::uint32_t(i / 4);
        c.maxAbsY = y;
    }
}

/// Fills c.maxAbs and its location; returns the sum of squared differences. Rows are
/// summed per channel (independent chains the compiler vectorises) and only a row whose
/// maximum beats the best so far is searched for the location.
BC_SIMD_CLONES double differenceFigures(const Image& a, const Image& b, ImageComparison& c) {
    double sumSquares = 0.0;
    for (std::uint32_t y = 0; y < a.height; ++y) {
        const float* pa = a.pixel(0, y);
        const float* pb = b.pixel(0, y);
        double squares[4] = {}, maxima[4] = {};
        for (std::size_t x = 0; x < a.width; ++x)
            for (std::size_t ch = 0; ch < 4; ++ch) {
                const double d = double(pa[4 * x + ch]) - double(pb[4 * x + ch]);
                squares[ch] += d * d;
                maxima[ch] = std::max(maxima[ch], std::fabs(d));
            }
        const double rowSquares = (squares[0] + squares[1]) + (squares[2] + squares[3]);
        const double rowMax =
            std::max(std::max(maxima[0], maxima[1]), std::max(maxima[2], maxima[3]));
        if (isWorse(rowMax, c.maxAbs) || (std::isnan(rowSquares) && !std::isnan(c.maxAbs)))
            locateInRow(a, b, y, c);
        sumSquares += rowSquares;
    }
    return sumSquares;
}

/// Root mean square over R, G and B of (a - b) filtered by the SSIM window's Gaussian, over
/// the pixels where the window fits (the whole image is one window when it is smaller).
double lowPassRmse(const Image& a, const Image& b) {
    if (a.width == 0 || a.height == 0) return 0.0;
    const std::uint32_t kx = std::min(a.width, kSsimWindow), ky = std::min(a.height, kSsimWindow);
    const Kernel wx = gaussianKernel(kx), wy = gaussianKernel(ky);
    const std::size_t width = a.width, stride = width + kSsimWindow;
    const std::size_t outWidth = width - kx + 1, outHeight = a.height - ky + 1;
    double sum = 0.0;
    std::vector<double> raw(stride, 0.0), out(outWidth), zeros(outWidth, 0.0);
    std::vector<double> along(std::size_t(a.height) * outWidth);
    for (int c = 0; c < kColourChannels; ++c) {
        // Filtered along x, row by row; then along y over kSsimWindow consecutive rows.
        for (std::uint32_t y = 0; y < a.height; ++y) {
            const float* pa = a.pixel(0, y) + c;
            const float* pb = b.pixel(0, y) + c;
            for (std::size_t x = 0; x < width; ++x)
                raw[x] = double(pa[4 * x]) - double(pb[4 * x]);
            KernelRows rows;
            for (std::size_t k = 0; k < kSsimWindow; ++k)
                rows[k] = raw.data() + k;
            filterRows(rows, wx, along.data() + y * outWidth, outWidth);
        }
        for (std::size_t y = 0; y < outHeight; ++y) {
            KernelRows rows;
            for (std::size_t k = 0; k < kSsimWindow; ++k)
                rows[k] = k < ky ? along.data() + (y + k) * outWidth : zeros.data();
            filterRows(rows, wy, out.data(), outWidth);
            for (double v : out)
                sum += v * v;
        }
    }
    return std::sqrt(sum / double(outWidth * outHeight * kColourChannels));
}

} // namespace

ImageComparison compareImages(const Image& a, const Image& b) {
    checkSameSize(a, b, "compareImages");
    ImageComparison c;
    const double sumSquares = differenceFigures(a, b, c);
    const double values = double(a.rgba.size());
    c.rmse = values > 0 ? std::sqrt(sumSquares / values) : 0.0;
    c.psnrDb =
        c.rmse == 0.0 ? std::numeric_limits<double>::infinity() : 20.0 * std::log10(1.0 / c.rmse);
    c.ssim = ssim(a, b);
    c.lowPassRmse = lowPassRmse(a, b);
    c.lowPassPsnrDb = c.lowPassRmse == 0.0 ? std::numeric_limits<double>::infinity()
                                           : 20.0 * std::log10(1.0 / c.lowPassRmse);
    return c;
}

Image differenceImage(const Image& a, const Image& b, float gain) {
    checkSameSize(a, b, "differenceImage");
    if (!(gain >= 0.0f) || !std::isfinite(gain))
        throw std::invalid_argument("differenceImage: gain must be finite and >= 0, got " +
                                    std::to_string(gain));
    Image out(a.width, a.height);
    for (std::size_t i = 0; i < out.rgba.size(); i += 4) {
        for (std::size_t c = 0; c < 3; ++c) {
            const float d = std::fabs(a.rgba[i + c] - b.rgba[i + c]) * gain;
            out.rgba[i + c] = d <= 1.0f ? d : 1.0f; // NaN shows as 1
        }
        out.rgba[i + 3] = 1.0f;
    }
    return out;
}

double maxAbsAlong(const Image& a, const Image& b, const std::vector<std::uint8_t>& mask) {
    checkSameSize(a, b, "maxAbsAlong");
    if (mask.size() != std::size_t(a.width) * a.height)
        throw std::invalid_argument("maxAbsAlong: mask has " + std::to_string(mask.size()) +
                                    " bytes for a " + sizeOf(a) + " image");
    double best = 0.0;
    for (std::size_t p = 0; p < mask.size(); ++p) {
        if (!mask[p]) continue;
        for (std::size_t c = 0; c < 4; ++c) {
            const double d = std::fabs(double(a.rgba[4 * p + c]) - double(b.rgba[4 * p + c]));
            if (isWorse(d, best)) best = d;
        }
    }
    return best;
}

} // namespace bc::render
