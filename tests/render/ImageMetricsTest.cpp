// Image error figures (max abs, RMSE, PSNR, SSIM) on known cases (`brickcast compare` end to
// end: tests/tools/CompareCommandTest.cpp).
#include "render/ImageMetrics.h"
#include "render/Image.h"
#include "tests/TestSupport.h"

#include <cmath>
#include <limits>
#include <random>
#include <stdexcept>

namespace bc::render {
namespace {

Image noiseImage(std::uint32_t w, std::uint32_t h, unsigned seed) {
    std::mt19937 rng(seed);
    std::uniform_real_distribution<float> u(0.0f, 1.0f);
    Image image(w, h);
    for (float& v : image.rgba)
        v = u(rng);
    return image;
}

/// A smooth picture with edges: what a rendering looks like more than noise does.
Image scene(std::uint32_t w, std::uint32_t h) {
    Image image(w, h);
    for (std::uint32_t y = 0; y < h; ++y)
        for (std::uint32_t x = 0; x < w; ++x) {
            float* p = image.pixel(x, y);
            const float disc = std::hypot(float(x) - w / 2.0f, float(y) - h / 2.0f) < w / 4.0f;
            p[0] = 0.2f + 0.6f * disc;
            p[1] = 0.5f + 0.4f * std::sin(float(x) * 0.3f) * std::cos(float(y) * 0.2f);
            p[2] = float(x + y) / float(w + h);
            p[3] = 1.0f;
        }
    return image;
}

Image boxBlur(const Image& in) {
    Image out = in;
    for (std::uint32_t y = 1; y + 1 < in.height; ++y)
        for (std::uint32_t x = 1; x + 1 < in.width; ++x)
            for (int c = 0; c < 3; ++c) {
                float sum = 0.0f;
                for (int dy = -1; dy <= 1; ++dy)
                    for (int dx = -1; dx <= 1; ++dx)
                        sum += in.pixel(x + dx, y + dy)[c];
                out.pixel(x, y)[c] = sum / 9.0f;
            }
    return out;
}

Image addNoise(const Image& in, float amplitude, unsigned seed) {
    std::mt19937 rng(seed);
    std::uniform_real_distribution<float> u(-amplitude, amplitude);
    Image out = in;
    for (float& v : out.rgba)
        v = std::clamp(v + u(rng), 0.0f, 1.0f);
    return out;
}

/// SSIM straight from Wang et al.: a 2-D Gaussian window at every valid position, in double.
double directSsim(const Image& a, const Image& b) {
    auto weights = [](std::uint32_t taps) {
        std::vector<double> w(taps);
        double sum = 0.0;
        for (std::uint32_t i = 0; i < taps; ++i) {
            const double r = double(i) - (taps - 1) / 2.0;
            sum += w[i] = std::exp(-r * r / (2.0 * 1.5 * 1.5));
        }
        for (double& v : w)
            v /= sum;
        return w;
    };
    const auto wx = weights(std::min(a.width, 11u)), wy = weights(std::min(a.height, 11u));
    const double c1 = 1e-4, c2 = 9e-4;
    double total = 0.0;
    std::size_t count = 0;
    for (int c = 0; c < 3; ++c)
        for (std::size_t y0 = 0; y0 + wy.size() <= a.height; ++y0)
            for (std::size_t x0 = 0; x0 + wx.size() <= a.width; ++x0, ++count) {
                double ma = 0, mb = 0, aa = 0, bb = 0, ab = 0;
                for (std::size_t j = 0; j < wy.size(); ++j)
                    for (std::size_t i = 0; i < wx.size(); ++i) {
                        const double w = wx[i] * wy[j];
                        const double va = a.pixel(x0 + i, y0 + j)[c],
                                     vb = b.pixel(x0 + i, y0 + j)[c];
                        ma += w * va, mb += w * vb, aa += w * va * va, bb += w * vb * vb,
                            ab += w * va * vb;
                    }
                total += ((2 * ma * mb + c1) * (2 * (ab - ma * mb) + c2)) /
                         ((ma * ma + mb * mb + c1) * (aa - ma * ma + bb - mb * mb + c2));
            }
    return total / double(count);
}

TEST(ImageMetricsTest, IdenticalImagesHaveNoErrorInfinitePsnrAndSsimOne) {
    const Image a = noiseImage(64, 40, 1);
    const ImageComparison c = compareImages(a, a);
    EXPECT_EQ(c.maxAbs, 0.0);
    EXPECT_EQ(c.rmse, 0.0);
    EXPECT_TRUE(std::isinf(c.psnrDb) && c.psnrDb > 0);
    EXPECT_EQ(c.ssim, 1.0);
}

TEST(ImageMetricsTest, SinglePixelChangeGivesExactMaxAbsLocationAndRmse) {
    Image a = noiseImage(64, 48, 2);
    for (float& v : a.rgba)
        v = std::round(v * 256.0f) / 256.0f; // exact in float and double
    Image b = a;
    b.pixel(12, 40)[1] =
        a.pixel(12, 40)[1] > 0.5f ? a.pixel(12, 40)[1] - 0.25f : a.pixel(12, 40)[1] + 0.25f;
    b.pixel(50, 3)[0] =
        a.pixel(50, 3)[0] > 0.5f ? a.pixel(50, 3)[0] - 0.125f : a.pixel(50, 3)[0] + 0.125f;
    const ImageComparison c = compareImages(a, b);
    EXPECT_EQ(c.maxAbs, 0.25);
    EXPECT_EQ(c.maxAbsX, 12u);
    EXPECT_EQ(c.maxAbsY, 40u);
    const double rmse = std::sqrt((0.25 * 0.25 + 0.125 * 0.125) / (64.0 * 48.0 * 4.0));
    EXPECT_NEAR(c.rmse, rmse, 1e-15);
    EXPECT_NEAR(c.psnrDb, 20.0 * std::log10(1.0 / rmse), 1e-9);
    EXPECT_LT(c.ssim, 1.0);
}

TEST(ImageMetricsTest, PsnrOfAUniformErrorIsTwentyLogOfItsInverse) {
    for (double e : {1.0 / 64.0, 1.0 / 255.0, 0.25}) {
        Image a(32, 32), b(32, 32);
        std::fill(a.rgba.begin(), a.rgba.end(), 0.25f);
        std::fill(b.rgba.begin(), b.rgba.end(), float(0.25 + e));
        const ImageComparison c = compareImages(a, b);
        EXPECT_NEAR(c.rmse, e, 1e-7);
        EXPECT_NEAR(c.psnrDb, 20.0 * std::log10(1.0 / e), 1e-4) << e;
    }
}

TEST(ImageMetricsTest, SsimOfFlatImagesIsTheLuminanceTerm) {
    Image a(20, 20), b(20, 20);
    std::fill(a.rgba.begin(), a.rgba.end(), 0.25f);
    std::fill(b.rgba.begin(), b.rgba.end(), 0.75f);
    const double want = (2 * 0.25 * 0.75 + 1e-4) / (0.25 * 0.25 + 0.75 * 0.75 + 1e-4);
    EXPECT_NEAR(compareImages(a, b).ssim, want, 1e-6);
}

TEST(ImageMetricsTest, SsimMatchesTheDirectWindowedDefinitionIncludingTinyImages) {
    for (auto [w, h] : {std::pair{23u, 17u}, {11u, 11u}, {7u, 30u}, {5u, 3u}, {1u, 1u}}) {
        const Image a = scene(w, h);
        const Image b = addNoise(a, 0.1f, w + h);
        EXPECT_NEAR(compareImages(a, b).ssim, directSsim(a, b), 2e-6) << w << "x" << h;
    }
}

TEST(ImageMetricsTest, SsimDropsForBlurAndNoiseAndIsSymmetric) {
    const Image a = scene(128, 96);
    const Image blurred = boxBlur(a);
    const Image lightNoise = addNoise(a, 0.02f, 3);
    const Image heavyNoise = addNoise(a, 0.2f, 4);
    const double sBlur = compareImages(a, blurred).ssim;
    const double sLight = compareImages(a, lightNoise).ssim;
    const double sHeavy = compareImages(a, heavyNoise).ssim;
    EXPECT_LT(sBlur, 0.9999);
    EXPECT_LT(sLight, 1.0);
    EXPECT_GT(sLight, 0.8);
    EXPECT_LT(sHeavy, sLight);
    EXPECT_EQ(compareImages(heavyNoise, a).ssim, sHeavy);
    EXPECT_EQ(compareImages(blurred, a).ssim, sBlur);
    EXPECT_EQ(compareImages(blurred, a).rmse, compareImages(a, blurred).rmse);
}

TEST(ImageMetricsTest, LowPassErrorKeepsStructureAndAveragesNoiseOut) {
    const Image a = scene(96, 80);
    EXPECT_TRUE(std::isinf(compareImages(a, a).lowPassPsnrDb));
    // A bias survives the low pass whole (R, G and B only, so against the RGBA RMSE: sqrt(4/3)).
    Image bias = a, rings = a, noise = a;
    for (std::size_t i = 0; i < bias.rgba.size(); ++i)
        if (i % 4 != 3) bias.rgba[i] += 0.02f;
    const ImageComparison cb = compareImages(a, bias);
    EXPECT_NEAR(cb.lowPassRmse, 0.02, 1e-6);
    EXPECT_NEAR(cb.lowPassPsnrDb, 20.0 * std::log10(1.0 / 0.02), 1e-3);
    // Rings 8 pixels apart and pixel noise of the same RMSE: the rings stay, the noise goes.
    std::mt19937 rng(7);
    std::uniform_int_distribution<int> sign(0, 1);
    for (std::uint32_t y = 0; y < a.height; ++y)
        for (std::uint32_t x = 0; x < a.width; ++x) {
            const float r = std::hypot(float(x) - 48.0f, float(y) - 40.0f);
            const float ring = 0.02f * std::sqrt(2.0f) * std::sin(r * 2.0f * 3.14159265f / 8.0f);
            const float dot = sign(rng) ? 0.02f : -0.02f;
            for (int c = 0; c < 3; ++c) {
                rings.pixel(x, y)[c] += ring;
                noise.pixel(x, y)[c] += dot;
            }
        }
    const ImageComparison cr = compareImages(a, rings), cn = compareImages(a, noise);
    EXPECT_NEAR(cr.rmse, cn.rmse, 0.1 * cn.rmse); // the same error by RMSE ...
    // A sine of period P keeps exp(-2 pi^2 sigma^2 / P^2) = 0.50 of its amplitude; white noise
    // keeps 1 / (2 sqrt(pi) sigma) = 0.19 of its RMSE. (rmse counts alpha too: x sqrt(4/3).)
    EXPECT_GT(cr.lowPassRmse, 0.4 * cr.rmse);
    EXPECT_LT(cn.lowPassRmse, 0.25 * cn.rmse);
    EXPECT_LT(cr.lowPassPsnrDb, cr.psnrDb + 6.0);
    EXPECT_GT(cn.lowPassPsnrDb, cn.psnrDb + 12.0);
    // Symmetric, and defined for images smaller than the window.
    EXPECT_EQ(compareImages(rings, a).lowPassRmse, cr.lowPassRmse);
    Image tiny(3, 2), tinyB(3, 2);
    std::fill(tinyB.rgba.begin(), tinyB.rgba.end(), 0.1f);
    EXPECT_NEAR(compareImages(tiny, tinyB).lowPassRmse, 0.1, 1e-6);
}

TEST(ImageMetricsTest, NanPixelFailsAToleranceCheck) {
    Image a(8, 8), b(8, 8);
    b.pixel(3, 5)[2] = std::numeric_limits<float>::quiet_NaN();
    const ImageComparison c = compareImages(a, b);
    EXPECT_FALSE(c.maxAbs <= 1.0 / 255.0);
    EXPECT_EQ(c.maxAbsX, 3u);
    EXPECT_EQ(c.maxAbsY, 5u);
    EXPECT_FALSE(c.rmse <= 1.0);
}

TEST(ImageMetricsTest, DifferenceImageScalesClampsAndIsOpaque) {
    Image a(2, 1), b(2, 1);
    const float av[8] = {0.5f, 0.25f, 0.0f, 0.0f, 1.0f, 0.0f, 0.5f, 1.0f};
    const float bv[8] = {0.25f, 0.25f, 0.125f, 1.0f, 0.0f, 0.5f, 0.5f, 0.0f};
    std::copy(av, av + 8, a.rgba.begin());
    std::copy(bv, bv + 8, b.rgba.begin());
    const Image d = differenceImage(a, b, 4.0f);
    const float want[8] = {1.0f, 0.0f, 0.5f, 1.0f, 1.0f, 1.0f, 0.0f, 1.0f};
    for (int i = 0; i < 8; ++i)
        EXPECT_EQ(d.rgba[i], want[i]) << i;
    EXPECT_EQ(differenceImage(a, b).rgba[0], 0.25f);
    EXPECT_THROW(differenceImage(a, b, -1.0f), std::invalid_argument);
}

TEST(ImageMetricsTest, MaxAbsAlongCountsOnlyMaskedPixels) {
    Image a(4, 4), b(4, 4);
    b.pixel(1, 1)[0] = 0.5f;
    b.pixel(3, 2)[3] = 0.125f;
    std::vector<std::uint8_t> mask(16, 0);
    EXPECT_EQ(maxAbsAlong(a, b, mask), 0.0);
    mask[2 * 4 + 3] = 1;
    EXPECT_EQ(maxAbsAlong(a, b, mask), 0.125);
    mask[1 * 4 + 1] = 255;
    EXPECT_EQ(maxAbsAlong(a, b, mask), 0.5);
    EXPECT_THROW(maxAbsAlong(a, b, std::vector<std::uint8_t>(15, 1)), std::invalid_argument);
}

TEST(ImageMetricsTest, SizeMismatchThrowsGivingBothSizes) {
    const Image a(64, 32), b(32, 64);
    try {
        compareImages(a, b);
        ADD_FAILURE() << "no error";
    } catch (const std::invalid_argument& e) {
        const std::string what = e.what();
        EXPECT_NE(what.find("64x32"), std::string::npos) << what;
        EXPECT_NE(what.find("32x64"), std::string::npos) << what;
    }
    EXPECT_THROW(differenceImage(a, b), std::invalid_argument);
    EXPECT_THROW(maxAbsAlong(a, b, std::vector<std::uint8_t>(64 * 32)), std::invalid_argument);
}

} // namespace
} // namespace bc::render
