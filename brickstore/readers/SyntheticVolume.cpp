// Deterministic test volumes of any size. Each slice is a pure function of (seed, z), so a
// generator needs O(slice) memory and is as fast as the painting of one slice; shapes live in
// normalized coordinates, so a 64^3 and a 4096^3 volume show the same anatomy.
#include "brickstore/Error.h"
#include "brickstore/Readers.h"

#include <algorithm>
#include <cmath>
#include <cstring>
#include <numbers>
#include <vector>

namespace bc::brickstore {

namespace {

using Vec3 = std::array<double, 3>;

std::uint64_t mix64(std::uint64_t z) {
    z = (z ^ (z >> 30)) * 0xbf58476d1ce4e5b9ull;
    z = (z ^ (z >> 27)) * 0x94d049bb133111ebull;
    return z ^ (z >> 31);
}

/// splitmix64: tiny, seedable, and the same sequence on every platform.
class SplitMix64 {
  public:
    explicit SplitMix64(std::uint64_t seed) : mState(seed) {}
    std::uint64_t next() { return mix64(mState += 0x9e3779b97f4a7c15ull); }
    /// Uniform in [lo, hi).
    double uniform(double lo, double hi) {
        return lo + (hi - lo) * double(next() >> 11) * 0x1.0p-53;
    }

  private:
    std::uint64_t mState;
};

Vec3 add(const Vec3& a, const Vec3& b) {
    return {a[0] + b[0], a[1] + b[1], a[2] + b[2]};
}
Vec3 sub(const Vec3& a, const Vec3& b) {
    return {a[0] - b[0], a[1] - b[1], a[2] - b[2]};
}
Vec3 scale(const Vec3& a, double s) {
    return {a[0] * s, a[1] * s, a[2] * s};
}
double dot(const Vec3& a, const Vec3& b) {
    return a[0] * b[0] + a[1] * b[1] + a[2] * b[2];
}
Vec3 cross(const Vec3& a, const Vec3& b) {
    return {a[1] * b[2] - a[2] * b[1], a[2] * b[0] - a[0] * b[2], a[0] * b[1] - a[1] * b[0]};
}
Vec3 normalize(const Vec3& a) {
    return scale(a, 1.0 / std::sqrt(dot(a, a)));
}

/// Common info and slice loop; subclasses paint one slice at a time.
class SyntheticVolume : public VolumeSource {
  public:
    const VolumeInfo& info() const override { return mInfo; }

  protected:
    SyntheticVolume(const std::string& kind, VoxelType type,
                    const std::array<std::uint64_t, 3>& dims, std::uint64_t seed) {
        mInfo.dims = dims;
        mInfo.type = type;
        mInfo.description = "synthetic " + kind + " " + std::to_string(dims[0]) + "x" +
                            std::to_string(dims[1]) + "x" + std::to_string(dims[2]) + ", " +
                            std::string(voxelTypeName(type)) + ", seed " + std::to_string(seed);
        validateVolumeInfo(mInfo, "synth:" + kind);
    }
    /// Writes slice z (sliceBytes() bytes, native type) to `out`.
    virtual void paintSlice(std::uint64_t z, std::byte* out) const = 0;

    VolumeInfo mInfo;

  private:
    void readNextSlices(std::uint64_t count, std::span<std::byte> out) override {
        for (std::uint64_t i = 0; i < count; ++i)
            paintSlice(nextSlice() + i, out.data() + i * mInfo.sliceBytes());
    }
};

// ---------------------------------------------------------------------------------------------
// Checker

class CheckerVolume final : public SyntheticVolume {
  public:
    CheckerVolume(const std::array<std::uint64_t, 3>& dims, std::uint64_t seed)
        : SyntheticVolume("checker", VoxelType::U8, dims, seed) {}

  private:
    void paintSlice(std::uint64_t z, std::byte* out) const override {
        const std::uint64_t dx = mInfo.dims[0], dy = mInfo.dims[1], p = kCheckerPeriodVoxels;
        for (std::uint64_t y = 0; y < dy; ++y) {
            std::byte* row = out + y * dx;
            const std::uint64_t parity = (y / p + z / p) & 1;
            for (std::uint64_t x0 = 0; x0 < dx; x0 += p) {
                const auto value = std::byte(((x0 / p + parity) & 1) ? 255 : 0);
                std::memset(row + x0, int(value), std::min(p, dx - x0));
            }
        }
    }
};

// ---------------------------------------------------------------------------------------------
// Phantom: nested ellipsoids in [-1,1]^3, painted row by row as analytic x-intervals.

struct Ellipsoid {
    Vec3 centre;
    Vec3 semiAxes;
    double value; ///< Hounsfield + 1000; ignored for the skull, whose density varies with depth
};

constexpr double kCsfScale = 0.91; ///< the inner table of the skull, as a fraction of the outer

class PhantomVolume final : public SyntheticVolume {
  public:
    PhantomVolume(const std::array<std::uint64_t, 3>& dims, std::uint64_t seed)
        : SyntheticVolume("phantom", VoxelType::U16, dims, seed), mSeed(seed) {
        const Vec3 skull{0.72, 0.86, 0.84};
        mShapes = {
            {{0, 0, 0}, {0.76, 0.90, 0.88}, 1080},           // scalp, soft tissue
            {{0, 0, 0}, skull, 0},                           // skull (kSkull)
            {{0, 0, 0}, scale(skull, kCsfScale), 1012},      // CSF under the skull
            {{0, 0, 0}, scale(skull, 0.895), 1040},          // grey matter
            {{0, 0.02, 0.08}, {0.50, 0.64, 0.56}, 1028},     // white matter
            {{-0.12, 0.04, 0.14}, {0.06, 0.26, 0.11}, 1008}, // lateral ventricles
            {{0.12, 0.04, 0.14}, {0.06, 0.26, 0.11}, 1008},
            {{0, 0.04, 0.04}, {0.02, 0.12, 0.06}, 1008},     // third ventricle
            {{-0.22, 0.02, 0.02}, {0.08, 0.12, 0.08}, 1046}, // basal ganglia
            {{0.22, 0.02, 0.02}, {0.08, 0.12, 0.08}, 1046},
            {{0, 0.22, 0.10}, {0.015, 0.015, 0.015}, 1350}, // calcified pineal
        };
        SplitMix64 rng(seed ^ 0x5eedf00dull);
        const double side = (rng.next() & 1) ? 1.0 : -1.0;
        const Vec3 lesionCentre{side * rng.uniform(0.15, 0.35), rng.uniform(-0.35, 0.35),
                                rng.uniform(-0.1, 0.4)};
        const double r = rng.uniform(0.03, 0.06);
        mShapes.push_back({lesionCentre, {r, r, r}, 1070}); // a small bleed
    }

  private:
    static constexpr std::size_t kSkin = 0, kSkull = 1;

    void paintSlice(std::uint64_t z, std::byte* out) const override {
        const std::uint64_t dx = mInfo.dims[0];
        std::vector<std::uint16_t> row(dx);
        for (std::uint64_t y = 0; y < mInfo.dims[1]; ++y) {
            paintRow(y, z, row);
            std::memcpy(out + y * dx * sizeof(std::uint16_t), row.data(),
                        dx * sizeof(std::uint16_t));
        }
    }

    double normalized(std::uint64_t i, int axis) const {
        return (double(i) + 0.5) * 2.0 / double(mInfo.dims[axis]) - 1.0;
    }

    /// Voxels [begin, end) of the row whose centres lie in `e`; begin == end when none do.
    std::pair<std::uint64_t, std::uint64_t> span(const Ellipsoid& e, double v, double w) const {
        const double dv = (v - e.centre[1]) / e.semiAxes[1], dw = (w - e.centre[2]) / e.semiAxes[2];
        const double rest = 1.0 - dv * dv - dw * dw;
        if (rest <= 0.0) return {0, 0};
        const double half = e.semiAxes[0] * std::sqrt(rest), dx = double(mInfo.dims[0]);
        const double lo = std::ceil((e.centre[0] - half + 1.0) * dx / 2.0 - 0.5);
        const double hi = std::floor((e.centre[0] + half + 1.0) * dx / 2.0 - 0.5);
        const double begin = std::max(lo, 0.0), end = std::min(hi + 1.0, dx);
        if (end <= begin) return {0, 0};
        return {std::uint64_t(begin), std::uint64_t(end)};
    }

    /// Compact bone at the outer and inner tables, spongy diploe in between (1800..2500).
    double skullValue(std::uint64_t x, double qyz) const {
        const double du =
            (normalized(x, 0) - mShapes[kSkull].centre[0]) / mShapes[kSkull].semiAxes[0];
        const double r = std::sqrt(du * du + qyz);
        const double t = std::clamp((r - kCsfScale) / (1.0 - kCsfScale), 0.0, 1.0);
        return 2500.0 - 2800.0 * t * (1.0 - t);
    }

    void paintRow(std::uint64_t y, std::uint64_t z, std::vector<std::uint16_t>& row) const {
        std::fill(row.begin(), row.end(), std::uint16_t(0));
        const double v = normalized(y, 1), w = normalized(z, 2);
        for (std::size_t s = 0; s < mShapes.size(); ++s) {
            const Ellipsoid& e = mShapes[s];
            const auto [begin, end] = span(e, v, w);
            if (s != kSkull) {
                std::fill(row.begin() + std::ptrdiff_t(begin), row.begin() + std::ptrdiff_t(end),
                          std::uint16_t(e.value));
                continue;
            }
            const double dv = (v - e.centre[1]) / e.semiAxes[1],
                         dw = (w - e.centre[2]) / e.semiAxes[2];
            for (std::uint64_t x = begin; x < end; ++x)
                row[x] = std::uint16_t(std::lround(skullValue(x, dv * dv + dw * dw)));
        }
        // Tissue gets a little noise (-8..8); the air outside the scalp stays exactly 0.
        const auto [begin, end] = span(mShapes[kSkin], v, w);
        const std::uint64_t rowKey = mix64(mSeed ^ mix64(z * 0x100000001b3ull + y));
        for (std::uint64_t x = begin; x < end; ++x) {
            const int noise = int(mix64(rowKey + x * 0x9e3779b97f4a7c15ull) % 17) - 8;
            row[x] = std::uint16_t(std::clamp(int(row[x]) + noise, 0, 4095));
        }
    }

    std::uint64_t mSeed;
    std::vector<Ellipsoid> mShapes; ///< painted in order; later shapes cover earlier ones
};

// ---------------------------------------------------------------------------------------------
// Vessels: a branching tree of tapered capsules in [0,1]^3, binned by z.

struct VesselPiece {
    Vec3 a, b;         ///< axis end points
    double ra, rb;     ///< radius at a and at b
    double brightness; ///< lumen value at the axis, 0..255
};

constexpr int kVesselLevels = 9;         ///< branch generations (2^9 - 1 branches)
constexpr int kPiecesPerBranch = 4;      ///< straight pieces per branch, for tortuosity
constexpr double kVesselFraction = 0.03; ///< target occupancy, before overlaps and clipping
constexpr double kWallFalloff = 0.4;     ///< fraction of the radius over which the lumen fades

class VesselVolume final : public SyntheticVolume {
  public:
    VesselVolume(const std::array<std::uint64_t, 3>& dims, std::uint64_t seed)
        : SyntheticVolume("vessels", VoxelType::U8, dims, seed) {
        SplitMix64 rng(seed);
        const Vec3 root{rng.uniform(0.4, 0.6), rng.uniform(0.4, 0.6), 0.03};
        const Vec3 dir = normalize({rng.uniform(-0.2, 0.2), rng.uniform(-0.2, 0.2), 1.0});
        grow(rng, root, dir, 1.0, 0.33, 0);
        fitRadii();
        binPieces();
    }

  private:
    void grow(SplitMix64& rng, Vec3 start, Vec3 dir, double radius, double length, int level) {
        const double endRadius = radius * 0.92;
        for (int i = 0; i < kPiecesPerBranch; ++i) {
            dir = normalize(add(dir, {rng.uniform(-0.25, 0.25), rng.uniform(-0.25, 0.25),
                                      rng.uniform(-0.25, 0.25)}));
            Vec3 end = add(start, scale(dir, length / kPiecesPerBranch));
            for (int a = 0; a < 3; ++a) { // bounce off the walls so the tree stays inside
                if (end[a] < 0.03 || end[a] > 0.97) {
                    dir[a] = -dir[a];
                    end[a] = start[a] + dir[a] * length / kPiecesPerBranch;
                }
            }
            const double r0 = radius + (endRadius - radius) * i / kPiecesPerBranch;
            const double r1 = radius + (endRadius - radius) * (i + 1) / kPiecesPerBranch;
            mPieces.push_back({start, end, r0, r1, 0.0});
            start = end;
        }
        if (level + 1 >= kVesselLevels) return;
        const Vec3 side = normalize(
            cross(dir, normalize({rng.uniform(-1, 1), rng.uniform(-1, 1), rng.uniform(-1, 1)})));
        const double angles[2] = {rng.uniform(0.35, 0.75), -rng.uniform(0.35, 0.75)};
        for (double angle : angles) {
            const Vec3 child =
                normalize(add(scale(dir, std::cos(angle)), scale(side, std::sin(angle))));
            const double childRadius =
                endRadius * 0.79 * rng.uniform(0.9, 1.05); // Murray's law, roughly
            grow(rng, start, child, childRadius, length * rng.uniform(0.78, 0.9), level + 1);
        }
    }

    /// Scales all radii so that the summed piece volume is kVesselFraction of the unit cube.
    void fitRadii() {
        double volume = 0.0;
        for (const VesselPiece& p : mPieces) {
            const Vec3 ab = sub(p.b, p.a);
            volume += std::numbers::pi * std::sqrt(dot(ab, ab)) *
                      (p.ra * p.ra + p.ra * p.rb + p.rb * p.rb) / 3.0;
        }
        const double factor = std::sqrt(kVesselFraction / volume);
        for (VesselPiece& p : mPieces) {
            p.ra *= factor;
            p.rb *= factor;
            p.brightness = std::min(255.0, 205.0 + 50.0 * std::sqrt(p.ra / mPieces.front().ra));
        }
    }

    void binPieces() {
        mBins.resize(std::min<std::uint64_t>(mInfo.dims[2], 256));
        const double bins = double(mBins.size());
        for (std::size_t i = 0; i < mPieces.size(); ++i) {
            const VesselPiece& p = mPieces[i];
            const double r = std::max(p.ra, p.rb);
            const double lo = std::min(p.a[2], p.b[2]) - r, hi = std::max(p.a[2], p.b[2]) + r;
            const auto first = std::size_t(std::clamp(std::floor(lo * bins), 0.0, bins - 1));
            const auto last = std::size_t(std::clamp(std::floor(hi * bins), 0.0, bins - 1));
            for (std::size_t b = first; b <= last; ++b)
                mBins[b].push_back(std::uint32_t(i));
        }
    }

    double centre(std::uint64_t i, int axis) const {
        return (double(i) + 0.5) / double(mInfo.dims[axis]);
    }

    /// Voxel range [first, last] whose centres may lie within [lo, hi] on `axis`.
    std::pair<std::int64_t, std::int64_t> voxelRange(double lo, double hi, int axis) const {
        const double n = double(mInfo.dims[axis]);
        const double first = std::max(std::floor(lo * n - 0.5), 0.0),
                     last = std::min(std::ceil(hi * n - 0.5), n - 1);
        return {std::int64_t(first), std::int64_t(last)};
    }

    void paintSlice(std::uint64_t z, std::byte* out) const override {
        std::memset(out, 0, mInfo.sliceBytes());
        const double w = centre(z, 2);
        const std::size_t bin = std::min(std::size_t(w * double(mBins.size())), mBins.size() - 1);
        for (std::uint32_t index : mBins[bin])
            paintPiece(mPieces[index], w, out);
    }

    void paintPiece(const VesselPiece& p, double w, std::byte* out) const {
        const double r = std::max(p.ra, p.rb);
        if (w < std::min(p.a[2], p.b[2]) - r || w > std::max(p.a[2], p.b[2]) + r) return;
        const auto [x0, x1] =
            voxelRange(std::min(p.a[0], p.b[0]) - r, std::max(p.a[0], p.b[0]) + r, 0);
        const auto [y0, y1] =
            voxelRange(std::min(p.a[1], p.b[1]) - r, std::max(p.a[1], p.b[1]) + r, 1);
        const Vec3 ab = sub(p.b, p.a);
        const double abLength2 = std::max(dot(ab, ab), 1e-30);
        for (std::int64_t y = y0; y <= y1; ++y) {
            for (std::int64_t x = x0; x <= x1; ++x) {
                const Vec3 ap =
                    sub({centre(std::uint64_t(x), 0), centre(std::uint64_t(y), 1), w}, p.a);
                const double t = std::clamp(dot(ap, ab) / abLength2, 0.0, 1.0);
                const Vec3 off = sub(ap, scale(ab, t));
                const double radius = p.ra + (p.rb - p.ra) * t, d2 = dot(off, off);
                if (d2 >= radius * radius) continue;
                const double s =
                    std::clamp((radius - std::sqrt(d2)) / (kWallFalloff * radius), 0.0, 1.0);
                const auto value =
                    std::uint8_t(std::lround(p.brightness * s * s * (3.0 - 2.0 * s)));
                auto& voxel = reinterpret_cast<std::uint8_t&>(
                    out[std::uint64_t(y) * mInfo.dims[0] + std::uint64_t(x)]);
                voxel = std::max(voxel, value);
            }
        }
    }

    std::vector<VesselPiece> mPieces;
    std::vector<std::vector<std::uint32_t>> mBins; ///< pieces whose z-extent meets each slab of z
};

} // namespace

std::unique_ptr<VolumeSource>
makeSynthetic(SynthKind kind, const std::array<std::uint64_t, 3>& dims, std::uint64_t seed) {
    switch (kind) {
    case SynthKind::Phantom:
        return std::make_unique<PhantomVolume>(dims, seed);
    case SynthKind::Vessels:
        return std::make_unique<VesselVolume>(dims, seed);
    case SynthKind::Checker:
        return std::make_unique<CheckerVolume>(dims, seed);
    }
    throw FormatError("synth", "kind", "unknown generator");
}

} // namespace bc::brickstore
