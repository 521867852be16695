#pragma once
// The screen ellipse of a sphere seen in perspective and the footprint index inside it, for
// hybrid forward splatting (Yuan et al. 2003, section 4.2 and appendix A). Plain
// double-precision geometry without GL: the CPU path, the tests and the shader constants
// share these definitions.
//
// Image-plane coordinates: x along SplatView::right, y along SplatView::up, origin on the view
// axis, measured on the plane focalLength in front of the eye. SplatView::from() makes them
// pixels from the image centre.
#include "render/Camera.h"

#include <cstdint>

#include <glm/vec2.hpp>
#include <glm/vec3.hpp>

namespace bc::render {

/// A view with an orthonormal basis, as splats need it (perspective or orthographic).
struct SplatView {
    glm::dvec3 eye{0.0};
    glm::dvec3 forward{0.0, 0.0, -1.0}; ///< unit
    glm::dvec3 right{1.0, 0.0, 0.0};    ///< unit, orthogonal to forward
    glm::dvec3 up{0.0, 1.0, 0.0};       ///< unit, orthogonal to forward and right
    bool orthographic = false;
    double focalLength = 1.0; ///< perspective: image units per unit of tan(angle off the axis)
    double orthoScale = 1.0;  ///< orthographic: image units per world unit

    /// The view of `basis` for a W x H image, in pixel units (square pixels).
    static SplatView from(const ViewBasis& basis, std::uint32_t width, std::uint32_t height);
    /// Image point of the centre of pixel (x, y), row 0 at the top, in a view made by from().
    static glm::dvec2 pixelCentre(double pixelX, double pixelY, std::uint32_t width,
                                  std::uint32_t height);
    /// The eye ray through an image point; for a view made by from() the same as ViewBasis::ray.
    Ray ray(const glm::dvec2& imagePoint) const;
    /// Throws std::invalid_argument naming the field when a vector is not finite or not unit,
    /// the basis is not orthogonal (to 1e-9), or the scale of the projection is not positive.
    void validate() const;
};

/// Why a sphere has no elliptical splat (Ok when it has one).
enum class SplatStatus {
    Ok,
    InvalidInput,    ///< NaN or infinite centre, radius or view; a negative radius or scale
    ZeroRadius,      ///< radius 0: nothing to splat (a point, if anything)
    EyeInsideSphere, ///< the eye lies inside the sphere or on its surface
    /// Part of the sphere is on or behind the plane through the eye normal to forward: the
    /// silhouette is a parabola or hyperbola (or too large to represent), not an ellipse.
    CrossesEyePlane,
};
const char* toString(SplatStatus status);

/// The silhouette of a sphere on the image plane, in image units.
struct SplatEllipse {
    /// The midpoint of the projected diameter along axisRadial; not projectedCentre.
    glm::dvec2 centre{0.0};
    /// Semi-axis in the plane of the view axis and the eye ray through the sphere centre
    /// (the paper's R1), pointing away from the view axis; +x when the centre is on the axis.
    glm::dvec2 axisRadial{0.0};
    glm::dvec2 axisTangential{0.0};  ///< the other semi-axis (R2): axisRadial turned by +90 deg
    glm::dvec2 projectedCentre{0.0}; ///< where the sphere centre projects
    double halfAngleRad = 0.0;       ///< alpha of the tangent cone, sin = r / |C - E|; 0 ortho

    glm::dvec2 halfExtent() const; ///< half the size of the axis-aligned bounding box
};

struct SplatProjection {
    SplatStatus status = SplatStatus::InvalidInput;
    SplatEllipse ellipse; ///< meaningful only when ok()
    bool ok() const { return status == SplatStatus::Ok; }
};

/// The exact silhouette of a sphere (world centre and radius): an ellipse in perspective, a
/// circle of radius r * orthoScale orthographically. Never NaN: degenerate cases get a status.
SplatProjection projectSphere(const SplatView& view, const glm::dvec3& centre, double radius);

/// The paper's affine index of an image point: 0 at ellipse.centre, 1 on the boundary.
/// Exact only on the view axis and orthographically; elsewhere see coneIndex.
double affineIndex(const SplatEllipse& ellipse, const glm::dvec2& imagePoint);

/// The exact index: tan(beta) / tan(alpha), beta the angle between the point's eye ray and
/// the ray to the sphere centre; 1 on the boundary, +inf for rays facing away. It is the
/// affine index on the tangent disk, so a quad on tangentDisk() with perspective-correct
/// interpolation delivers it. Precondition: projectSphere(view, centre, radius).ok().
double coneIndex(const SplatView& view, const glm::dvec3& centre, double radius,
                 const glm::dvec2& imagePoint);

/// Distance from the sphere centre to the ray of index i, in radii: sin(atan(i tan a)) / sin a
/// (the paper divides by tan a, which normalises by r / cos a and gives cos a at the rim).
double correctedDistance(double index, double halfAngleRad);

/// Reference for the index: distance from the centre to the point's eye ray (as a line),
/// divided by the radius. Precondition: radius > 0.
double rayCentreDistance(const SplatView& view, const glm::dvec3& centre, double radius,
                         const glm::dvec2& imagePoint);

/// The circle along which the eye rays touch the sphere (the paper's Figure 3): its
/// projection is exactly the splat ellipse.
struct TangentDisk {
    glm::dvec3 centre{0.0};
    glm::dvec3 normal{0.0, 0.0, 1.0}; ///< unit, from the eye towards the sphere centre
    double radius = 0.0;              ///< r cos(alpha)
};

/// The tangent disk of a sphere for `view`. Precondition: projectSphere(...).ok().
TangentDisk tangentDisk(const SplatView& view, const glm::dvec3& centre, double radius);

} // namespace bc::render
