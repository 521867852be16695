// The crop box and clip planes (render/Clip.h, RenderOptions::clip): bad values are refused
// naming the field; the kept interval of a ray and the bricks wholly outside are what the
// geometry says; a crop holding an eighth of a volume loads only the bricks it touches; on
// real scans the CPU raycaster draws the reference's image in every mode with a crop and a
// plane, and skipping changes no pixel.
#include "render/Clip.h"
#include "RenderTestSupport.h"
#include "brickstore/BrickCache.h"
#include "render/BrickPlan.h"
#include "render/ReferenceRenderer.h"

#include <cmath>
#include <limits>

#include <glm/geometric.hpp>

namespace bc::render {
namespace {

using test::TestStore;

TEST(ClipRules, BadValuesAreRefusedNamingTheField) {
    const double nan = std::numeric_limits<double>::quiet_NaN();
    const double inf = std::numeric_limits<double>::infinity();
    Clip c;
    c.cropped = true;
    c.cropMin = {0, 0, 0};
    c.cropMax = {10, 10, 10};
    EXPECT_NO_THROW(c.validate());
    for (const auto& [lo, hi] :
         std::vector<std::pair<double, double>>{{5, 5}, {6, 5}, {nan, 5}, {0, inf}, {-inf, 1}}) {
        Clip bad = c;
        bad.cropMin[1] = lo;
        bad.cropMax[1] = hi;
        const std::string why = test::refusal([&] { bad.validate(); });
        EXPECT_EQ(why.rfind("crop:", 0), 0u) << lo << ".." << hi << ": " << why;
        EXPECT_NE(why.find("axis y"), std::string::npos) << why;
    }
    Clip planes;
    planes.planeCount = 2;
    planes.planes[0] = {{1, 0, 0}, -3};
    planes.planes[1] = {{0, 0, 0}, 1};
    EXPECT_EQ(test::refusal([&] { planes.validate(); }).rfind("clip[1]: the normal is zero", 0),
              0u);
    planes.planes[1] = {{0, nan, 1}, 1};
    EXPECT_EQ(test::refusal([&] { planes.validate(); }).rfind("clip[1]:", 0), 0u);
    planes.planes[1] = {{0, 0, 1}, inf};
    EXPECT_EQ(test::refusal([&] { planes.validate(); }).rfind("clip[1]:", 0), 0u);
    planes.planeCount = 7;
    planes.planes[1] = {{0, 0, 1}, 1};
    EXPECT_EQ(test::refusal([&] { planes.validate(); }).rfind("clip: 7 planes", 0), 0u);
    // Through the options, as every renderer validates them.
    RenderOptions o;
    o.clip = planes;
    EXPECT_EQ(test::refusal([&] { o.validate(); }).rfind("clip:", 0), 0u);
}

TEST(ClipRules, TheKeptIntervalAndTheBricksOutside) {
    Clip c;
    c.cropped = true;
    c.cropMin = {10, 0, 0};
    c.cropMax = {20, 100, 100};
    // Along +x from x = 0: the box keeps t in [10, 20].
    const auto box = c.interval({0, 50, 50}, {1, 0, 0});
    EXPECT_DOUBLE_EQ(box[0], 10.0);
    EXPECT_DOUBLE_EQ(box[1], 20.0);
    // A plane keeping x <= 15 (-x + 15 >= 0) shortens it; one with a huge normal is the same.
    c.planeCount = 1;
    c.planes[0] = {{-1, 0, 0}, 15};
    EXPECT_DOUBLE_EQ(c.interval({0, 50, 50}, {1, 0, 0})[1], 15.0);
    float fa = -3e38f, fb = 3e38f;
    Clip huge = c;
    huge.planes[0] = {{-1e300, 0, 0}, 15e300};
    ClipF::of(huge).interval({0, 50, 50}, {1, 0, 0}, fa, fb);
    EXPECT_FLOAT_EQ(fa, 10.0f);
    EXPECT_FLOAT_EQ(fb, 15.0f);
    // A ray parallel to the plane on its cut side keeps nothing.
    const auto parallel = c.interval({16, 50, 0}, {0, 0, 1});
    EXPECT_GT(parallel[0], parallel[1]);
    // Boxes: outside the crop, on the cut side, touching (kept).
    EXPECT_TRUE(c.outside({{21, 0, 0}, {30, 10, 10}}));
    EXPECT_TRUE(c.outside({{15.5, 0, 0}, {19, 10, 10}}));
    EXPECT_FALSE(c.outside({{15, 0, 0}, {19, 10, 10}}));
    EXPECT_FALSE(c.outside({{0, 0, 0}, {10, 10, 10}}));
}

/// A generated 64^3 phantom in bricks of 16 (4^3 bricks), with a cold cache.
std::unique_ptr<TestStore> phantom64() {
    auto source = brickstore::makeSynthetic(brickstore::SynthKind::Phantom, {64, 64, 64}, 1);
    return test::ingestStore(*source, {16, 2, 4});
}

TEST(ClipResidency, ACropHoldingAnEighthOfTheVolumeLoadsOnlyTheBricksItTouches) {
    const auto t = phantom64();
    const TransferFunction tf = TransferFunction::preset("ct-skin", t->stats);
    const LevelGeometry g = LevelGeometry::of(*t->store, 0);
    const Camera camera = Camera::orbit(g.box, 30.0, 20.0);
    RenderOptions o;
    o.width = o.height = 96;
    o.skip = SkipMode::None; // every brick in view is drawn unless the crop removes it
    o.clip.cropped = true;
    for (int a = 0; a < 3; ++a) { // the low octant, a voxel inside its faces: 2^3 bricks
        o.clip.cropMin[a] = g.box.min[a] + g.spacing[a];
        o.clip.cropMax[a] = g.box.min[a] + 0.5 * g.box.size()[a] - g.spacing[a];
    }
    FrameStats stats;
    const Image image = test::cpuFrame(*t, tf, camera, o, &stats);
    EXPECT_GT(test::alphaSum(image), 1.0) << "the octant shows something";
    EXPECT_LE(stats.bricksVisited, 8u);
    EXPECT_GE(stats.bricksCulled, 64u - 8u);
    const auto cache = t->cache->stats();
    EXPECT_LE(cache.misses, 8u) << "bricks loaded from the store";
    std::printf("[clip] an eighth of 4^3 bricks: %llu drawn, %llu loaded, %llu culled\n",
                (unsigned long long)stats.bricksVisited, (unsigned long long)cache.misses,
                (unsigned long long)stats.bricksCulled);
}

class ClipOnScans : public ::testing::TestWithParam<std::string> {};

TEST_P(ClipOnScans, EveryModeInsideACropAndAPlaneIsTheReferencesAndSkippingChangesNoPixel) {
    const auto t = test::ingestRealScan(GetParam());
    if (!t) return test::missingData("scan " + GetParam());
    const TransferFunction bone = TransferFunction::preset("ct-bone", t->stats);
    const TransferFunction ramp = test::greyRamp(t->stats);
    const Box box = LevelGeometry::of(*t->store, 0).box;
    const Camera camera = Camera::orbit(box, 40.0, 30.0);
    Clip clip;
    clip.cropped = true;
    for (int a = 0; a < 3; ++a) {
        clip.cropMin[a] = box.min[a] + 0.1 * box.size()[a];
        clip.cropMax[a] = box.min[a] + 0.8 * box.size()[a];
    }
    // An oblique plane through the centre, keeping the side away from the camera's left.
    const glm::dvec3 n = glm::normalize(glm::dvec3(1, -0.5, 0.3));
    clip.planeCount = 1;
    clip.planes[0] = ClipPlane{{n.x, n.y, n.z}, -glm::dot(n, box.centre())};
    ReferenceRenderer reference;
    for (const BlendMode mode :
         {BlendMode::Composite, BlendMode::Maximum, BlendMode::Average, BlendMode::Isosurface}) {
        SCOPED_TRACE(toString(mode));
        const TransferFunction& tf = mode == BlendMode::Average ? ramp : bone;
        RenderOptions o;
        o.width = o.height = 96;
        o.mode = mode;
        o.clip = clip;
        o.isoValue = 0.5 * (tf.domainMin() + tf.domainMax());
        FrameStats refStats;
        const Image ref = reference.render(*t->store, *t->cache, tf, camera, o, refStats);
        const Image cpu = test::cpuFrame(*t, tf, camera, o);
        const ImageComparison c = compareImages(cpu, ref);
        test::printComparison(GetParam() + " " + toString(mode) + " cropped and clipped", c);
        EXPECT_GE(c.psnrDb, 50.0);
        // Skipping off (and early termination, which changes no pixel in the other modes;
        // composite's is kept on both sides: it stops within 1 - its threshold by design).
        RenderOptions plain = o;
        plain.skip = SkipMode::None;
        plain.earlyTermination = mode == BlendMode::Composite;
        EXPECT_EQ(compareImages(test::cpuFrame(*t, tf, camera, plain), cpu).maxAbs, 0.0);
        // The cut changes the image: without it the frame differs.
        RenderOptions whole = o;
        whole.clip = {};
        EXPECT_GT(compareImages(test::cpuFrame(*t, tf, camera, whole), cpu).maxAbs, 0.0);
    }
}

INSTANTIATE_TEST_SUITE_P(RealScans, ClipOnScans,
                         ::testing::Values("cthead", "CT_AVM", "Iguana", "headsq"));

} // namespace
} // namespace bc::render
