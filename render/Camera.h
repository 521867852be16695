#pragma once
// Cameras in world space (millimetres; the volume box spans [0, dims * spacing]) and the
// one ray-generation rule every renderer uses, so the GPU raycaster, the CPU reference and
// the splatter put their samples in the same places.
#include <array>
#include <cstdint>
#include <string>

#include <glm/vec3.hpp>

namespace bc::render {

/// An axis-aligned box in world space.
struct Box {
    glm::dvec3 min{0.0};
    glm::dvec3 max{0.0};
    glm::dvec3 centre() const { return 0.5 * (min + max); }
    glm::dvec3 size() const { return max - min; }
    double radius() const; ///< radius of the bounding sphere
};

/// A ray in world space: origin + t * direction, direction unit length.
struct Ray {
    glm::dvec3 origin{0.0};
    glm::dvec3 direction{0.0, 0.0, 1.0};
};

struct Camera {
    glm::dvec3 eye{0.0, 0.0, 1.0};
    glm::dvec3 target{0.0};
    glm::dvec3 up{0.0, 1.0, 0.0};
    double fovYDeg = 30.0; ///< vertical field of view (perspective)
    bool orthographic = false;
    double orthoHeight = 1.0; ///< world height of the view (orthographic)

    /// A camera circling `box`: azimuth about +z from +x, elevation from the xy plane,
    /// distance in units of the distance at which the bounding sphere just fills the view.
    static Camera orbit(const Box& box, double azimuthDeg, double elevationDeg,
                        double distanceFactor = 1.0, double fovYDeg = 30.0);
    /// Throws std::invalid_argument naming the field when a vector is not finite, eye ==
    /// target, up is parallel to the view direction, or the fov is outside (0, 180).
    void validate() const;
};

/// The view basis derived from a camera for a W x H image: the ray through pixel (x, y)
/// (row 0 at the top, pixel centres at +0.5) is
///   perspective:  origin = eye,                      dir = normalize(forward + sx*right +
///   sy*upScaled) orthographic: origin = eye + sx*right + sy*upScaled, dir = forward
/// with sx = (2(x+0.5)/W - 1), sy = (1 - 2(y+0.5)/H).
struct ViewBasis {
    glm::dvec3 eye{0.0};
    glm::dvec3 forward{0.0};
    glm::dvec3 right{
        0.0}; ///< scaled: half the view width at unit distance (or in world units, ortho)
    glm::dvec3 upScaled{0.0}; ///< scaled likewise for the height
    bool orthographic = false;

    /// @throw std::invalid_argument when the camera is not valid (Camera::validate).
    static ViewBasis from(const Camera& camera, std::uint32_t width, std::uint32_t height);
    /// The same for a camera already validated (View::of, the protocol's decoder).
    static ViewBasis fromValid(const Camera& camera, std::uint32_t width, std::uint32_t height);
    Ray ray(double pixelX, double pixelY, std::uint32_t width, std::uint32_t height) const;
};

/// Parametric interval [tNear, tFar] where `ray` is inside `box`; empty when tNear > tFar.
/// Rays parallel to a face use +-infinity slabs, so rays exactly along a face are inside.
std::array<double, 2> intersectBox(const Ray& ray, const Box& box);

} // namespace bc::render
