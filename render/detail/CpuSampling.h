#pragma once
// Trilinear sampling of one stored brick for the CPU raycaster (render/CpuRaycaster.cpp):
// the value, and the value with its central-difference gradient from one set of weights.
//
// Positions q are brick-local stored texel coordinates: voxel j of the stored brick (apron
// included) sits at q = j, the brick holds edge^3 voxels, x fastest.
//
// The gradient of render/OPTICS.md is g_a = v(q + e_a) - v(q - e_a) (before scaling), each
// term a clamped trilinear fetch. Trilinear interpolation is linear in the voxel values and
// the offsets are exactly one voxel, so where no fetch is clamped g_a is the trilinear
// interpolation, with q's own weights, of the per-voxel central differences
// D_a[i] = v[i + e_a] - v[i - e_a] over the 8 corners of q's cell: 32 distinct voxels (the
// 2x2x2 cell and its +-1 neighbours along each axis) and one set of weights instead of 56
// loads and 7 weight computations. fusedInRange() says where that holds; elsewhere (apron 0
// or 1, q at the very border of the stored brick) the six clamped fetches stay.

#include <cstddef>

#include <glm/common.hpp>
#include <glm/vec3.hpp>

namespace bc::render::detail {

inline float lerp1(float a, float b, float t) {
    return a + t * (b - a);
}

/// Trilinear at q, clamped to the brick (the shader's fetch() with full-precision weights).
template <class T> float fetch(const T* v, int edge, glm::vec3 q) {
    const float hi = float(edge - 1);
    q = glm::clamp(q, glm::vec3(0.0f), glm::vec3(hi));
    const int x0 = int(q.x), y0 = int(q.y), z0 = int(q.z);
    const float fx = q.x - float(x0), fy = q.y - float(y0), fz = q.z - float(z0);
    const int dx = x0 < edge - 1 ? 1 : 0, dy = y0 < edge - 1 ? edge : 0,
              dz = z0 < edge - 1 ? edge * edge : 0;
    const T* p = v + (std::size_t(z0) * edge + std::size_t(y0)) * edge + std::size_t(x0);
    const float c00 = lerp1(float(p[0]), float(p[dx]), fx);
    const float c10 = lerp1(float(p[dy]), float(p[dy + dx]), fx);
    const float c01 = lerp1(float(p[dz]), float(p[dz + dx]), fx);
    const float c11 = lerp1(float(p[dz + dy]), float(p[dz + dy + dx]), fx);
    return lerp1(lerp1(c00, c10, fy), lerp1(c01, c11, fy), fz);
}

/// The gradient as six clamped fetches (the old formula, and the fallback).
template <class T> glm::vec3 sixFetchGradient(const T* v, int edge, glm::vec3 q) {
    return glm::vec3(
        fetch(v, edge, q + glm::vec3(1, 0, 0)) - fetch(v, edge, q - glm::vec3(1, 0, 0)),
        fetch(v, edge, q + glm::vec3(0, 1, 0)) - fetch(v, edge, q - glm::vec3(0, 1, 0)),
        fetch(v, edge, q + glm::vec3(0, 0, 1)) - fetch(v, edge, q - glm::vec3(0, 0, 1)));
}

/// Whether the fused path applies at q: 1 <= q_a < edge - 2 on every axis. Then q's cell
/// [x0, x0 + 1] and its neighbours x0 - 1, x0 + 2 lie in the stored brick, and none of the
/// seven fetches of the six-fetch formula is clamped (q - e_a >= 0, q + e_a < edge - 1), so
/// the two agree up to float rounding. False for NaN. With an apron of 2 or more every sample
/// of the payload (q in [apron - 1/2, apron + brick - 1/2]) qualifies.
inline bool fusedInRange(int edge, glm::vec3 q) {
    const float hi = float(edge - 2);
    return q.x >= 1.0f && q.y >= 1.0f && q.z >= 1.0f && q.x < hi && q.y < hi && q.z < hi;
}

/// q's cell and trilinear weights, unclamped: only where fusedInRange(edge, q).
template <class T> struct Cell {
    const T* p = nullptr; ///< voxel (x0, y0, z0)
    std::ptrdiff_t sy = 0, sz = 0;
    float fx = 0, fy = 0, fz = 0;
};

template <class T> Cell<T> cellAt(const T* v, int edge, glm::vec3 q) {
    Cell<T> c;
    const int x0 = int(q.x), y0 = int(q.y), z0 = int(q.z);
    c.fx = q.x - float(x0);
    c.fy = q.y - float(y0);
    c.fz = q.z - float(z0);
    c.sy = edge;
    c.sz = std::ptrdiff_t(edge) * edge;
    c.p = v + (std::size_t(z0) * edge + std::size_t(y0)) * edge + std::size_t(x0);
    return c;
}

/// The value at the cell's position: 8 loads, bit for bit fetch(v, edge, q).
template <class T> float cellValue(const Cell<T>& c) {
    const T* p = c.p;
    const std::ptrdiff_t dy = c.sy, dz = c.sz;
    const float c00 = lerp1(float(p[0]), float(p[1]), c.fx);
    const float c10 = lerp1(float(p[dy]), float(p[dy + 1]), c.fx);
    const float c01 = lerp1(float(p[dz]), float(p[dz + 1]), c.fx);
    const float c11 = lerp1(float(p[dz + dy]), float(p[dz + dy + 1]), c.fx);
    return lerp1(lerp1(c00, c10, c.fy), lerp1(c01, c11, c.fy), c.fz);
}

/// The three central differences at the cell's position from its weights: the 8 cell voxels
/// and the 24 neighbours one voxel beyond the cell along each axis (the cell voxels come
/// from cache: cellValue() has just read them).
template <class T> glm::vec3 cellGradient(const Cell<T>& c) {
    const T* p = c.p;
    const std::ptrdiff_t sy = c.sy, sz = c.sz;
    auto at = [p](std::ptrdiff_t o) { return float(p[o]); };
    // Corner (i, j, k) of the cell is p[i + j sy + k sz]; D_a there is
    // v[corner + e_a] - v[corner - e_a]. Interpolated in fetch()'s order: x, then y, then z.
    auto tri = [&c](float d000, float d100, float d010, float d110, float d001, float d101,
                    float d011, float d111) {
        return lerp1(lerp1(lerp1(d000, d100, c.fx), lerp1(d010, d110, c.fx), c.fy),
                     lerp1(lerp1(d001, d101, c.fx), lerp1(d011, d111, c.fx), c.fy), c.fz);
    };
    auto corner = [&](std::ptrdiff_t i, std::ptrdiff_t j, std::ptrdiff_t k, std::ptrdiff_t e) {
        const std::ptrdiff_t o = i + j * sy + k * sz;
        return at(o + e) - at(o - e);
    };
    auto axis = [&](std::ptrdiff_t e) {
        return tri(corner(0, 0, 0, e), corner(1, 0, 0, e), corner(0, 1, 0, e), corner(1, 1, 0, e),
                   corner(0, 0, 1, e), corner(1, 0, 1, e), corner(0, 1, 1, e), corner(1, 1, 1, e));
    };
    return glm::vec3(axis(1), axis(sy), axis(sz));
}

struct ValueGradient {
    float value = 0;
    glm::vec3 gradient{0.0f}; ///< v(q + e_a) - v(q - e_a), unscaled
    bool fused = false;       ///< from one set of weights (else the six clamped fetches)
};

/// The value and the three central differences at q, from one set of weights where
/// fusedInRange(edge, q), else from the seven clamped fetches.
template <class T> ValueGradient fetchWithGradient(const T* v, int edge, glm::vec3 q) {
    ValueGradient r;
    if (fusedInRange(edge, q)) {
        const Cell<T> c = cellAt(v, edge, q);
        r.value = cellValue(c);
        r.gradient = cellGradient(c);
        r.fused = true;
    } else {
        r.value = fetch(v, edge, q);
        r.gradient = sixFetchGradient(v, edge, q);
    }
    return r;
}

} // namespace bc::render::detail
