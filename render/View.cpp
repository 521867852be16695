#include "render/View.h"

#include <algorithm>
#include <cmath>
#include <stdexcept>

#include <glm/geometric.hpp>

namespace bc::render {

namespace {

void checkSize(std::uint32_t width, std::uint32_t height) {
    if (width == 0 || height == 0)
        throw std::invalid_argument("view size " + std::to_string(width) + "x" +
                                    std::to_string(height) + " is empty");
}

/// `v` rotated by `angle` radians about unit `axis` (Rodrigues).
glm::dvec3 rotated(const glm::dvec3& v, const glm::dvec3& axis, double angle) {
    return v * std::cos(angle) + glm::cross(axis, v) * std::sin(angle) +
           axis * glm::dot(axis, v) * (1.0 - std::cos(angle));
}

} // namespace

View View::of(const Camera& camera, std::uint32_t width, std::uint32_t height) {
    camera.validate();
    return ofDecoded(camera, width, height);
}

View View::ofDecoded(const Camera& camera, std::uint32_t width, std::uint32_t height) {
    checkSize(width, height);
    return View{camera, ViewBasis::fromValid(camera, width, height), width, height};
}

Camera predictNext(const Camera& a, const Camera& b) {
    Camera next = b;
    const glm::dvec3 r0 = a.eye - a.target, r1 = b.eye - b.target;
    const double l0 = glm::length(r0), l1 = glm::length(r1);
    const glm::dvec3 axis = glm::cross(r0, r1);
    const bool sameTarget = glm::length(b.target - a.target) <= 1e-9 * std::max(l1, 1.0);
    if (sameTarget && l0 > 0 && l1 > 0 && glm::length(axis) > 1e-12 * l0 * l1) {
        const double angle = std::atan2(glm::length(axis), glm::dot(r0, r1));
        const glm::dvec3 u = glm::normalize(axis);
        next.eye = b.target + rotated(r1, u, angle) * (l1 / l0);
        next.up = rotated(b.up, u, angle);
    } else {
        next.eye = b.eye + (b.eye - a.eye);
        next.target = b.target + (b.target - a.target);
    }
    return next;
}

} // namespace bc::render
