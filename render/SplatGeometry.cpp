#include "render/SplatGeometry.h"

#include <algorithm>
#include <cmath>
#include <limits>
#include <stdexcept>
#include <string>

#include <glm/geometric.hpp>

namespace bc::render {
namespace {

constexpr double kBasisTolerance = 1e-9;

bool finite(const glm::dvec3& v) {
    return std::isfinite(v.x) && std::isfinite(v.y) && std::isfinite(v.z);
}

bool finite(const glm::dvec2& v) {
    return std::isfinite(v.x) && std::isfinite(v.y);
}

void requireUnit(const glm::dvec3& v, const char* name) {
    if (!finite(v))
        throw std::invalid_argument(std::string("splat view ") + name + " is not finite");
    if (std::abs(glm::length(v) - 1.0) > kBasisTolerance)
        throw std::invalid_argument(std::string("splat view ") + name + " is not unit length");
}

void requireOrthogonal(const glm::dvec3& a, const glm::dvec3& b, const char* names) {
    if (std::abs(glm::dot(a, b)) > kBasisTolerance)
        throw std::invalid_argument(std::string("splat view ") + names + " are not orthogonal");
}

bool finite(const SplatEllipse& e) {
    return finite(e.centre) && finite(e.axisRadial) && finite(e.axisTangential) &&
           finite(e.projectedCentre) && std::isfinite(e.halfAngleRad);
}

/// The sphere centre in view coordinates (right, up, forward) relative to the eye.
glm::dvec3 viewCoordinates(const SplatView& view, const glm::dvec3& centre) {
    const glm::dvec3 rel = centre - view.eye;
    return {glm::dot(rel, view.right), glm::dot(rel, view.up), glm::dot(rel, view.forward)};
}

SplatProjection projectOrthographic(const SplatView& view, const glm::dvec3& c, double radius) {
    if (c.z <= radius) return {SplatStatus::CrossesEyePlane, {}};
    SplatEllipse e;
    e.centre = e.projectedCentre = view.orthoScale * glm::dvec2(c.x, c.y);
    e.axisRadial = {view.orthoScale * radius, 0.0};
    e.axisTangential = {0.0, view.orthoScale * radius};
    return {SplatStatus::Ok, e};
}

// Appendix A in closed form. With q the unit eye-to-centre direction in view coordinates,
// s = sin(alpha) and g = q.z^2 - s^2 = cos(theta + alpha) cos(theta - alpha), the cone of
// tangent rays meets the plane z = f in
//   (x - m)^2 / a^2 + y^2 / b^2 = 1   (x along the radial direction e1 = (q.x, q.y) / rho)
// with m = f rho q.z / g, a = f s cos(alpha) / g, b = f s / sqrt(g): the two tangent rays in
// the plane of the view axis and q land at f tan(theta -+ alpha), and m is their midpoint.
SplatProjection projectPerspective(const SplatView& view, const glm::dvec3& c, double radius) {
    // Scale by the largest coordinate so that squares neither overflow nor underflow.
    const double big = std::max({std::abs(c.x), std::abs(c.y), std::abs(c.z)});
    if (big == 0.0) return {SplatStatus::EyeInsideSphere, {}};
    const glm::dvec3 cs = c / big;
    const double rs = radius / big, dist = glm::length(cs);
    if (dist <= rs) return {SplatStatus::EyeInsideSphere, {}};
    if (cs.z <= rs) return {SplatStatus::CrossesEyePlane, {}};
    const glm::dvec3 q = cs / dist;
    const double s = rs / dist, cosA = std::sqrt((1.0 - s) * (1.0 + s));
    const double g = (q.z - s) * (q.z + s);
    if (!(g > 0.0)) return {SplatStatus::CrossesEyePlane, {}};
    const double rho = std::hypot(q.x, q.y), f = view.focalLength;
    const glm::dvec2 e1 = rho > 0.0 ? glm::dvec2(q.x, q.y) / rho : glm::dvec2(1.0, 0.0);
    SplatEllipse e;
    e.centre = (f * rho * q.z / g) * e1;
    e.axisRadial = (f * s * cosA / g) * e1;
    e.axisTangential = (f * s / std::sqrt(g)) * glm::dvec2(-e1.y, e1.x);
    e.projectedCentre = (f / q.z) * glm::dvec2(q.x, q.y);
    e.halfAngleRad = std::atan2(s, cosA);
    if (!finite(e)) return {SplatStatus::CrossesEyePlane, {}}; // too close to the eye plane
    return {SplatStatus::Ok, e};
}

} // namespace

SplatView SplatView::from(const ViewBasis& basis, std::uint32_t width, std::uint32_t height) {
    SplatView v;
    v.eye = basis.eye;
    v.forward = glm::normalize(basis.forward);
    v.right = glm::normalize(basis.right);
    v.up = glm::normalize(basis.upScaled);
    v.orthographic = basis.orthographic;
    // Half the image height in pixels over half the view height (tangent or world units).
    const double pixelsPerUnit = 0.5 * double(height) / glm::length(basis.upScaled);
    v.focalLength = pixelsPerUnit;
    v.orthoScale = pixelsPerUnit;
    return v;
}

glm::dvec2 SplatView::pixelCentre(double pixelX, double pixelY, std::uint32_t width,
                                  std::uint32_t height) {
    return {pixelX + 0.5 - 0.5 * double(width), 0.5 * double(height) - pixelY - 0.5};
}

Ray SplatView::ray(const glm::dvec2& imagePoint) const {
    if (orthographic) {
        const glm::dvec2 p = imagePoint / orthoScale;
        return {eye + p.x * right + p.y * up, forward};
    }
    const glm::dvec2 p = imagePoint / focalLength;
    return {eye, glm::normalize(forward + p.x * right + p.y * up)};
}

void SplatView::validate() const {
    if (!finite(eye)) throw std::invalid_argument("splat view eye is not finite");
    requireUnit(forward, "forward");
    requireUnit(right, "right");
    requireUnit(up, "up");
    requireOrthogonal(forward, right, "forward and right");
    requireOrthogonal(forward, up, "forward and up");
    requireOrthogonal(right, up, "right and up");
    const double scale = orthographic ? orthoScale : focalLength;
    if (!(scale > 0.0 && std::isfinite(scale)))
        throw std::invalid_argument(orthographic ? "splat view orthoScale must be positive"
                                                 : "splat view focalLength must be positive");
}

const char* toString(SplatStatus status) {
    switch (status) {
    case SplatStatus::Ok:
        return "ok";
    case SplatStatus::InvalidInput:
        return "invalid input";
    case SplatStatus::ZeroRadius:
        return "zero radius";
    case SplatStatus::EyeInsideSphere:
        return "eye inside sphere";
    case SplatStatus::CrossesEyePlane:
        return "sphere crosses the eye plane";
    }
    return "unknown";
}

glm::dvec2 SplatEllipse::halfExtent() const {
    return {std::hypot(axisRadial.x, axisTangential.x), std::hypot(axisRadial.y, axisTangential.y)};
}

SplatProjection projectSphere(const SplatView& view, const glm::dvec3& centre, double radius) {
    const double scale = view.orthographic ? view.orthoScale : view.focalLength;
    if (!(std::isfinite(radius) && radius >= 0.0 && std::isfinite(scale) && scale > 0.0))
        return {SplatStatus::InvalidInput, {}};
    const glm::dvec3 c = viewCoordinates(view, centre);
    if (!finite(c)) return {SplatStatus::InvalidInput, {}};
    if (radius == 0.0) return {SplatStatus::ZeroRadius, {}};
    return view.orthographic ? projectOrthographic(view, c, radius)
                             : projectPerspective(view, c, radius);
}

double affineIndex(const SplatEllipse& ellipse, const glm::dvec2& imagePoint) {
    const glm::dvec2 p = imagePoint - ellipse.centre;
    const double u =
        glm::dot(p, ellipse.axisRadial) / glm::dot(ellipse.axisRadial, ellipse.axisRadial);
    const double v = glm::dot(p, ellipse.axisTangential) /
                     glm::dot(ellipse.axisTangential, ellipse.axisTangential);
    return std::hypot(u, v);
}

double coneIndex(const SplatView& view, const glm::dvec3& centre, double radius,
                 const glm::dvec2& imagePoint) {
    if (view.orthographic) return rayCentreDistance(view, centre, radius, imagePoint);
    const glm::dvec3 rel = centre - view.eye, w = view.ray(imagePoint).direction;
    const double along = glm::dot(w, rel);
    if (!(along > 0.0)) return std::numeric_limits<double>::infinity();
    const double dist = glm::length(rel);
    const double tanBeta = glm::length(glm::cross(w, rel)) / along;
    const double tanAlpha = radius / std::sqrt((dist - radius) * (dist + radius));
    return tanBeta / tanAlpha;
}

double correctedDistance(double index, double halfAngleRad) {
    // sin(atan(x)) = x / sqrt(1 + x^2) with x = i tan(a), divided by sin(a).
    const double s = std::sin(halfAngleRad), c = std::cos(halfAngleRad);
    if (std::isinf(index)) return s > 0.0 ? 1.0 / s : index;
    return index / std::sqrt(c * c + index * index * s * s);
}

double rayCentreDistance(const SplatView& view, const glm::dvec3& centre, double radius,
                         const glm::dvec2& imagePoint) {
    const Ray ray = view.ray(imagePoint);
    return glm::length(glm::cross(centre - ray.origin, ray.direction)) / radius;
}

TangentDisk tangentDisk(const SplatView& view, const glm::dvec3& centre, double radius) {
    if (view.orthographic) return {centre, view.forward, radius};
    const glm::dvec3 rel = centre - view.eye;
    const double dist = glm::length(rel), s = radius / dist;
    const glm::dvec3 q = rel / dist;
    return {centre - (radius * s) * q, q, radius * std::sqrt((1.0 - s) * (1.0 + s))};
}

} // namespace bc::render
