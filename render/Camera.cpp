#include "render/Camera.h"

#include <algorithm>
#include <cmath>
#include <limits>
#include <stdexcept>

#include <glm/geometric.hpp>

namespace bc::render {
namespace {

constexpr double kPi = 3.14159265358979323846;

bool finite(const glm::dvec3& v) {
    return std::isfinite(v.x) && std::isfinite(v.y) && std::isfinite(v.z);
}

/// The unit vector along `v` (finite, not zero). `v` is first scaled by the power of two that
/// brings its largest component into [1, 2), which is exact: directions of vectors whose squared
/// length would overflow or underflow normalise too, and any other gives the bits of
/// glm::normalize(v). protocol/MessageRules.cpp judges cameras with the same arithmetic.
glm::dvec3 direction(const glm::dvec3& v) {
    const int e = std::ilogb(std::max({std::abs(v.x), std::abs(v.y), std::abs(v.z)}));
    return glm::normalize(
        glm::dvec3(std::ldexp(v.x, -e), std::ldexp(v.y, -e), std::ldexp(v.z, -e)));
}

} // namespace

double Box::radius() const {
    return 0.5 * glm::length(size());
}

Camera Camera::orbit(const Box& box, double azimuthDeg, double elevationDeg, double distanceFactor,
                     double fovYDeg) {
    Camera c;
    const double az = azimuthDeg * kPi / 180.0, el = elevationDeg * kPi / 180.0;
    const glm::dvec3 dir{std::cos(el) * std::cos(az), std::cos(el) * std::sin(az), std::sin(el)};
    const double fit = box.radius() / std::sin(0.5 * fovYDeg * kPi / 180.0);
    c.target = box.centre();
    c.eye = c.target + dir * fit * distanceFactor;
    // +z up, except looking straight down or up the z axis.
    c.up = std::abs(std::sin(el)) > 0.999 ? glm::dvec3{0.0, 1.0, 0.0} : glm::dvec3{0.0, 0.0, 1.0};
    c.fovYDeg = fovYDeg;
    c.orthoHeight = 2.0 * box.radius() * distanceFactor;
    return c;
}

void Camera::validate() const {
    if (!finite(eye)) throw std::invalid_argument("camera eye is not finite");
    if (!finite(target)) throw std::invalid_argument("camera target is not finite");
    if (!finite(up)) throw std::invalid_argument("camera up is not finite");
    const glm::dvec3 view = target - eye;
    if (view == glm::dvec3(0.0)) throw std::invalid_argument("camera eye equals target");
    if (!finite(view)) throw std::invalid_argument("camera target - eye is not finite");
    if (!(glm::length(glm::cross(direction(view), up)) >= 1e-9))
        throw std::invalid_argument("camera up is zero or parallel to the view direction");
    if (!(fovYDeg > 0.0 && fovYDeg < 180.0))
        throw std::invalid_argument("camera fov must lie in (0, 180) degrees");
    if (orthographic && !(orthoHeight > 0.0 && std::isfinite(orthoHeight)))
        throw std::invalid_argument("camera ortho height must be positive");
}

ViewBasis ViewBasis::from(const Camera& camera, std::uint32_t width, std::uint32_t height) {
    camera.validate();
    return fromValid(camera, width, height);
}

ViewBasis ViewBasis::fromValid(const Camera& camera, std::uint32_t width, std::uint32_t height) {
    ViewBasis b;
    b.eye = camera.eye;
    b.orthographic = camera.orthographic;
    b.forward = direction(camera.target - camera.eye);
    const glm::dvec3 right = direction(glm::cross(b.forward, camera.up));
    const glm::dvec3 up = glm::cross(right, b.forward);
    const double aspect = double(width) / double(height);
    const double halfH = camera.orthographic ? 0.5 * camera.orthoHeight
                                             : std::tan(0.5 * camera.fovYDeg * kPi / 180.0);
    b.right = right * (halfH * aspect);
    b.upScaled = up * halfH;
    return b;
}

Ray ViewBasis::ray(double pixelX, double pixelY, std::uint32_t width, std::uint32_t height) const {
    const double sx = 2.0 * (pixelX + 0.5) / width - 1.0;
    const double sy = 1.0 - 2.0 * (pixelY + 0.5) / height;
    if (orthographic) return {eye + sx * right + sy * upScaled, forward};
    return {eye, glm::normalize(forward + sx * right + sy * upScaled)};
}

std::array<double, 2> intersectBox(const Ray& ray, const Box& box) {
    double t0 = -std::numeric_limits<double>::infinity(),
           t1 = std::numeric_limits<double>::infinity();
    for (int a = 0; a < 3; ++a) {
        const double o = ray.origin[a], d = ray.direction[a];
        if (d == 0.0) {
            if (o < box.min[a] || o > box.max[a]) return {1.0, 0.0};
            continue;
        }
        double ta = (box.min[a] - o) / d, tb = (box.max[a] - o) / d;
        if (ta > tb) std::swap(ta, tb);
        t0 = std::max(t0, ta);
        t1 = std::min(t1, tb);
    }
    return {t0, t1};
}

} // namespace bc::render
