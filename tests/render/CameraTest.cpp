// Ray generation and box clipping: the rules every renderer shares (render/OPTICS.md).
#include "render/Camera.h"

#include <gtest/gtest.h>

#include <cmath>
#include <glm/geometric.hpp>

namespace bc::render {
namespace {

TEST(CameraTest, OrbitLooksAtTheBoxCentreAndFitsItsBoundingSphere) {
    const Box box{{0, 0, 0}, {256, 256, 226}};
    const Camera c = Camera::orbit(box, 30, 20, 1.0, 30.0);
    EXPECT_NEAR(glm::length(c.target - box.centre()), 0.0, 1e-12);
    const double dist = glm::length(c.eye - c.target);
    EXPECT_NEAR(std::sin(15.0 * 3.14159265358979 / 180.0) * dist, box.radius(), 1e-9);
    EXPECT_NO_THROW(c.validate());
}

TEST(CameraTest, CentrePixelRayOfAnEvenImagePassesBesideTheTargetAndCornersSpanTheFov) {
    Camera c;
    c.eye = {0, 0, 10};
    c.target = {0, 0, 0};
    c.up = {0, 1, 0};
    c.fovYDeg = 90.0;
    const ViewBasis v = ViewBasis::from(c, 2, 2);
    // Pixel (0,0) is the top-left quarter: direction (-0.5, +0.5, -1) normalised.
    const Ray r = v.ray(0, 0, 2, 2);
    const glm::dvec3 want = glm::normalize(glm::dvec3(-0.5, 0.5, -1.0));
    EXPECT_NEAR(glm::length(r.direction - want), 0.0, 1e-12);
    EXPECT_EQ(r.origin, c.eye);
}

TEST(CameraTest, OrthographicRaysAreParallelAndOffsetOnTheImagePlane) {
    Camera c;
    c.eye = {0, 0, 10};
    c.target = {0, 0, 0};
    c.up = {0, 1, 0};
    c.orthographic = true;
    c.orthoHeight = 4.0;
    const ViewBasis v = ViewBasis::from(c, 4, 2); // 8 x 4 mm view
    const Ray a = v.ray(0, 0, 4, 2), b = v.ray(3, 1, 4, 2);
    EXPECT_EQ(a.direction, b.direction);
    EXPECT_NEAR(a.origin.x, -3.0, 1e-12);
    EXPECT_NEAR(a.origin.y, 1.0, 1e-12);
    EXPECT_NEAR(b.origin.x, 3.0, 1e-12);
    EXPECT_NEAR(b.origin.y, -1.0, 1e-12);
}

TEST(CameraTest, RejectsNonFiniteDegenerateOrParallelCameras) {
    Camera c;
    c.eye = {0, 0, NAN};
    EXPECT_THROW(c.validate(), std::invalid_argument);
    c.eye = {0, 0, 0};
    EXPECT_THROW(c.validate(), std::invalid_argument); // eye == target
    c.eye = {0, 5, 0};
    c.up = {0, 1, 0};
    EXPECT_THROW(c.validate(), std::invalid_argument); // up parallel to view
    c.up = {1, 0, 0};
    c.fovYDeg = 180.0;
    EXPECT_THROW(c.validate(), std::invalid_argument);
    c.fovYDeg = 40.0;
    EXPECT_NO_THROW(c.validate());
}

TEST(CameraTest, RayExactlyAlongABoxFaceCountsAsInsideAndOutsideRaysMiss) {
    const Box box{{0, 0, 0}, {10, 10, 10}};
    const auto along = intersectBox({{0, 5, -5}, {0, 0, 1}}, box); // on the x = 0 face
    EXPECT_DOUBLE_EQ(along[0], 5.0);
    EXPECT_DOUBLE_EQ(along[1], 15.0);
    const auto miss = intersectBox({{-0.001, 5, -5}, {0, 0, 1}}, box);
    EXPECT_GT(miss[0], miss[1]);
    const auto grazing = intersectBox({{-1, 5, 0}, glm::normalize(glm::dvec3(1, 0, 1e-9))}, box);
    EXPECT_LE(grazing[0], grazing[1]);
}

} // namespace
} // namespace bc::render
