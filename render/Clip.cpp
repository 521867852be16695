#include "render/Clip.h"

#include "render/Camera.h"

#include <glm/geometric.hpp>

#include <algorithm>
#include <cmath>
#include <limits>
#include <stdexcept>
#include <string>

namespace bc::render {

void Clip::validate() const {
    if (cropped)
        for (int a = 0; a < 3; ++a)
            if (!std::isfinite(cropMin[a]) || !std::isfinite(cropMax[a]) ||
                !(cropMin[a] < cropMax[a]))
                throw std::invalid_argument(
                    "crop: the box must have finite bounds with min < max on every axis (axis " +
                    std::string(1, "xyz"[a]) + ": " + std::to_string(cropMin[a]) + ".." +
                    std::to_string(cropMax[a]) + ")");
    if (planeCount > kMaxPlanes)
        throw std::invalid_argument("clip: " + std::to_string(planeCount) + " planes, at most " +
                                    std::to_string(kMaxPlanes));
    for (std::uint32_t i = 0; i < planeCount; ++i) {
        const ClipPlane& p = planes[i];
        const std::string field = "clip[" + std::to_string(i) + "]";
        if (!std::isfinite(p.normal[0]) || !std::isfinite(p.normal[1]) ||
            !std::isfinite(p.normal[2]) || !std::isfinite(p.offset))
            throw std::invalid_argument(field + ": the normal and offset must be finite");
        const double largest =
            std::max({std::abs(p.normal[0]), std::abs(p.normal[1]), std::abs(p.normal[2])});
        // A normal whose length is zero or below what float resolves has no direction.
        if (!(largest > 1e-30))
            throw std::invalid_argument(field + ": the normal is zero (a plane needs a direction)");
    }
}

std::array<double, 2> Clip::interval(const glm::dvec3& o, const glm::dvec3& d,
                                     glm::dvec3* entryNormal) const {
    constexpr double kInf = std::numeric_limits<double>::infinity();
    double ta = -kInf, tb = kInf;
    if (entryNormal) *entryNormal = glm::dvec3(0.0);
    if (cropped)
        for (int a = 0; a < 3; ++a) {
            if (d[a] == 0.0) {
                if (o[a] < cropMin[a] || o[a] > cropMax[a]) return {kInf, -kInf};
                continue;
            }
            const double u0 = (cropMin[a] - o[a]) / d[a], u1 = (cropMax[a] - o[a]) / d[a];
            if (entryNormal && std::min(u0, u1) > ta) {
                *entryNormal = glm::dvec3(0.0);
                (*entryNormal)[a] = u0 < u1 ? 1.0 : -1.0;
            }
            ta = std::max(ta, std::min(u0, u1));
            tb = std::min(tb, std::max(u0, u1));
        }
    for (std::uint32_t i = 0; i < planeCount; ++i) {
        const glm::dvec3 n(planes[i].normal[0], planes[i].normal[1], planes[i].normal[2]);
        const double nd = glm::dot(n, d), no = glm::dot(n, o) + planes[i].offset;
        if (nd == 0.0) {
            if (no < 0.0) return {kInf, -kInf};
            continue;
        }
        const double t = -no / nd;
        if (nd > 0.0) {
            if (entryNormal && t > ta) { // unit length by a scale that cannot overflow
                const glm::dvec3 m = n / std::max({std::abs(n.x), std::abs(n.y), std::abs(n.z)});
                *entryNormal = m / glm::length(m);
            }
            ta = std::max(ta, t);
        } else {
            tb = std::min(tb, t);
        }
    }
    return {ta, tb};
}

bool Clip::outside(const Box& box) const {
    if (cropped)
        for (int a = 0; a < 3; ++a)
            if (box.max[a] < cropMin[a] || box.min[a] > cropMax[a]) return true;
    for (std::uint32_t i = 0; i < planeCount; ++i) {
        // The corner furthest along the normal: if even it is cut, the whole box is.
        const ClipPlane& p = planes[i];
        double best = p.offset;
        for (int a = 0; a < 3; ++a)
            best += p.normal[a] * (p.normal[a] > 0.0 ? box.max[a] : box.min[a]);
        if (best < 0.0) return true;
    }
    return false;
}

ClipF ClipF::of(const Clip& c) {
    ClipF f;
    f.cropped = c.cropped;
    f.any = c.any();
    f.cap = c.cap;
    for (int a = 0; a < 3; ++a) {
        f.cropMin[a] = float(c.cropMin[a]);
        f.cropMax[a] = float(c.cropMax[a]);
    }
    f.planeCount = int(c.planeCount);
    for (std::uint32_t i = 0; i < c.planeCount; ++i) {
        // Unit normals (by a scale that cannot overflow), offsets within float's range: the
        // same half-space, in numbers float holds.
        const ClipPlane& p = c.planes[i];
        const double big =
            std::max({std::abs(p.normal[0]), std::abs(p.normal[1]), std::abs(p.normal[2])});
        const glm::dvec3 n = glm::dvec3(p.normal[0], p.normal[1], p.normal[2]) / big;
        const double length = glm::length(n) * big;
        f.normals[i] = glm::vec3(n / glm::length(n));
        f.offsets[i] = float(std::clamp(p.offset / length, -1e30, 1e30));
    }
    return f;
}

} // namespace bc::render
