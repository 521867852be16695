#pragma once
// How far two frames are apart: the figures the accuracy tests, the benchmark and
// `brickcast compare` report. All of them take the peak value as 1.0.
#include "render/Image.h"

#include <cstdint>
#include <vector>

namespace bc::render {

struct ImageComparison {
    double maxAbs = 0.0;       ///< largest |a-b| over all four channels of all pixels
    double rmse = 0.0;         ///< root mean square of a-b over all four channels
    double psnrDb = 0.0;       ///< 20 log10(1 / rmse); +infinity when rmse == 0
    double ssim = 1.0;         ///< mean SSIM (Wang et al. 2004) of R, G and B, averaged
    std::uint32_t maxAbsX = 0; ///< pixel where maxAbs occurs (the first, in row order)
    std::uint32_t maxAbsY = 0;
    /// RMSE and PSNR of a-b over R, G and B after a Gaussian low pass (sigma 1.5 pixels, the
    /// SSIM window, over the pixels where the window fits): the *structured* error a viewer
    /// integrates, such as wood-grain rings or a bias, while pixel-scale noise (jittered
    /// sampling's) averages out. Rings of a fixed sample lattice keep it low; the same error
    /// spread as noise raises it.
    double lowPassRmse = 0.0;
    double lowPassPsnrDb = 0.0; ///< +infinity when lowPassRmse == 0
};

/// Max abs difference, RMSE, PSNR, SSIM and the low-pass error of two equally sized images. SSIM
/// uses an 11x11 Gaussian window (sigma 1.5, shrunk to fit smaller images), C1 = 0.01^2, C2 =
/// 0.03^2. A NaN in either image makes maxAbs and rmse NaN, so a tolerance check fails.
/// @throw std::invalid_argument when the sizes differ (the message gives both).
ImageComparison compareImages(const Image& a, const Image& b);

/// |a-b| * gain per colour channel, clamped to 1, alpha 1: a viewable picture of where two
/// frames differ. @throw std::invalid_argument when the sizes differ or gain < 0.
Image differenceImage(const Image& a, const Image& b, float gain = 1.0f);

/// Largest |a-b| over the channels of pixels whose `mask` byte (one per pixel, row order)
/// is non-zero; 0 when none is. Used to look for seams along brick borders.
/// @throw std::invalid_argument when the sizes differ or mask is not width*height bytes.
double maxAbsAlong(const Image& a, const Image& b, const std::vector<std::uint8_t>& mask);

} // namespace bc::render
