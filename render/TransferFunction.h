#pragma once
// Transfer functions: the piecewise-linear map from a sample's value (native stored units) to
// straight RGBA, and the table both renderers classify through (see render/OPTICS.md).
//
// File format (configs/tf/README.md has the full text):
//   {"name": "ct-bone", "description": "...", "shading": true,
//    "points": [{"percentile": 90, "rgba": [1, 1, 1, 0]},
//               {"fraction": 0.5, "rgba": [1, 0.9, 0.8, 0.4]},
//               {"value": 1200, "rgba": [1, 1, 1, 0.9]}]}
// - A point is placed by exactly one of "value" (native units), "fraction" (0..1 of
//   [valueMin, valueMax]) or "percentile" (0..100 of the level-0 voxels ABOVE the most
//   populated histogram bin, linear inside a bin; of all voxels when none lie above it).
// - "rgba": straight colour and opacity per unit step (one voxel of the smallest spacing),
//   each in [0, 1]. "shading" (optional) is the file's preferred default.
// - Points are sorted by value (stable); two points at one value make a step (the later one
//   holds at and above it). Linear between points, the end points' RGBA beyond them.
#include <algorithm>
#include <array>
#include <cmath>
#include <cstddef>
#include <cstdint>
#include <optional>
#include <string>
#include <vector>

namespace bc::brickstore {
struct StoreInfo;
}

namespace bc::render {

/// What placing points by fraction and percentile needs to know about a volume.
struct VolumeValueStats {
    double valueMin = 0.0;
    double valueMax = 0.0;
    std::vector<std::uint64_t> histogram; ///< level-0 voxels, equal bins over [valueMin, valueMax]

    /// The store's level-0 value range and histogram.
    static VolumeValueStats fromStore(const brickstore::StoreInfo& info);
    /// Index of the most populated bin (the first of equals). @throw std::invalid_argument if
    /// the histogram is empty.
    std::size_t modeBin() const;
    /// Value below which `percent` % of the voxels above the mode bin lie (linear inside a
    /// bin); of all voxels when none lie above it. @throw std::invalid_argument if the
    /// histogram is empty or holds no voxel, or `percent` is outside [0, 100].
    double percentile(double percent) const;
};

/// How a point's position is given (see the file format above).
enum class Placement { Value, Fraction, Percentile };

/// A point as a user gives it, before it is placed for a volume.
struct PointSpec {
    Placement placement = Placement::Value;
    double position = 0.0;       ///< native units, fraction 0..1 or percentile 0..100
    std::array<float, 4> rgba{}; ///< straight colour, opacity per unit step, each in [0, 1]
};

/// One placed point of a transfer function.
struct ControlPoint {
    double value = 0.0;          ///< native stored units
    std::array<float, 4> rgba{}; ///< straight colour, opacity per unit step
};

/// The sampled transfer function both renderers classify through. Entry i sits at value
/// domainMin + i (domainMax - domainMin) / (entries - 1); opacities are corrected for the step.
/// Built once by TransferFunction::table; `rgba` must not change afterwards (maxOpacity
/// answers from a structure built over it). Immutable use is thread-safe.
struct TransferFunctionTable {
    /// Wraps `rgba` (entries * 4 floats, entries >= 2) and builds the range-max structure.
    /// @throw std::invalid_argument on a bad size or domain (not finite, max <= min).
    TransferFunctionTable(double domainMin, double domainMax, std::vector<float> rgba);

    double domainMin = 0.0;
    double domainMax = 1.0;
    std::uint32_t entries = 0;
    std::vector<float> rgba; ///< entries * 4: straight colour, step-corrected opacity

    /// What a linear-filtered texture returns: u = (v - domainMin) / span * (entries - 1),
    /// clamped, linear between the two neighbouring entries, in double. NaN reads entry 0.
    std::array<float, 4> lookup(double value) const;
    /// Maximum alpha of entries floor(u(lo)) .. ceil(u(hi)) (clamped): an upper bound of the
    /// opacity of every value in [lo, hi], > 0 whenever any of them is not transparent.
    /// O(1). Bounds in either order; a NaN bound answers for the whole table.
    double maxOpacity(double lo, double hi) const;
    /// True when every value in [lo, hi] classifies as fully transparent.
    bool transparent(double lo, double hi) const { return maxOpacity(lo, hi) <= 0.0; }

  private:
    std::vector<float> mAlphaMax; ///< sparse table: level k, entry i = max alpha of [i, i + 2^k)
};

/// The transfer function as pre-integration needs it (Engel et al. 2001, with 1D integral
/// tables as in Lum et al. 2004; render/OPTICS.md): over the table position u of a value,
/// the extinction tau(u) = -ln(1 - alpha) of the opacity per unit step and the
/// extinction-weighted colour tau * rgb are linear between entries, and `integral` holds
/// their running integrals from u = 0. A segment of a ray whose value runs linearly from
/// front to back over a length of d (units of the opacity) then has
///     alpha = 1 - exp(-d * mean tau),  colour = mean(tau * rgb) / mean tau,
/// the means over [u(front), u(back)] being (integral(back) - integral(front)) / du. One table
/// serves every step (d enters only there), so it is built once per transfer function.
/// Integrals are in double: differences of large running sums over a cell or less keep
/// their digits. Over values the function maps to zero opacity the integral is constant to
/// the bit, so a segment there is exactly transparent (empty-space skipping relies on it).
struct PreintegratedTable {
    /// Extinction of an entry whose opacity is 1 (or would exceed this): exp(-40) is far
    /// below one float ulp of 1, so such a segment is opaque at any step of 0.5 and above.
    static constexpr double kMaxExtinction = 40.0;

    struct Entry {
        double integral[4]; ///< of (tau, tau r, tau g, tau b) over [0, i]
        float rate[4];      ///< (tau, tau r, tau g, tau b) at entry i
    };

    double domainMin = 0.0;
    double domainMax = 1.0;
    std::uint32_t entries = 0;
    std::vector<Entry> table;

    /// Where a segment starts or ends: a sample's table position, and the rates and their
    /// integrals there.
    struct End {
        double u = 0.0;
        double integral[4] = {0, 0, 0, 0};
        double rate[4] = {0, 0, 0, 0};
    };

    /// Below this many table cells between front and back, a segment's means are the
    /// average of its ends' rates (exact inside one cell, where the rates are linear), not a
    /// difference of integrals divided by a vanishing du.
    static constexpr double kMinSpan = 1.0 / 1024.0;

    /// Table position of a native value, clamped to [0, entries - 1] (NaN reads 0): the
    /// plain table's, in double.
    double position(double value) const {
        const double last = double(entries - 1);
        const double u = (value - domainMin) / (domainMax - domainMin) * last;
        return u > 0.0 ? std::min(u, last) : 0.0;
    }

    End end(double value) const {
        End e;
        e.u = position(value);
        const auto i = std::min(std::uint32_t(e.u), entries - 2);
        const double w = e.u - double(i);
        const Entry& a = table[i];
        const Entry& b = table[i + 1];
        for (int k = 0; k < 4; ++k) {
            const double slope = double(b.rate[k]) - double(a.rate[k]);
            e.rate[k] = double(a.rate[k]) + slope * w;
            e.integral[k] = a.integral[k] + w * (double(a.rate[k]) + 0.5 * slope * w);
        }
        return e;
    }

    /// Straight colour and opacity of a segment of length `d` whose value runs from `front`
    /// to `back` (front == back: the opacity of one value over d). Exactly 0 opacity when
    /// every value between them is transparent.
    std::array<double, 4> segment(const End& front, const End& back, double d) const {
        const double du = back.u - front.u;
        double mean[4];
        if (std::abs(du) >= kMinSpan) {
            for (int k = 0; k < 4; ++k)
                mean[k] = (back.integral[k] - front.integral[k]) / du;
        } else {
            for (int k = 0; k < 4; ++k)
                mean[k] = 0.5 * (front.rate[k] + back.rate[k]);
        }
        if (!(mean[0] > 0.0)) return {0.0, 0.0, 0.0, 0.0};
        return {std::clamp(mean[1] / mean[0], 0.0, 1.0), std::clamp(mean[2] / mean[0], 0.0, 1.0),
                std::clamp(mean[3] / mean[0], 0.0, 1.0), -std::expm1(-d * mean[0])};
    }
};

class TransferFunction {
  public:
    static constexpr std::uint32_t kDefaultTableEntries = 4096;
    static constexpr std::uint32_t kMaxTableEntries = 1u << 20;
    /// Most points a function may have (files and messages alike).
    static constexpr std::size_t kMaxPoints = 4096;

    /// Parses a transfer-function document (format above) and places its points for a volume.
    /// `sourceName` names the input in errors ("tf.json", "<preset ct-bone>").
    /// @throw RenderInputError naming the source and the field at fault (e.g. points[3].rgba[1]).
    static TransferFunction parse(const std::string& jsonText, const std::string& sourceName,
                                  const VolumeValueStats& stats);
    /// Builds from points without any text format: checks each point (a field such as
    /// "points[2].rgba[1]" or "points[0].fraction" in errors), places it for the volume and
    /// sorts by value (stable). `sourceName` names the input in errors.
    /// @throw RenderInputError naming the source and the point at fault: no points, more than
    /// kMaxPoints, a position or colour not finite or out of its range.
    static TransferFunction fromPoints(const std::vector<PointSpec>& points,
                                       const std::string& sourceName, const VolumeValueStats& stats,
                                       std::string name = {}, std::optional<bool> shading = {});
    /// The preset embedded from configs/tf at build time. Reads no file.
    /// @throw RenderInputError (source "presets", field "name") when there is no such preset;
    /// the message lists the presets and does not repeat the name asked for.
    static TransferFunction preset(const std::string& name, const VolumeValueStats& stats);
    /// Whether `name` is an embedded preset.
    static bool isPreset(const std::string& name);
    /// Names of the presets embedded from configs/tf at build time, sorted.
    static std::vector<std::string> presetNames();

    const std::string& name() const { return mName; }
    const std::string& description() const { return mDescription; }
    /// The document's "shading" default, if it gives one.
    std::optional<bool> shading() const { return mShading; }
    /// The placed points, sorted by value.
    const std::vector<ControlPoint>& points() const { return mPoints; }
    /// Table domain: the volume's [valueMin, valueMax], widened by 1 when they are equal.
    double domainMin() const { return mDomainMin; }
    double domainMax() const { return mDomainMax; }

    /// Whether both map every value alike: the same placed points and the same domain (names,
    /// descriptions and shading defaults do not matter).
    bool sameFunction(const TransferFunction& other) const;
    /// A hash of what sameFunction compares, computed once when the function is built.
    std::uint64_t contentHash() const { return mContentHash; }

    /// The exact piecewise-linear function (straight RGBA, opacity per unit step).
    std::array<float, 4> evaluate(double value) const;
    /// Samples the function at `entries` values over the domain, opacity corrected for
    /// `stepVoxels` (a' = 1 - (1 - a)^stepVoxels). Each entry is evaluate() at its value, except
    /// that a point whose opacity exceeds both entries of its cell is copied onto the nearer
    /// of the two (if higher), so no peak narrower than a cell vanishes.
    /// @throw std::invalid_argument if stepVoxels is not finite and > 0, or entries is outside
    /// [2, kMaxTableEntries].
    TransferFunctionTable table(double stepVoxels,
                                std::uint32_t entries = kDefaultTableEntries) const;

    /// The pre-integration table over `entries` entries: the same entries as table() (peaks
    /// snapped alike) with the opacity per unit step turned into extinction.
    /// @throw std::invalid_argument if entries is outside [2, kMaxTableEntries].
    PreintegratedTable preintegrated(std::uint32_t entries = kDefaultTableEntries) const;

    /// a' = 1 - (1 - a)^stepVoxels, accurate for small a; a' > 0 whenever a > 0.
    static float correctOpacity(float alpha, double stepVoxels);

  private:
    TransferFunction() = default;
    void snapPeaks(std::vector<float>& rgba, std::uint32_t entries) const;
    void setPoints(std::vector<ControlPoint> points, const VolumeValueStats& stats);

    std::string mName, mDescription;
    std::optional<bool> mShading;
    std::vector<ControlPoint> mPoints;
    double mDomainMin = 0.0, mDomainMax = 1.0;
    std::uint64_t mContentHash = 0;
};

} // namespace bc::render
