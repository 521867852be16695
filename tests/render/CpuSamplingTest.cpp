// The CPU raycaster's fused value + gradient (render/detail/CpuSampling.h): one set of
// trilinear weights and 32 voxels must give the six clamped fetches' central differences to
// float rounding wherever it is used, and the six fetches must stay where it cannot be.
#include "render/detail/CpuSampling.h"

#include <gtest/gtest.h>

#include <algorithm>
#include <cmath>
#include <cstdint>
#include <cstdio>
#include <limits>
#include <random>
#include <string>
#include <vector>

namespace bc::render::detail {
namespace {

/// A random brick of edge^3 voxels between sentinel guards (a read outside the brick would
/// pick up a guard, far off any interpolated value).
template <class T> struct RandomBrick {
    int edge = 0;
    std::vector<T> storage;
    std::size_t guard = 0;
    double lo = 0, hi = 0;
    const T* voxels() const { return storage.data() + guard; }
};

template <class T> RandomBrick<T> randomBrick(int edge, std::mt19937& rng) {
    RandomBrick<T> b;
    b.edge = edge;
    b.guard = std::size_t(2) * edge * edge;
    const std::size_t n = std::size_t(edge) * edge * edge;
    T sentinel;
    if constexpr (std::is_floating_point_v<T>)
        sentinel = std::numeric_limits<T>::quiet_NaN();
    else
        sentinel = std::numeric_limits<T>::max();
    b.storage.assign(n + 2 * b.guard, sentinel);
    for (std::size_t i = 0; i < n; ++i) {
        T x;
        if constexpr (std::is_floating_point_v<T>) {
            x = std::uniform_real_distribution<float>(-250.0f, 3000.0f)(rng);
        } else {
            // Full-range noise, and stretches near the extremes of the type.
            const int lo = std::numeric_limits<T>::min(), hi = std::numeric_limits<T>::max();
            x = T(std::uniform_int_distribution<int>(lo, hi)(rng));
        }
        b.storage[b.guard + i] = x;
    }
    const auto [mn, mx] =
        std::minmax_element(b.storage.begin() + b.guard, b.storage.end() - b.guard);
    b.lo = double(*mn);
    b.hi = double(*mx);
    return b;
}

float randomCoordinate(std::mt19937& rng, float lo, float hi) {
    // Now and then exactly an end of the range, or an integer (a cell face).
    const int pick = std::uniform_int_distribution<int>(0, 19)(rng);
    if (pick == 0) return lo;
    if (pick == 1) return hi;
    const float x = std::uniform_real_distribution<float>(lo, hi)(rng);
    if (pick == 2) return std::clamp(std::round(x), lo, hi);
    return x;
}

/// The central differences at q in double, unclamped (fusedInRange(edge, q) only).
template <class T> glm::dvec3 exactGradient(const RandomBrick<T>& b, glm::vec3 qf) {
    const int e = b.edge;
    auto value = [&](glm::dvec3 q) {
        const int x0 = int(std::floor(q.x)), y0 = int(std::floor(q.y)), z0 = int(std::floor(q.z));
        const double fx = q.x - x0, fy = q.y - y0, fz = q.z - z0;
        double s = 0;
        for (int k = 0; k < 2; ++k)
            for (int j = 0; j < 2; ++j)
                for (int i = 0; i < 2; ++i) {
                    const int x = std::min(x0 + i, e - 1), y = std::min(y0 + j, e - 1),
                              z = std::min(z0 + k, e - 1);
                    const double w = (i ? fx : 1 - fx) * (j ? fy : 1 - fy) * (k ? fz : 1 - fz);
                    if (w != 0) s += w * double(b.voxels()[(std::size_t(z) * e + y) * e + x]);
                }
        return s;
    };
    const glm::dvec3 q(qf);
    return {value(q + glm::dvec3(1, 0, 0)) - value(q - glm::dvec3(1, 0, 0)),
            value(q + glm::dvec3(0, 1, 0)) - value(q - glm::dvec3(0, 1, 0)),
            value(q + glm::dvec3(0, 0, 1)) - value(q - glm::dvec3(0, 0, 1))};
}

struct Worst {
    double relative = 0; ///< |fused - six fetches| / value range, over the three components
    double fusedExact = 0, sixExact = 0; ///< each against the double-precision differences
    std::size_t fused = 0, fallback = 0;
};

/// Compares fetchWithGradient with fetch() and the six-fetch formula at n random q in
/// [lo, hi]^3; returns the worst relative gradient difference among fused samples.
template <class T>
Worst compare(const RandomBrick<T>& b, float lo, float hi, int n, std::mt19937& rng) {
    Worst w;
    const double range = std::max(b.hi - b.lo, 1e-30);
    for (int s = 0; s < n; ++s) {
        const glm::vec3 q(randomCoordinate(rng, lo, hi), randomCoordinate(rng, lo, hi),
                          randomCoordinate(rng, lo, hi));
        const ValueGradient r = fetchWithGradient(b.voxels(), b.edge, q);
        const float value = fetch(b.voxels(), b.edge, q);
        const glm::vec3 g = sixFetchGradient(b.voxels(), b.edge, q);
        // The value is the old fetch bit for bit: classification cannot change.
        EXPECT_EQ(r.value, value) << "q " << q.x << " " << q.y << " " << q.z;
        EXPECT_EQ(r.fused, fusedInRange(b.edge, q));
        if (!r.fused) {
            ++w.fallback;
            EXPECT_EQ(r.gradient.x, g.x);
            EXPECT_EQ(r.gradient.y, g.y);
            EXPECT_EQ(r.gradient.z, g.z);
            continue;
        }
        ++w.fused;
        // Where fused: every voxel read is in the brick, and no old fetch was clamped.
        for (int a = 0; a < 3; ++a) {
            const int x0 = int(std::floor(q[a]));
            EXPECT_GE(x0 - 1, 0);
            EXPECT_LE(x0 + 2, b.edge - 1);
            EXPECT_GE(q[a] - 1.0f, 0.0f);
            EXPECT_LE(q[a] + 1.0f, float(b.edge - 1));
        }
        const glm::dvec3 exact = exactGradient(b, q);
        for (int a = 0; a < 3; ++a) {
            w.fusedExact = std::max(w.fusedExact, std::abs(r.gradient[a] - exact[a]) / range);
            w.sixExact = std::max(w.sixExact, std::abs(g[a] - exact[a]) / range);
            EXPECT_TRUE(std::isfinite(r.gradient[a])) << "read outside the brick";
            const double d = std::abs(double(r.gradient[a]) - double(g[a])) / range;
            w.relative = std::max(w.relative, d);
            EXPECT_LE(d, 1e-5) << "axis " << a << " q " << q.x << " " << q.y << " " << q.z
                               << ": fused " << r.gradient[a] << ", six fetches " << g[a];
        }
    }
    return w;
}

template <class T> void checkType(const char* name, std::uint32_t seed) {
    std::mt19937 rng(seed);
    double worst = 0, fusedExact = 0, sixExact = 0;
    std::size_t fused = 0, fallback = 0;
    for (int brick : {4, 8, 16, 32, 64}) {
        for (int apron : {2, 3}) {
            const int edge = brick + 2 * apron;
            const auto b = randomBrick<T>(edge, rng);
            // Every sample of the payload takes the fused path.
            const float lo = float(apron) - 0.5f, hi = float(apron + brick) - 0.5f;
            const Worst w = compare(b, lo, hi, 20000, rng);
            EXPECT_EQ(w.fallback, 0u) << name << " brick " << brick << " apron " << apron;
            worst = std::max(worst, w.relative);
            fusedExact = std::max(fusedExact, w.fusedExact);
            sixExact = std::max(sixExact, w.sixExact);
            fused += w.fused;
            // The whole stored brick and beyond: both paths, each where it belongs.
            const Worst all = compare(b, -0.75f, float(edge) - 0.25f, 20000, rng);
            EXPECT_GT(all.fused, 0u);
            EXPECT_GT(all.fallback, 0u);
            worst = std::max(worst, all.relative);
            fusedExact = std::max(fusedExact, all.fusedExact);
            sixExact = std::max(sixExact, all.sixExact);
            fused += all.fused;
            fallback += all.fallback;
        }
    }
    std::printf("[sampling] %s: worst |fused - six fetches| / value range = %.3g; against "
                "double: fused %.3g, six fetches %.3g (%zu fused, %zu fallback samples)\n",
                name, worst, fusedExact, sixExact, fused, fallback);
    EXPECT_LE(worst, 1e-5);
}

TEST(CpuSampling, FusedGradientMatchesSixFetchesU8) {
    checkType<std::uint8_t>("u8", 1);
}
TEST(CpuSampling, FusedGradientMatchesSixFetchesU16) {
    checkType<std::uint16_t>("u16", 2);
}
TEST(CpuSampling, FusedGradientMatchesSixFetchesI16) {
    checkType<std::int16_t>("i16", 3);
}
TEST(CpuSampling, FusedGradientMatchesSixFetchesF32) {
    checkType<float>("f32", 4);
}

// Where the fused path stops: 1 <= q < edge - 2 on every axis.
TEST(CpuSampling, FusedRangeEndsWhereAFetchWouldClampOrReadOutside) {
    for (int brick : {8, 32}) {
        for (int apron : {0, 1, 2, 3}) {
            const int edge = brick + 2 * apron;
            const float first = float(apron) - 0.5f, last = float(apron + brick) - 0.5f;
            const float mid = 0.5f * float(edge);
            const bool payloadFused = apron >= 2;
            for (int a = 0; a < 3; ++a) {
                glm::vec3 q(mid);
                q[a] = first;
                EXPECT_EQ(fusedInRange(edge, q), payloadFused) << "apron " << apron;
                q[a] = last;
                EXPECT_EQ(fusedInRange(edge, q), payloadFused) << "apron " << apron;
                q[a] = 1.0f;
                EXPECT_TRUE(fusedInRange(edge, q));
                q[a] = std::nextafter(1.0f, 0.0f);
                EXPECT_FALSE(fusedInRange(edge, q));
                q[a] = std::nextafter(float(edge - 2), 0.0f);
                EXPECT_TRUE(fusedInRange(edge, q));
                q[a] = float(edge - 2); // the cell's +1 neighbour would be voxel edge
                EXPECT_FALSE(fusedInRange(edge, q));
                q[a] = 0.0f;
                EXPECT_FALSE(fusedInRange(edge, q));
                q[a] = float(edge - 1);
                EXPECT_FALSE(fusedInRange(edge, q));
                q[a] = std::numeric_limits<float>::quiet_NaN();
                EXPECT_FALSE(fusedInRange(edge, q));
            }
        }
    }
    // A brick too small for any fused sample (edge <= 3).
    for (int edge : {1, 2, 3})
        for (float x : {0.0f, 0.5f, 1.0f, 1.5f, 2.0f})
            EXPECT_FALSE(fusedInRange(edge, glm::vec3(x)));
}

// At the very border the fallback keeps the clamped six-fetch result (apron 0 and 1 bricks).
TEST(CpuSampling, FallbackAtTheBorderIsTheSixFetchFormula) {
    std::mt19937 rng(5);
    for (int apron : {0, 1}) {
        const int brick = 8, edge = brick + 2 * apron;
        const auto b = randomBrick<std::uint16_t>(edge, rng);
        const float first = float(apron) - 0.5f, last = float(apron + brick) - 0.5f;
        for (float x : {first, 0.0f, 0.25f, 0.999f, float(edge) - 2.5f, float(edge - 2), last,
                        float(edge - 1)}) {
            const glm::vec3 q(x, 0.5f * float(edge), x);
            const ValueGradient r = fetchWithGradient(b.voxels(), edge, q);
            const glm::vec3 g = sixFetchGradient(b.voxels(), edge, q);
            EXPECT_EQ(r.fused, fusedInRange(edge, q));
            if (r.fused) continue;
            EXPECT_EQ(r.value, fetch(b.voxels(), edge, q));
            EXPECT_EQ(r.gradient.x, g.x);
            EXPECT_EQ(r.gradient.y, g.y);
            EXPECT_EQ(r.gradient.z, g.z);
        }
    }
}

} // namespace
} // namespace bc::render::detail
