// The geometric and numeric core of hybrid forward splatting: the exact screen
// ellipse of a sphere against its numerically traced silhouette, the corrected footprint
// index against the exact ray-to-centre distance, and the footprint table against direct
// evaluation. Worst errors are printed so the figures quoted in the headers can be checked.
#include "render/SplatGeometry.h"
#include "render/SplatFootprint.h"

#include <gtest/gtest.h>

#include <algorithm>
#include <cmath>
#include <cstdio>
#include <functional>
#include <limits>
#include <random>
#include <vector>

#include <glm/geometric.hpp>

namespace bc::render {
namespace {

constexpr double kPi = 3.14159265358979323846;
constexpr double kDeg = kPi / 180.0;

/// A sphere placed by its angles: off-axis angle theta, azimuth phi about the view axis,
/// cone half-angle alpha, distance from the eye.
struct SplatCase {
    SplatView view;
    glm::dvec3 centre{0.0};
    double radius = 0.0;
    double thetaRad = 0.0;
};

glm::dvec3 randomUnit(std::mt19937_64& rng) {
    std::normal_distribution<double> n;
    for (;;) {
        const glm::dvec3 v{n(rng), n(rng), n(rng)};
        if (glm::length(v) > 1e-3) return glm::normalize(v);
    }
}

/// Two unit vectors completing `q` to an orthonormal basis.
std::pair<glm::dvec3, glm::dvec3> perpendiculars(const glm::dvec3& q) {
    const glm::dvec3 helper = std::abs(q.x) < 0.6 ? glm::dvec3(1, 0, 0) : glm::dvec3(0, 1, 0);
    const glm::dvec3 u = glm::normalize(glm::cross(q, helper));
    return {u, glm::cross(q, u)};
}

SplatView randomView(std::mt19937_64& rng) {
    std::uniform_real_distribution<double> eye(-50.0, 50.0),
        logFocal(std::log(0.5), std::log(2000.0));
    SplatView v;
    v.eye = {eye(rng), eye(rng), eye(rng)};
    v.forward = randomUnit(rng);
    v.right = perpendiculars(v.forward).first;
    v.up = glm::cross(v.right, v.forward);
    v.focalLength = std::exp(logFocal(rng));
    return v;
}

SplatCase makeCase(std::mt19937_64& rng, double thetaRad, double alphaRad) {
    std::uniform_real_distribution<double> unit(0.0, 1.0);
    SplatCase c;
    c.view = randomView(rng);
    const double phi = 2.0 * kPi * unit(rng),
                 dist = std::exp(std::log(1e-2) + unit(rng) * std::log(1e6));
    const glm::dvec3 q =
        std::cos(thetaRad) * c.view.forward +
        std::sin(thetaRad) * (std::cos(phi) * c.view.right + std::sin(phi) * c.view.up);
    c.centre = c.view.eye + dist * q;
    c.radius = dist * std::sin(alphaRad);
    c.thetaRad = thetaRad;
    return c;
}

/// Hundreds of spheres of each kind that matters: general, near the view axis (exactly on
/// it included), wide cones (alpha around and beyond 15 deg) and far off the axis.
std::vector<SplatCase> splatCases(std::size_t perKind) {
    std::mt19937_64 rng(20030601);
    std::uniform_real_distribution<double> unit(0.0, 1.0);
    std::vector<SplatCase> cases;
    const auto logUniform = [&](double lo, double hi) {
        return std::exp(std::log(lo) + unit(rng) * (std::log(hi) - std::log(lo)));
    };
    for (std::size_t k = 0; k < perKind; ++k) {
        const double a1 = logUniform(1e-4, 15.0) * kDeg;
        cases.push_back(makeCase(rng, unit(rng) * 60.0 * kDeg, a1));
        const double a2 = logUniform(1e-4, 15.0) * kDeg;
        cases.push_back(makeCase(rng, k % 4 == 0 ? 0.0 : logUniform(1e-12, 1e-6), a2));
        const double a3 = (12.0 + unit(rng) * 33.0) * kDeg;
        cases.push_back(makeCase(rng, unit(rng) * (85.0 * kDeg - a3), a3));
        const double a4 = logUniform(1e-3, 10.0) * kDeg;
        cases.push_back(makeCase(rng, 60.0 * kDeg + unit(rng) * (25.0 * kDeg - a4), a4));
    }
    return cases;
}

/// Where the tangent ray at angle phi around the cone axis meets the image plane.
glm::dvec2 silhouettePoint(const SplatCase& c, double phi) {
    const glm::dvec3 rel = c.centre - c.view.eye;
    const glm::dvec3 q = glm::normalize(rel);
    const auto [u, v] = perpendiculars(q);
    const double s = c.radius / glm::length(rel), co = std::sqrt(1.0 - s * s);
    const glm::dvec3 w = co * q + s * (std::cos(phi) * u + std::sin(phi) * v);
    const double z = glm::dot(w, c.view.forward);
    return c.view.focalLength * glm::dvec2(glm::dot(w, c.view.right), glm::dot(w, c.view.up)) / z;
}

/// max over phi of f(phi): dense samples, then golden-section search around the best one.
double maximise(const std::function<double(double)>& f) {
    constexpr int kSamples = 2048;
    int best = 0;
    for (int k = 1; k < kSamples; ++k)
        if (f(2.0 * kPi * k / kSamples) > f(2.0 * kPi * best / kSamples)) best = k;
    double lo = 2.0 * kPi * (best - 1) / kSamples, hi = 2.0 * kPi * (best + 1) / kSamples;
    const double g = 0.5 * (std::sqrt(5.0) - 1.0);
    for (int it = 0; it < 80; ++it) {
        const double a = hi - g * (hi - lo), b = lo + g * (hi - lo);
        (f(a) < f(b) ? lo : hi) = (f(a) < f(b) ? a : b);
    }
    return f(0.5 * (lo + hi));
}

double ellipseResidual(const SplatEllipse& e, const glm::dvec2& p) {
    const glm::dvec2 d = p - e.centre;
    const double u = glm::dot(d, e.axisRadial) / glm::dot(e.axisRadial, e.axisRadial);
    const double v = glm::dot(d, e.axisTangential) / glm::dot(e.axisTangential, e.axisTangential);
    return std::abs(u * u + v * v - 1.0);
}

/// A uniformly random point inside the ellipse.
glm::dvec2 pointInside(const SplatEllipse& e, std::mt19937_64& rng) {
    std::uniform_real_distribution<double> unit(0.0, 1.0);
    const double rad = std::sqrt(unit(rng)) * (1.0 - 1e-9), t = 2.0 * kPi * unit(rng);
    return e.centre + rad * (std::cos(t) * e.axisRadial + std::sin(t) * e.axisTangential);
}

TEST(SplatGeometryTest, EllipseMatchesTheTracedSilhouetteOverManyViews) {
    const std::vector<SplatCase> cases = splatCases(100);
    double worstResidual = 0.0, worstExtreme = 0.0, worstPlane = 0.0, worstTangency = 0.0;
    for (const SplatCase& c : cases) {
        const SplatProjection proj = projectSphere(c.view, c.centre, c.radius);
        ASSERT_TRUE(proj.ok()) << toString(proj.status) << " theta " << c.thetaRad;
        const SplatEllipse& e = proj.ellipse;
        const double major = std::max(glm::length(e.axisRadial), glm::length(e.axisTangential));
        for (int k = 0; k < 256; ++k) {
            const glm::dvec2 p = silhouettePoint(c, 2.0 * kPi * (k + 0.37) / 256);
            worstResidual = std::max(worstResidual, ellipseResidual(e, p));
            worstTangency = std::max(
                {worstTangency, std::abs(rayCentreDistance(c.view, c.centre, c.radius, p) - 1.0),
                 std::abs(coneIndex(c.view, c.centre, c.radius, p) - 1.0)});
        }
        // Extreme silhouette points along each axis lie at +-the semi-axis from the centre.
        for (const glm::dvec2& axis : {e.axisRadial, e.axisTangential})
            for (const double sign : {1.0, -1.0}) {
                const glm::dvec2 dir = sign * glm::normalize(axis);
                const double reach = maximise(
                    [&](double phi) { return glm::dot(silhouettePoint(c, phi) - e.centre, dir); });
                worstExtreme = std::max(worstExtreme, std::abs(reach - glm::length(axis)) / major);
            }
        // The radial axis lies in the plane of the view axis and the eye ray through C.
        const double off = glm::length(e.projectedCentre);
        if (off > 1e-6 * major) {
            const glm::dvec2 a = glm::normalize(e.axisRadial), p = e.projectedCentre / off;
            worstPlane = std::max(worstPlane, std::abs(a.x * p.y - a.y * p.x));
            EXPECT_GT(glm::dot(a, p), 0.0);
        }
    }
    std::printf("[splat] %zu spheres: worst ellipse-equation residual %.2e, worst extreme-point "
                "error %.2e (of the major semi-axis), radial axis off the PQ plane %.2e, tangent "
                "rays' distance (radii) and cone index off 1 by %.2e\n",
                cases.size(), worstResidual, worstExtreme, worstPlane, worstTangency);
    EXPECT_LT(worstResidual, 1e-4);
    EXPECT_LT(worstExtreme, 1e-4);
    EXPECT_LT(worstPlane, 1e-9);
    EXPECT_LT(worstTangency, 1e-6);
}

TEST(SplatGeometryTest, CentreIsTheMidpointOfTheProjectedDiameterNotTheProjectedCentre) {
    SplatView view; // eye at the origin looking down -z, focal length 1
    const double theta = 40.0 * kDeg, alpha = 10.0 * kDeg, dist = 5.0;
    const glm::dvec3 centre = dist * glm::dvec3(std::sin(theta), 0.0, -std::cos(theta));
    const SplatProjection proj = projectSphere(view, centre, dist * std::sin(alpha));
    ASSERT_TRUE(proj.ok());
    const SplatEllipse& e = proj.ellipse;
    // The two tangent rays in the xz plane land at tan(theta -+ alpha).
    const double lo = std::tan(theta - alpha), hi = std::tan(theta + alpha);
    EXPECT_NEAR(e.centre.x, 0.5 * (lo + hi), 1e-14);
    EXPECT_NEAR(e.axisRadial.x, 0.5 * (hi - lo), 1e-14);
    EXPECT_NEAR(e.projectedCentre.x, std::tan(theta), 1e-14);
    EXPECT_GT(e.centre.x - e.projectedCentre.x, 0.01); // far from equal at 40 deg off axis
    EXPECT_NEAR(e.halfAngleRad, alpha, 1e-14);
}

TEST(SplatGeometryTest, SphereOnTheViewAxisProjectsToACircle) {
    SplatView view;
    view.focalLength = 300.0;
    const SplatProjection proj = projectSphere(view, {0.0, 0.0, -10.0}, 2.0);
    ASSERT_TRUE(proj.ok());
    const SplatEllipse& e = proj.ellipse;
    const double radius = 300.0 * std::tan(std::asin(0.2));
    EXPECT_EQ(e.centre, glm::dvec2(0.0));
    EXPECT_NEAR(e.axisRadial.x, radius, 1e-12);
    EXPECT_EQ(e.axisRadial.y, 0.0);
    EXPECT_NEAR(e.axisTangential.y, radius, 1e-12);
    EXPECT_NEAR(e.halfExtent().x, radius, 1e-12);
}

TEST(SplatGeometryTest, OrthographicSplatIsACircleOfTheRadiusAtTheProjectedCentre) {
    SplatView view;
    view.orthographic = true;
    view.orthoScale = 4.0;
    const glm::dvec3 centre{1.5, -2.0, -30.0};
    const SplatProjection proj = projectSphere(view, centre, 0.75);
    ASSERT_TRUE(proj.ok());
    EXPECT_EQ(proj.ellipse.centre, glm::dvec2(6.0, -8.0));
    EXPECT_EQ(proj.ellipse.projectedCentre, proj.ellipse.centre);
    EXPECT_EQ(glm::length(proj.ellipse.axisRadial), 3.0);
    EXPECT_EQ(glm::length(proj.ellipse.axisTangential), 3.0);
    EXPECT_EQ(proj.ellipse.halfAngleRad, 0.0);
    std::mt19937_64 rng(7);
    for (int k = 0; k < 200; ++k) {
        const glm::dvec2 p = pointInside(proj.ellipse, rng);
        const double exact = rayCentreDistance(view, centre, 0.75, p);
        EXPECT_NEAR(correctedDistance(affineIndex(proj.ellipse, p), 0.0), exact, 1e-12);
        EXPECT_NEAR(coneIndex(view, centre, 0.75, p), exact, 1e-12);
    }
}

TEST(SplatGeometryTest, CorrectedConeIndexMatchesTheExactRayToCentreDistance) {
    const std::vector<SplatCase> cases = splatCases(100);
    std::mt19937_64 rng(42);
    double worst = 0.0, worstDisk = 0.0;
    std::size_t points = 0;
    for (const SplatCase& c : cases) {
        const SplatProjection proj = projectSphere(c.view, c.centre, c.radius);
        ASSERT_TRUE(proj.ok());
        const TangentDisk disk = tangentDisk(c.view, c.centre, c.radius);
        for (int k = 0; k < 50; ++k, ++points) {
            const glm::dvec2 p = pointInside(proj.ellipse, rng);
            const double i = coneIndex(c.view, c.centre, c.radius, p);
            const double exact = rayCentreDistance(c.view, c.centre, c.radius, p);
            ASSERT_LT(exact, 1.0 + 1e-9); // inside the ellipse means the ray meets the sphere
            worst =
                std::max(worst, std::abs(correctedDistance(i, proj.ellipse.halfAngleRad) - exact));
            // The index is the affine one on the tangent disk, hit by the same ray.
            const Ray ray = c.view.ray(p);
            const double t = glm::dot(disk.centre - ray.origin, disk.normal) /
                             glm::dot(ray.direction, disk.normal);
            const glm::dvec3 hit = ray.origin + t * ray.direction;
            worstDisk =
                std::max(worstDisk, std::abs(glm::length(hit - disk.centre) / disk.radius - i));
        }
    }
    std::printf("[splat] %zu points in %zu ellipses: worst |d(cone index) - exact| %.2e radii, "
                "worst |tangent-disk index - cone index| %.2e\n",
                points, cases.size(), worst, worstDisk);
    EXPECT_LT(worst, 1e-9);
    EXPECT_LT(worstDisk, 1e-6);
}

// The paper's affine index (measured from the ellipse centre) is exact only on the view axis:
// the ray through the ellipse centre misses the sphere centre by about tan(alpha) tan(theta)
// radii, and that is the worst error (measured: 1.00 to 1.04 times it for alpha <= 15 deg,
// up to 1.3 times for wider cones). Hence coneIndex for anything off the axis.
TEST(SplatGeometryTest, AffineIndexIsExactOnTheAxisAndOffByTanAlphaTanThetaElsewhere) {
    const std::vector<SplatCase> cases = splatCases(100);
    std::mt19937_64 rng(43);
    double worstOnAxis = 0.0, worstNarrow = 0.0, worstWide = 0.0, worstSmall = 0.0;
    for (const SplatCase& c : cases) {
        const SplatProjection proj = projectSphere(c.view, c.centre, c.radius);
        ASSERT_TRUE(proj.ok());
        const double alpha = proj.ellipse.halfAngleRad;
        const double scale = std::tan(alpha) * std::tan(c.thetaRad);
        for (int k = 0; k < 50; ++k) {
            const glm::dvec2 p = pointInside(proj.ellipse, rng);
            const double err = std::abs(correctedDistance(affineIndex(proj.ellipse, p), alpha) -
                                        rayCentreDistance(c.view, c.centre, c.radius, p));
            if (c.thetaRad == 0.0)
                worstOnAxis = std::max(worstOnAxis, err);
            else if (alpha <= 15.0 * kDeg)
                worstNarrow = std::max(worstNarrow, (err - 1e-9) / scale);
            else
                worstWide = std::max(worstWide, (err - 1e-9) / scale);
            if (alpha < 0.01 && c.thetaRad < 30 * kDeg) worstSmall = std::max(worstSmall, err);
        }
    }
    std::printf("[splat] affine index: worst error %.2e radii on the axis; off it, worst error / "
                "(tan alpha tan theta) %.3f for alpha <= 15 deg, %.3f beyond; worst error for "
                "alpha < 0.01 rad and theta < 30 deg %.2e radii\n",
                worstOnAxis, worstNarrow, worstWide, worstSmall);
    EXPECT_LT(worstOnAxis, 1e-9);
    EXPECT_LT(worstNarrow, 1.05);
    EXPECT_LT(worstWide, 1.5);
}

TEST(SplatGeometryTest, CorrectedDistanceIsZeroAtTheCentreAndOneOnTheRim) {
    for (const double alphaDeg : {0.0, 1e-6, 5.0, 15.0, 45.0, 80.0}) {
        const double a = alphaDeg * kDeg;
        EXPECT_EQ(correctedDistance(0.0, a), 0.0);
        EXPECT_NEAR(correctedDistance(1.0, a), 1.0, 1e-15);
        // The paper's formula, sin(atan(i tan a)) / tan a, for comparison: cos(a) at the rim.
        if (a > 0.0) {
            EXPECT_NEAR(correctedDistance(0.5, a) * std::sin(a),
                        std::sin(std::atan(0.5 * std::tan(a))), 1e-15);
        }
        EXPECT_GE(correctedDistance(0.5, a), 0.5); // d > i: the sphere bulges towards the eye
    }
}

TEST(SplatGeometryTest, PixelUnitViewReproducesTheCameraRays) {
    for (const bool ortho : {false, true}) {
        Camera camera = Camera::orbit({{0, 0, 0}, {100, 80, 60}}, 35, 20, 1.3, 40.0);
        camera.orthographic = ortho;
        const ViewBasis basis = ViewBasis::from(camera, 160, 90);
        const SplatView view = SplatView::from(basis, 160, 90);
        EXPECT_NO_THROW(view.validate());
        for (const auto& [px, py] :
             {std::pair{0.0, 0.0}, {159.0, 89.0}, {80.0, 3.0}, {17.0, 60.0}}) {
            const Ray want = basis.ray(px, py, 160, 90);
            const Ray got = view.ray(SplatView::pixelCentre(px, py, 160, 90));
            EXPECT_LT(glm::length(got.direction - want.direction), 1e-12);
            EXPECT_LT(glm::length(got.origin - want.origin), 1e-9);
        }
    }
}

TEST(SplatGeometryTest, HalfExtentBoundsTheSilhouetteTightly) {
    for (const SplatCase& c : splatCases(10)) {
        const SplatProjection proj = projectSphere(c.view, c.centre, c.radius);
        ASSERT_TRUE(proj.ok());
        const glm::dvec2 half = proj.ellipse.halfExtent();
        for (const int axis : {0, 1}) {
            const double reach = maximise([&](double phi) {
                return std::abs(silhouettePoint(c, phi)[axis] - proj.ellipse.centre[axis]);
            });
            EXPECT_NEAR(reach, half[axis], 1e-9 * std::max(half.x, half.y));
        }
    }
}

void expectStatus(const SplatView& view, const glm::dvec3& centre, double radius,
                  SplatStatus want) {
    const SplatProjection proj = projectSphere(view, centre, radius);
    EXPECT_EQ(proj.status, want) << toString(proj.status) << " for centre (" << centre.x << ", "
                                 << centre.y << ", " << centre.z << ") radius " << radius;
}

TEST(SplatGeometryTest, DegenerateSpheresGetAStatusNotNaN) {
    SplatView view; // eye at the origin looking down -z
    const double nan = std::numeric_limits<double>::quiet_NaN();
    const double inf = std::numeric_limits<double>::infinity();
    expectStatus(view, {0, 0, 0}, 1.0, SplatStatus::EyeInsideSphere); // eye at the centre
    expectStatus(view, {0.3, 0, -0.5}, 1.0, SplatStatus::EyeInsideSphere);
    expectStatus(view, {0, 0, -2}, 2.0, SplatStatus::EyeInsideSphere);   // eye on the surface
    expectStatus(view, {0, 0, 5}, 1.0, SplatStatus::CrossesEyePlane);    // behind the eye
    expectStatus(view, {3, 0, -0.5}, 1.0, SplatStatus::CrossesEyePlane); // straddles the plane
    expectStatus(view, {3, 0, -1}, 1.0, SplatStatus::CrossesEyePlane);   // touches it
    expectStatus(view, {0, 0, -5}, 0.0, SplatStatus::ZeroRadius);
    expectStatus(view, {0, 0, -5}, -1.0, SplatStatus::InvalidInput);
    expectStatus(view, {0, 0, -5}, nan, SplatStatus::InvalidInput);
    expectStatus(view, {0, 0, -5}, inf, SplatStatus::InvalidInput);
    expectStatus(view, {nan, 0, -5}, 1.0, SplatStatus::InvalidInput);
    expectStatus(view, {0, -inf, -5}, 1.0, SplatStatus::InvalidInput);
    SplatView bad = view;
    bad.eye.y = nan;
    expectStatus(bad, {0, 0, -5}, 1.0, SplatStatus::InvalidInput);
    bad = view;
    bad.focalLength = 0.0;
    expectStatus(bad, {0, 0, -5}, 1.0, SplatStatus::InvalidInput);
    bad = view;
    bad.orthographic = true;
    expectStatus(bad, {0, 0, 5}, 1.0, SplatStatus::CrossesEyePlane);
    expectStatus(bad, {0, 0, -5}, 0.0, SplatStatus::ZeroRadius);
}

TEST(SplatGeometryTest, ExtremeButValidSpheresAreFiniteOrRefused) {
    SplatView view;
    // Ever closer to touching the eye plane, far off axis, and at huge or tiny scales.
    for (const double gap : {1e-3, 1e-8, 1e-12, 1e-15, 1e-17, 0.0})
        for (const double scale : {1e-300, 1e-150, 1.0, 1e150, 1e300}) {
            const glm::dvec3 centre = scale * glm::dvec3(7.0, 0.0, -(1.0 + gap));
            const SplatProjection proj = projectSphere(view, centre, scale);
            if (!proj.ok()) {
                EXPECT_EQ(proj.status, SplatStatus::CrossesEyePlane);
                continue;
            }
            const SplatEllipse& e = proj.ellipse;
            for (const double x : {e.centre.x, e.centre.y, e.axisRadial.x, e.axisRadial.y,
                                   e.axisTangential.x, e.axisTangential.y, e.halfAngleRad})
                EXPECT_TRUE(std::isfinite(x)) << "gap " << gap << " scale " << scale;
        }
}

TEST(SplatGeometryTest, ViewValidationNamesTheBadField) {
    SplatView view;
    EXPECT_NO_THROW(view.validate());
    SplatView bad = view;
    bad.forward = {0, 0, -2};
    EXPECT_THROW(bad.validate(), std::invalid_argument);
    bad = view;
    bad.up = glm::normalize(glm::dvec3(0, 1, 0.1));
    EXPECT_THROW(bad.validate(), std::invalid_argument);
    bad = view;
    bad.eye.x = std::numeric_limits<double>::quiet_NaN();
    EXPECT_THROW(bad.validate(), std::invalid_argument);
    bad = view;
    bad.focalLength = -1.0;
    EXPECT_THROW(bad.validate(), std::invalid_argument);
}

// ---- footprint ----

/// Composite Simpson rule over [a, b] with n (even) intervals.
double simpson(const std::function<double(double)>& f, double a, double b, int n) {
    const double h = (b - a) / n;
    double sum = f(a) + f(b);
    for (int k = 1; k < n; ++k)
        sum += f(a + k * h) * (k % 2 ? 4.0 : 2.0);
    return sum * h / 3.0;
}

TEST(SplatFootprintTest, LineIntegralMatchesQuadratureOfTheKernel) {
    const double sigma = 0.5;
    const SplatFootprint fp({sigma});
    const double rim = std::exp(-0.5 / (sigma * sigma));
    const auto kernel = [&](double s) {
        return s < 1.0 ? std::exp(-0.5 * s * s / (sigma * sigma)) - rim : 0.0;
    };
    const auto chord = [&](double d) {
        const double half = std::sqrt(std::max(0.0, 1.0 - d * d));
        return simpson([&](double t) { return kernel(std::hypot(d, t)); }, -half, half, 4000);
    };
    const double centre = chord(0.0);
    for (const double d : {0.0, 0.1, 0.3, 0.5, 0.7, 0.9, 0.99})
        EXPECT_NEAR(fp.lineIntegral(d) / fp.lineIntegral(0.0), chord(d) / centre, 1e-9) << d;
}

TEST(SplatFootprintTest, FootprintIntegratesToOneOverTheUnitDisk) {
    for (const double sigma : {0.3, 0.5, 1.0, 5.0}) {
        const SplatFootprint fp({sigma});
        const double mass =
            simpson([&](double d) { return 2.0 * kPi * d * fp.lineIntegral(d); }, 0.0, 1.0, 20000);
        EXPECT_NEAR(mass, 1.0, 1e-7) << "sigma " << sigma;
    }
}

TEST(SplatFootprintTest, FootprintFallsToZeroAtTheRimAndOutside) {
    const SplatFootprint fp;
    EXPECT_EQ(fp.lineIntegral(1.0), 0.0);
    EXPECT_EQ(fp.lineIntegral(1.5), 0.0);
    EXPECT_EQ(fp.lineIntegral(std::nan("")), 0.0);
    EXPECT_LT(fp.lineIntegral(0.999), 1e-4 * fp.lineIntegral(0.0)); // zero value and slope
    EXPECT_EQ(fp.lookup(1.0, 0.1), 0.0);
    EXPECT_EQ(fp.lookup(3.0, 0.1), 0.0);
    EXPECT_EQ(fp.lookup(std::nan(""), 0.1), 0.0);
    EXPECT_EQ(fp.lookup(0.5, std::nan("")), 0.0);
    EXPECT_EQ(fp.lookup(-0.5, 0.1), fp.lookup(0.0, 0.1));
    EXPECT_THROW(SplatFootprint({0.0}), std::invalid_argument);
    EXPECT_THROW(SplatFootprint({std::nan("")}), std::invalid_argument);
}

TEST(SplatFootprintTest, TableMatchesDirectEvaluationWithinTheStatedBound) {
    for (const double sigma : {0.3, 0.5, 0.7, 1.0}) {
        const SplatFootprint fp({sigma});
        const double peak = fp.lineIntegral(0.0);
        double worst = 0.0, worstI = 0.0, worstA = 0.0;
        for (int a = 0; a <= 600; ++a) {
            const double alpha = SplatFootprint::kTableMaxAngleRad * a / 600;
            for (int k = 0; k <= 8192; ++k) {
                const double i = k / 8192.0;
                const double err = std::abs(fp.lookup(i, alpha) - fp.evaluate(i, alpha)) / peak;
                if (err > worst) worst = err, worstI = i, worstA = alpha;
            }
        }
        std::printf("[splat] footprint table %ux%u, sigma %.1f r: worst error %.2e of the centre "
                    "value (at i %.4f, alpha %.2f deg)\n",
                    SplatFootprint::kIndexSamples, SplatFootprint::kAngleSamples, sigma, worst,
                    worstI, worstA / kDeg);
        EXPECT_LT(worst, SplatFootprint::kTableRelativeError) << "sigma " << sigma;
    }
}

// The CPU splatter's per-pixel table over u = d^2 against the closed form: no erf or square
// root per pixel, and an error far below the 2D table's.
TEST(SplatFootprintTest, SquaredDistanceTableMatchesTheLineIntegralWithinTheStatedBound) {
    for (const double sigma : {0.3, 0.5, 0.7, 1.0}) {
        const SplatFootprint fp({sigma});
        const double peak = fp.lineIntegral(0.0);
        double worst = 0.0, worstU = 0.0;
        for (int k = 0; k <= 1 << 20; ++k) {
            const double u = k / double(1 << 20);
            const double exact = fp.lineIntegral(std::sqrt(u));
            const double err = std::abs(fp.bySquaredDistance(float(u)) - exact) / peak;
            if (err > worst) worst = err, worstU = u;
        }
        std::printf("[splat] footprint over d^2, %u entries, sigma %.1f r: worst error %.2e of the "
                    "centre value (at d^2 %.5f)\n",
                    SplatFootprint::kSquaredSamples, sigma, worst, worstU);
        EXPECT_LT(worst, SplatFootprint::kSquaredTableRelativeError) << "sigma " << sigma;
    }
    const SplatFootprint fp;
    EXPECT_EQ(fp.bySquaredDistance(1.0f), 0.0f);
    EXPECT_EQ(fp.bySquaredDistance(2.0f), 0.0f);
    EXPECT_EQ(fp.bySquaredDistance(std::nanf("")), 0.0f);
    EXPECT_EQ(fp.bySquaredDistance(-0.5f), fp.bySquaredDistance(0.0f));
    EXPECT_NEAR(fp.bySquaredDistance(0.0f), fp.lineIntegral(0.0), 1e-7 * fp.lineIntegral(0.0));
}

TEST(SplatFootprintTest, BeyondFifteenDegreesLookupIsDirectEvaluation) {
    const SplatFootprint fp;
    for (const double alphaDeg : {15.001, 20.0, 45.0, 80.0})
        for (const double i : {0.0, 0.3, 0.8, 0.999})
            EXPECT_EQ(fp.lookup(i, alphaDeg * kDeg), fp.evaluate(i, alphaDeg * kDeg));
}

// End to end: what a splat puts on a pixel (table at the cone index) equals the kernel
// integrated along that pixel's eye ray through the sphere.
TEST(SplatFootprintTest, LookupAtTheConeIndexEqualsTheKernelAlongThePixelRay) {
    const SplatFootprint fp;
    const double sigma = SplatFootprintConfig{}.sigmaOverRadius,
                 rim = std::exp(-0.5 / (sigma * sigma));
    const double norm =
        1.0 / fp.lineIntegral(0.0) *
        simpson([&](double t) { return std::exp(-0.5 * t * t / (sigma * sigma)) - rim; }, -1.0, 1.0,
                4000);
    std::mt19937_64 rng(11);
    double worst = 0.0;
    for (const SplatCase& c : splatCases(10)) {
        const SplatProjection proj = projectSphere(c.view, c.centre, c.radius);
        ASSERT_TRUE(proj.ok());
        for (int k = 0; k < 20; ++k) {
            const glm::dvec2 p = pointInside(proj.ellipse, rng);
            const Ray ray = c.view.ray(p);
            const double tc = glm::dot(c.centre - ray.origin, ray.direction);
            const double along =
                simpson(
                    [&](double t) {
                        const double s =
                            glm::length(ray.origin + t * ray.direction - c.centre) / c.radius;
                        return s < 1.0 ? std::exp(-0.5 * s * s / (sigma * sigma)) - rim : 0.0;
                    },
                    tc - c.radius, tc + c.radius, 4000) /
                c.radius / norm;
            const double got =
                fp.lookup(coneIndex(c.view, c.centre, c.radius, p), proj.ellipse.halfAngleRad);
            worst = std::max(worst, std::abs(got - along) / fp.lineIntegral(0.0));
        }
    }
    std::printf("[splat] table at the cone index vs kernel integrated along pixel rays: worst "
                "%.2e of the centre value\n",
                worst);
    EXPECT_LT(worst, SplatFootprint::kTableRelativeError + 1e-6);
}

} // namespace
} // namespace bc::render
