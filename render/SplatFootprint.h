#pragma once
// The footprint of a spherical splat: the line integral of a radially symmetric kernel along
// an eye ray, as a function of the ray's distance d from the sphere centre (in radii), looked
// up by the splat's index i and cone half-angle alpha through d = correctedDistance(i, alpha)
// (paper section 4.2).
//
// Kernel, in units of the sphere radius: h(s) = exp(-s^2 / 2 sigma^2) - exp(-1 / 2 sigma^2)
// for s < 1, else 0; sigma = sigmaOverRadius. Shifting the Gaussian down by its rim value makes
// it continuous at the sphere surface, so the footprint falls to 0 at the ellipse with zero
// slope (no visible splat edges, and a table without the square-root cusp of a cut Gaussian).
// Normalised to unit volume integral, so the footprint integrates to 1 over the unit disk:
// overlapping splats add up to the voxel values whatever the radius. A voxel's share of a
// pixel is therefore value * footprint * A / r^2, A the pixel's area on the plane through the
// sphere centre normal to the ray.
//
// For the CPU splatter's inner loops a third form: a 1D table of the line integral over the
// squared distance u = d^2 (no erf, no square root per pixel), linear between entries.
#include <cstddef>
#include <cstdint>
#include <vector>

namespace bc::render {

struct SplatFootprintConfig {
    double sigmaOverRadius = 0.5; ///< Gaussian width in sphere radii, in (0, 10]
    /// Throws std::invalid_argument naming the field when out of range.
    void validate() const;
};

/// Direct evaluation and a 2D table over (i, alpha). Immutable after construction: safe to
/// share between threads.
class SplatFootprint {
  public:
    static constexpr std::uint32_t kIndexSamples = 257; ///< i = k / 256, k = 0..256
    static constexpr std::uint32_t kAngleSamples = 16;  ///< alpha = j deg, j = 0..15
    static constexpr double kTableMaxAngleRad = 15.0 * 3.14159265358979323846 / 180.0;
    /// Worst |lookup - evaluate| over i in [0, 1], alpha in [0, 15 deg], relative to the
    /// centre value lineIntegral(0), for sigmaOverRadius in [0.3, 1] (measured: tests).
    static constexpr double kTableRelativeError = 1e-4;
    static constexpr std::uint32_t kSquaredSamples = 4097; ///< u = d^2 = k / 4096, k = 0..4096
    /// Worst |bySquaredDistance(u) - lineIntegral(sqrt(u))| over u in [0, 1], relative to the
    /// centre value, for sigmaOverRadius in [0.3, 1] (measured: tests).
    static constexpr double kSquaredTableRelativeError = 1e-6;

    explicit SplatFootprint(const SplatFootprintConfig& config = {});

    /// Line integral of the kernel along a ray passing `distanceRadii` from the centre
    /// (closed form with erf); 0 at and beyond 1 and for NaN.
    double lineIntegral(double distanceRadii) const;
    /// Exact footprint: lineIntegral(correctedDistance(index, halfAngleRad)).
    double evaluate(double index, double halfAngleRad) const;
    /// Bilinear table lookup for alpha <= kTableMaxAngleRad, evaluate() beyond; 0 for index
    /// >= 1 or NaN. Index and angle below 0 are taken as 0.
    double lookup(double index, double halfAngleRad) const;

    /// lineIntegral(sqrt(u)) from the 1D table over u = d^2, linear between entries; 0 for
    /// u >= 1 or NaN, u below 0 taken as 0. Cheap enough for a per-pixel loop.
    float bySquaredDistance(float u) const {
        if (!(u < 1.0f)) return 0.0f;
        const float s = (u > 0.0f ? u : 0.0f) * float(kSquaredSamples - 1);
        std::uint32_t k = std::uint32_t(s);
        k = k < kSquaredSamples - 2 ? k : kSquaredSamples - 2;
        const float t = s - float(k), a = mSquared[k];
        return a + t * (mSquared[k + 1] - a);
    }

    /// The table for upload: kAngleSamples rows of kIndexSamples floats, row j at alpha = j
    /// deg, column k at i = k / 256. Texel centres: texcoord = (i * 256 + 0.5) / 257.
    const std::vector<float>& table() const { return mTable; }

  private:
    double mSigma;
    double mRimValue; ///< exp(-1 / 2 sigma^2), subtracted from the Gaussian
    double mNorm;     ///< the kernel's integral over the unit ball
    std::vector<float> mTable;
    std::vector<float> mSquared; ///< kSquaredSamples values of the line integral over d^2
};

} // namespace bc::render
