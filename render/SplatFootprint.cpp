#include "render/SplatFootprint.h"

#include "render/SplatGeometry.h"

#include <algorithm>
#include <cmath>
#include <stdexcept>

namespace bc::render {
namespace {

constexpr double kPi = 3.14159265358979323846;
constexpr double kAngleStepRad =
    SplatFootprint::kTableMaxAngleRad / (SplatFootprint::kAngleSamples - 1);
constexpr double kIndexSteps = SplatFootprint::kIndexSamples - 1;

} // namespace

void SplatFootprintConfig::validate() const {
    if (!(sigmaOverRadius > 0.0 && sigmaOverRadius <= 10.0))
        throw std::invalid_argument("splat footprint sigmaOverRadius must lie in (0, 10]");
}

SplatFootprint::SplatFootprint(const SplatFootprintConfig& config) {
    config.validate();
    mSigma = config.sigmaOverRadius;
    const double s2 = mSigma * mSigma;
    mRimValue = std::exp(-0.5 / s2);
    // Integral over the unit ball: 4 pi int_0^1 s^2 exp(-s^2 / 2 sigma^2) ds minus the rim
    // value times the ball's volume.
    const double gaussBall =
        4.0 * kPi *
        (s2 * mSigma * std::sqrt(0.5 * kPi) * std::erf(1.0 / (mSigma * std::sqrt(2.0))) -
         s2 * mRimValue);
    mNorm = gaussBall - 4.0 / 3.0 * kPi * mRimValue;
    mTable.resize(std::size_t(kIndexSamples) * kAngleSamples);
    for (std::uint32_t j = 0; j < kAngleSamples; ++j)
        for (std::uint32_t k = 0; k < kIndexSamples; ++k)
            mTable[std::size_t(j) * kIndexSamples + k] =
                float(evaluate(k / kIndexSteps, j * kAngleStepRad));
    mSquared.resize(kSquaredSamples);
    for (std::uint32_t k = 0; k < kSquaredSamples; ++k)
        mSquared[k] = float(lineIntegral(std::sqrt(k / double(kSquaredSamples - 1))));
}

double SplatFootprint::lineIntegral(double distanceRadii) const {
    const double d = std::abs(distanceRadii);
    if (!(d < 1.0)) return 0.0;
    const double half = std::sqrt((1.0 - d) * (1.0 + d)); // half the chord through the ball
    const double gauss = mSigma * std::sqrt(2.0 * kPi) *
                         std::exp(-0.5 * d * d / (mSigma * mSigma)) *
                         std::erf(half / (mSigma * std::sqrt(2.0)));
    return std::max(0.0, gauss - 2.0 * half * mRimValue) / mNorm;
}

double SplatFootprint::evaluate(double index, double halfAngleRad) const {
    return lineIntegral(correctedDistance(index, halfAngleRad));
}

double SplatFootprint::lookup(double index, double halfAngleRad) const {
    if (!(index < 1.0) || std::isnan(halfAngleRad)) return 0.0;
    if (halfAngleRad > kTableMaxAngleRad) return evaluate(index, halfAngleRad);
    const double fi = std::max(index, 0.0) * kIndexSteps;
    const double fa = std::max(halfAngleRad, 0.0) / kAngleStepRad;
    const std::uint32_t k = std::min(std::uint32_t(fi), kIndexSamples - 2);
    const std::uint32_t j = std::min(std::uint32_t(fa), kAngleSamples - 2);
    const double t = fi - k, u = fa - j;
    const float* row0 = mTable.data() + std::size_t(j) * kIndexSamples + k;
    const float* row1 = row0 + kIndexSamples;
    const double a = row0[0] + t * (row0[1] - row0[0]);
    const double b = row1[0] + t * (row1[1] - row1[0]);
    return a + u * (b - a);
}

} // namespace bc::render
