#include "brickstore/detail/BrickSummary.h"

#include <algorithm>
#include <cstring>
#include <limits>
#include <stdexcept>
#include <string>
#include <type_traits>

namespace bc::brickstore::detail {
namespace {

template <typename T> const T* as(const std::byte* p) {
    return reinterpret_cast<const T*>(p);
}

/// Calls f with a value of the native C++ type of `type` as the template argument.
template <typename F> decltype(auto) dispatch(VoxelType type, F&& f) {
    switch (type) {
    case VoxelType::U8:
        return f(std::uint8_t{});
    case VoxelType::U16:
        return f(std::uint16_t{});
    case VoxelType::I16:
        return f(std::int16_t{});
    case VoxelType::F32:
        break;
    }
    return f(float{});
}

template <typename T> ValueRange rangeOf(const T* v, std::size_t n) {
    T lo = v[0], hi = v[0];
    for (std::size_t i = 1; i < n; ++i) {
        lo = std::min(lo, v[i]);
        hi = std::max(hi, v[i]);
    }
    return {static_cast<float>(lo), static_cast<float>(hi)};
}

template <typename T> struct MinMax { T min, max; };

/// Min/max of v[begin, end) (a plain loop the compiler vectorises).
template <typename T> MinMax<T> rowRange(const T* v, std::uint32_t begin, std::uint32_t end) {
    T mn = v[begin], mx = v[begin];
    for (std::uint32_t i = begin + 1; i < end; ++i) {
        mn = v[i] < mn ? v[i] : mn;
        mx = v[i] > mx ? v[i] : mx;
    }
    return {mn, mx};
}

/// Leaf ranges by separable reduction: windows along x per row, then along y, then along z.
/// Leaf i's window along an axis is stored [i*l, min((i+1)*l, b) + 2a): its payload voxels
/// widened by the apron reach `a` on each side. Only the first `inside` leaves per axis are
/// reduced, and only the rows and planes their windows read.
template <typename T>
void leafRangesT(const T* v, std::uint32_t edge, const BrickGeometry& g,
                 const std::array<std::uint32_t, 3>& inside, std::vector<ValueRange>& out) {
    const std::uint32_t b = g.brickVoxels, a = g.apronVoxels, l = g.leafVoxels;
    const std::uint32_t nx = inside[0], ny = inside[1], nz = inside[2];
    auto lo = [&](std::uint32_t i) { return i * l; };
    auto hi = [&](std::uint32_t i) { return std::min((i + 1) * l, b) + 2 * a; };
    auto merge = [](MinMax<T>& m, const MinMax<T>& o) {
        m.min = std::min(m.min, o.min);
        m.max = std::max(m.max, o.max);
    };
    const std::uint32_t rowsY = hi(ny - 1), planesZ = hi(nz - 1);
    // x: per (z, y) row the windows read, nx windows.
    std::vector<MinMax<T>> rows(std::size_t(planesZ) * rowsY * nx);
    for (std::uint32_t z = 0; z < planesZ; ++z)
        for (std::uint32_t y = 0; y < rowsY; ++y) {
            const T* row = v + (std::size_t(z) * edge + y) * edge;
            for (std::uint32_t lx = 0; lx < nx; ++lx)
                rows[(std::size_t(z) * rowsY + y) * nx + lx] = rowRange(row, lo(lx), hi(lx));
        }
    // y: per z, ny x nx.
    std::vector<MinMax<T>> planes(std::size_t(planesZ) * ny * nx);
    for (std::uint32_t z = 0; z < planesZ; ++z)
        for (std::uint32_t ly = 0; ly < ny; ++ly)
            for (std::uint32_t lx = 0; lx < nx; ++lx) {
                MinMax<T> m = rows[(std::size_t(z) * rowsY + lo(ly)) * nx + lx];
                for (std::uint32_t y = lo(ly) + 1; y < hi(ly); ++y)
                    merge(m, rows[(std::size_t(z) * rowsY + y) * nx + lx]);
                planes[(std::size_t(z) * ny + ly) * nx + lx] = m;
            }
    // z: nz x ny x nx.
    out.resize(std::size_t(nz) * ny * nx);
    for (std::uint32_t lz = 0; lz < nz; ++lz)
        for (std::uint32_t j = 0; j < ny * nx; ++j) {
            MinMax<T> m = planes[std::size_t(lo(lz)) * ny * nx + j];
            for (std::uint32_t z = lo(lz) + 1; z < hi(lz); ++z)
                merge(m, planes[std::size_t(z) * ny * nx + j]);
            out[std::size_t(lz) * ny * nx + j] = {float(m.min), float(m.max)};
        }
}

template <typename T> T mean8(double sum) {
    if constexpr (std::is_floating_point_v<T>) {
        return static_cast<T>(sum / 8.0);
    } else {
        auto s = static_cast<std::int64_t>(sum);
        return static_cast<T>((s + 4) >> 3); // floor((s + 4) / 8): round half up
    }
}

template <typename T>
void downsampleT(const T* a, const T* b, std::uint64_t dx, std::uint64_t dy, T* out) {
    const std::uint64_t ox = (dx + 1) / 2, oy = (dy + 1) / 2;
    for (std::uint64_t y = 0; y < oy; ++y) {
        std::uint64_t y0 = 2 * y, y1 = std::min(2 * y + 1, dy - 1);
        for (std::uint64_t x = 0; x < ox; ++x) {
            std::uint64_t x0 = 2 * x, x1 = std::min(2 * x + 1, dx - 1);
            double s = 0;
            for (const T* p : {a, b})
                s += double(p[y0 * dx + x0]) + double(p[y0 * dx + x1]) + double(p[y1 * dx + x0]) +
                     double(p[y1 * dx + x1]);
            out[y * ox + x] = mean8<T>(s);
        }
    }
}

} // namespace

bool isConstant(std::span<const std::byte> data, std::size_t vb) {
    if (data.size() <= vb) return true;
    // data[i] == data[i + vb] for every i means the bytes repeat with the voxel's period:
    // one memcmp at memory speed.
    return std::memcmp(data.data(), data.data() + vb, data.size() - vb) == 0;
}

ValueRange brickRange(VoxelType type, std::span<const std::byte> brick) {
    return dispatch(type, [&](auto t) {
        using T = decltype(t);
        return rangeOf(as<T>(brick.data()), brick.size() / sizeof(T));
    });
}

std::vector<ValueRange> leafRanges(VoxelType type, std::span<const std::byte> brick,
                                   const BrickGeometry& g,
                                   const std::array<std::uint32_t, 3>& inside) {
    std::vector<ValueRange> out;
    const std::uint32_t edge = g.brickVoxels + 2 * g.apronVoxels;
    const std::uint32_t n = (g.brickVoxels + g.leafVoxels - 1) / g.leafVoxels;
    for (auto i : inside)
        if (i == 0 || i > n)
            throw std::invalid_argument("leafRanges: " + std::to_string(i) + " leaves of " +
                                        std::to_string(n) + " along an axis");
    dispatch(type, [&](auto t) {
        using T = decltype(t);
        leafRangesT(as<T>(brick.data()), edge, g, inside, out);
        return 0;
    });
    return out;
}

std::vector<ValueRange> leafRanges(VoxelType type, std::span<const std::byte> brick,
                                   const BrickGeometry& g) {
    const std::uint32_t n = (g.brickVoxels + g.leafVoxels - 1) / g.leafVoxels;
    return leafRanges(type, brick, g, {n, n, n});
}

std::vector<ValueRange> expandLeafTable(std::span<const ValueRange> clipped, std::uint32_t n,
                                        const std::array<std::uint32_t, 3>& inside) {
    if (clipped.size() != std::size_t(inside[0]) * inside[1] * inside[2] || inside[0] == 0 ||
        inside[1] == 0 || inside[2] == 0)
        throw std::invalid_argument("leaf table of " + std::to_string(clipped.size()) +
                                    " entries for " + std::to_string(inside[0]) + "x" +
                                    std::to_string(inside[1]) + "x" + std::to_string(inside[2]) +
                                    " leaves");
    std::vector<ValueRange> out(std::size_t(n) * n * n);
    for (std::uint32_t z = 0; z < n; ++z) {
        const std::uint32_t cz = std::min(z, inside[2] - 1);
        for (std::uint32_t y = 0; y < n; ++y) {
            const std::uint32_t cy = std::min(y, inside[1] - 1);
            for (std::uint32_t x = 0; x < n; ++x) {
                const std::uint32_t cx = std::min(x, inside[0] - 1);
                out[(std::size_t(z) * n + y) * n + x] =
                    clipped[(std::size_t(cz) * inside[1] + cy) * inside[0] + cx];
            }
        }
    }
    return out;
}

std::vector<std::byte> encodeLeafTable(std::span<const ValueRange> leaves) {
    std::vector<std::byte> out(leaves.size() * 8);
    for (std::size_t i = 0; i < leaves.size(); ++i) {
        std::memcpy(out.data() + 8 * i, &leaves[i].min, 4);
        std::memcpy(out.data() + 8 * i + 4, &leaves[i].max, 4);
    }
    return out;
}

std::vector<ValueRange> decodeLeafTable(std::span<const std::byte> bytes) {
    std::vector<ValueRange> out(bytes.size() / 8);
    for (std::size_t i = 0; i < out.size(); ++i) {
        std::memcpy(&out[i].min, bytes.data() + 8 * i, 4);
        std::memcpy(&out[i].max, bytes.data() + 8 * i + 4, 4);
    }
    return out;
}

void downsampleSlices(VoxelType type, const std::byte* z0, const std::byte* z1, std::uint64_t dx,
                      std::uint64_t dy, std::byte* out) {
    dispatch(type, [&](auto t) {
        using T = decltype(t);
        downsampleT(as<T>(z0), as<T>(z1), dx, dy, reinterpret_cast<T*>(out));
        return 0;
    });
}

void fillConstant(VoxelType type, double value, std::span<std::byte> out) {
    dispatch(type, [&](auto t) {
        using T = decltype(t);
        // Only a damaged store holds a constant its type cannot (found by fuzzing: the cast
        // of an out-of-range double to an integer type is undefined): clamped, NaN as 0.
        if constexpr (std::is_integral_v<T>) {
            const double lo = double(std::numeric_limits<T>::lowest());
            const double hi = double(std::numeric_limits<T>::max());
            value = value == value ? std::clamp(value, lo, hi) : 0.0;
        }
        T v = static_cast<T>(value);
        T* p = reinterpret_cast<T*>(out.data());
        std::fill(p, p + out.size() / sizeof(T), v);
        return 0;
    });
}

std::size_t histogramBin(double v, double lo, double hi, std::size_t n) {
    if (!(hi > lo)) return 0;
    double f = (v - lo) / (hi - lo) * double(n);
    if (!(f > 0)) return 0;
    return std::min<std::size_t>(static_cast<std::size_t>(f), n - 1);
}

HistogramBinner::HistogramBinner(VoxelType type, double lo, double hi, std::size_t bins)
    : mType(type), mLo(lo), mHi(hi), mBins(bins) {
    // 8- and 16-bit voxels look their bin up in a table of every possible value.
    dispatch(type, [&](auto t) {
        using T = decltype(t);
        if constexpr (sizeof(T) <= 2 && std::is_integral_v<T>) {
            mTable.resize(std::size_t(1) << (8 * sizeof(T)));
            for (std::size_t i = 0; i < mTable.size(); ++i) {
                T value;
                auto raw = static_cast<std::make_unsigned_t<T>>(i);
                std::memcpy(&value, &raw, sizeof(T));
                mTable[i] = static_cast<std::uint32_t>(histogramBin(double(value), lo, hi, bins));
            }
        }
        return 0;
    });
}

void HistogramBinner::add(std::span<const std::byte> brick, std::uint32_t edge,
                          const std::array<std::uint32_t, 3>& o,
                          const std::array<std::uint64_t, 3>& e,
                          std::span<std::uint64_t> counts) const {
    dispatch(mType, [&](auto t) {
        using T = decltype(t);
        const T* v = as<T>(brick.data());
        for (std::uint64_t z = 0; z < e[2]; ++z)
            for (std::uint64_t y = 0; y < e[1]; ++y) {
                const T* row = v + ((z + o[2]) * edge + (y + o[1])) * edge + o[0];
                for (std::uint64_t x = 0; x < e[0]; ++x) {
                    if constexpr (sizeof(T) <= 2 && std::is_integral_v<T>)
                        ++counts[mTable[static_cast<std::make_unsigned_t<T>>(row[x])]];
                    else
                        ++counts[histogramBin(double(row[x]), mLo, mHi, mBins)];
                }
            }
        return 0;
    });
}

void HistogramBinner::addValueCounts(std::span<const std::uint64_t> valueCounts,
                                     std::span<std::uint64_t> counts) const {
    if (valueCounts.size() != mTable.size())
        throw std::invalid_argument("histogram: " + std::to_string(valueCounts.size()) +
                                    " value counts for a table of " +
                                    std::to_string(mTable.size()));
    for (std::size_t v = 0; v < valueCounts.size(); ++v)
        counts[mTable[v]] += valueCounts[v];
}

std::size_t valueCountSize(VoxelType type) {
    return dispatch(type, [](auto t) -> std::size_t {
        using T = decltype(t);
        if constexpr (sizeof(T) <= 2 && std::is_integral_v<T>)
            return std::size_t(1) << (8 * sizeof(T));
        else
            return 0;
    });
}

bool countsValues(VoxelType type) {
    return valueCountSize(type) != 0;
}

void countValues(VoxelType type, std::span<const std::byte> brick, std::uint32_t edge,
                 const std::array<std::uint32_t, 3>& o, const std::array<std::uint64_t, 3>& e,
                 std::span<std::uint64_t> valueCounts) {
    if (valueCounts.size() != valueCountSize(type) || valueCounts.empty())
        throw std::invalid_argument("countValues: " + std::to_string(valueCounts.size()) +
                                    " counters for " + std::string(voxelTypeName(type)));
    dispatch(type, [&](auto t) {
        using T = decltype(t);
        if constexpr (sizeof(T) <= 2 && std::is_integral_v<T>) {
            using U = std::make_unsigned_t<T>;
            const U* v = reinterpret_cast<const U*>(brick.data());
            std::uint64_t* c = valueCounts.data();
            for (std::uint64_t z = 0; z < e[2]; ++z)
                for (std::uint64_t y = 0; y < e[1]; ++y) {
                    const U* row = v + ((z + o[2]) * edge + (y + o[1])) * edge + o[0];
                    for (std::uint64_t x = 0; x < e[0]; ++x)
                        ++c[row[x]];
                }
        }
        return 0;
    });
}

} // namespace bc::brickstore::detail
