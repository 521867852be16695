// The CPU raycaster's SIMD marches (render/detail/CpuMarchSimd.cpp: across rays, and across
// one ray's samples) against its scalar loop: the same image, bit for bit, on every
// instruction set Highway compiled that this host runs, for every voxel type, with and
// without shading, skipping and early termination, and where some lanes fall back to the
// scalar code (aprons under 2).
#include "RenderTestSupport.h"
#include "render/CpuRaycaster.h"
#include "render/detail/CpuMarchSimd.h"

#include <hwy/targets.h>

#include <random>

namespace bc::render {
namespace {

using test::TestStore;

struct Frames {
    Image image;
    FrameStats stats;
};

/// The CPU raycaster's three marches: the scalar loop, and the two SIMD layouts.
enum class March { Scalar, Samples, Packets };

Frames draw(TestStore& t, const TransferFunction& tf, const Camera& c, RenderOptions o,
            March march) {
    o.simd = march != March::Scalar;
    o.packets = march == March::Packets;
    CpuRaycaster r;
    Frames f;
    f.image = r.render(*t.store, *t.cache, tf, c, o, f.stats);
    return f;
}

/// Every Highway target this host supports and the build compiled, each made the chosen one
/// in turn (restored after).
class EachTarget {
  public:
    EachTarget() : mTargets(hwy::SupportedAndGeneratedTargets()) {
        std::printf("SIMD targets here:");
        for (const std::int64_t target : mTargets)
            std::printf(" %s", hwy::TargetName(target));
        std::printf("\n");
    }
    ~EachTarget() { hwy::SetSupportedTargetsForTest(0); }
    template <class F> void run(F&& body) const {
        for (const std::int64_t target : mTargets) {
            hwy::SetSupportedTargetsForTest(target);
            SCOPED_TRACE(hwy::TargetName(target));
            EXPECT_EQ(CpuRaycaster::simdTarget().rfind(hwy::TargetName(target), 0), 0u)
                << CpuRaycaster::simdTarget();
            body();
        }
    }
    std::size_t count() const { return mTargets.size(); }

  private:
    std::vector<std::int64_t> mTargets;
};

void expectSame(TestStore& t, const TransferFunction& tf, const Camera& c, const RenderOptions& o,
                const std::string& what) {
    const Frames withMaps = draw(t, tf, c, o, March::Scalar);
    EXPECT_GT(test::alphaSum(withMaps.image), 0.01 * o.width * o.height)
        << what << ": the view shows almost nothing, so proves nothing";
    // The march across one ray's samples leaps by the octree alone, not by distance maps: its
    // samples are compared with the scalar loop's without maps (its image with either).
    RenderOptions leaves = o;
    leaves.cellVoxels = 0;
    const Frames scalarLeaves = draw(t, tf, c, leaves, March::Scalar);
    EXPECT_EQ(compareImages(scalarLeaves.image, withMaps.image).maxAbs, 0.0) << what;
    for (const March march : {March::Samples, March::Packets}) {
        const std::string how = what + (march == March::Samples ? ", samples" : ", packets");
        const Frames simd = draw(t, tf, c, march == March::Samples ? leaves : o, march);
        const Frames& scalar = march == March::Samples ? scalarLeaves : withMaps;
        const auto cmp = compareImages(simd.image, scalar.image);
        EXPECT_EQ(cmp.maxAbs, 0.0) << how;
        EXPECT_TRUE(test::allFinite(simd.image)) << how;
        // The SIMD marches test the octree per sample as the scalar loop does, but leap from
        // the sample's own leaf (or over a vector of samples): they take about the scalar
        // loop's samples, a few more (transparent ones) or a few fewer, not many either way.
        EXPECT_GE(double(simd.stats.samples), 0.98 * double(scalar.stats.samples)) << how;
        EXPECT_LE(double(simd.stats.samples), 2.0 * double(scalar.stats.samples) + 16.0) << how;
    }
}

struct Case {
    std::string scan, preset;
    brickstore::VoxelType type;
};

class CpuSimd : public ::testing::TestWithParam<Case> {};

TEST_P(CpuSimd, SameImageAsTheScalarLoopOnEveryTarget) {
    const Case k = GetParam();
    auto spec = test::realScan(k.scan);
    if (!spec) return test::missingData("scan " + k.scan);
    auto t = test::ingestSpec(*spec, {32, 2, 8});
    ASSERT_EQ(t->store->info().volume.type, k.type);
    const auto tf = TransferFunction::preset(k.preset, t->stats);
    const Box box = LevelGeometry::of(*t->store, 0).box;
    EachTarget targets;
    ASSERT_GE(targets.count(), 1u);
    targets.run([&] {
        for (const auto& [az, el] : {std::pair{30.0, 20.0}, std::pair{210.0, -40.0}}) {
            const Camera c = Camera::orbit(box, az, el);
            RenderOptions o;
            o.width = o.height = 64;
            expectSame(*t, tf, c, o, k.scan + " shaded, skipping, ERT");
            o.shading = false;
            o.skip = SkipMode::None;
            o.earlyTermination = false;
            o.stepVoxels = 0.7;
            expectSame(*t, tf, c, o, k.scan + " unshaded, plain, step 0.7");
        }
    });
}

INSTANTIATE_TEST_SUITE_P(VoxelTypes, CpuSimd,
                         ::testing::Values(Case{"headsq", "ct-skin", brickstore::VoxelType::U16},
                                           Case{"CT_AVM", "vessels", brickstore::VoxelType::U8},
                                           Case{"hydrogen", "smoke", brickstore::VoxelType::F32},
                                           Case{"pancreas", "ct-bone", brickstore::VoxelType::I16}),
                         [](const auto& info) { return info.param.scan; });

// Aprons of 0 and 1 leave samples near brick faces outside the fused range: those lanes are
// redone by the scalar code, in order, inside the vector loop.
TEST(CpuSimdFallback, NarrowApronsMixScalarAndVectorLanesExactly) {
    auto spec = test::realScan("headsq");
    if (!spec) return test::missingData("scan headsq");
    for (const std::uint32_t apron : {0u, 1u}) {
        auto t = test::ingestSpec(*spec, {16, apron, 8});
        const auto tf = TransferFunction::preset("ct-bone", t->stats);
        const Camera c = Camera::orbit(LevelGeometry::of(*t->store, 0).box, 75, 25);
        RenderOptions o;
        o.width = o.height = 64;
        expectSame(*t, tf, c, o, "headsq apron " + std::to_string(apron));
    }
}

// Positions near x = 16384 voxels, rays through a camera inside the volume, axis-parallel
// orthographic rays on brick faces, and steps of 0.05 and 4 voxels: exact on the SIMD path too.
TEST(CpuSimdFallback, StressViewsAreExactAndFinite) {
    const test::FarChecker checker = test::farChecker();
    RenderOptions o;
    o.width = o.height = 64;
    expectSame(*checker.store, checker.tf, checker.camera, o, "checker 16384 wide, far end");

    auto phantom = brickstore::makeSynthetic(brickstore::SynthKind::Phantom, {96, 96, 64}, 3);
    auto p = test::ingestStore(*phantom, {32, 2, 8});
    const auto skin = TransferFunction::preset("ct-skin", p->stats);
    const Box box = LevelGeometry::of(*p->store, 0).box;
    Camera inside;
    inside.eye = box.centre();
    inside.target = box.centre() + glm::dvec3(1, 0.3, 0.2);
    inside.up = {0, 0, 1};
    inside.fovYDeg = 70;
    expectSame(*p, skin, inside, o, "phantom camera inside");
    Camera faces;
    faces.orthographic = true;
    faces.eye = {47.5, 48, 500}; // pixel columns on the x = 32k faces, rays along z
    faces.target = {47.5, 48, 0};
    faces.up = {0, 1, 0};
    faces.orthoHeight = 96;
    RenderOptions ortho = o;
    ortho.width = ortho.height = 96;
    expectSame(*p, skin, faces, ortho, "phantom axis-parallel rays on brick faces");
    for (const double step : {0.05, 4.0}) {
        RenderOptions s = o;
        s.stepVoxels = step;
        expectSame(*p, skin, Camera::orbit(box, 150, 10), s,
                   "phantom step " + std::to_string(step));
    }
}

// The march across rays addresses each lane's voxels by 32-bit offsets from the packet's first
// brick; a brick out of that reach (bricks are separate allocations, and a large host cache
// can put them gigabytes apart) marches with the scalar loop. With the reach cut to nothing
// every brick is out of it: the colours and sample counts stay the scalar walk's, bit for bit.
TEST(CpuSimdPackets, BricksOutOfGatherReachMarchWithTheScalarLoopExactly) {
    constexpr int kBrick = 8, kApron = 2, kEdge = kBrick + 2 * kApron, kEntries = 256;
    std::mt19937 rng(11);
    std::vector<std::vector<std::uint16_t>> voxels(4);
    for (auto& v : voxels) {
        v.resize(std::size_t(kEdge) * kEdge * kEdge);
        for (auto& x : v)
            x = std::uint16_t(rng() % 1000);
    }
    std::vector<float> tf(4 * kEntries);
    for (int i = 0; i < kEntries; ++i) {
        tf[4 * i] = float(i) / kEntries;
        tf[4 * i + 1] = 0.5f;
        tf[4 * i + 2] = 1.0f - float(i) / kEntries;
        tf[4 * i + 3] = i < 100 ? 0.0f : 0.6f * float(i - 100) / kEntries;
    }
    std::vector<detail::BrickRef> bricks(4);
    for (int i = 0; i < 4; ++i)
        bricks[i] = {voxels[i].data(), 0.0f, 0, detail::Slot::Sampled};
    detail::Frame f;
    f.eye = glm::vec3(-9.0f, -7.0f, -11.0f);
    f.forward = glm::normalize(glm::vec3(8.0f, 8.0f, 4.0f) - f.eye);
    f.right = 0.3f * glm::normalize(glm::cross(f.forward, glm::vec3(0.0f, 0.0f, 1.0f)));
    f.up = 0.3f * glm::normalize(glm::cross(f.right, f.forward));
    f.invSpacing = glm::vec3(1.0f);
    f.dims = glm::vec3(16.0f, 16.0f, 8.0f);
    f.stepMm = 0.7f;
    f.brick = kBrick;
    f.apron = kApron;
    f.edge = kEdge;
    f.grid = glm::ivec3(2, 2, 1);
    f.tf = tf.data();
    f.entries = kEntries;
    f.tfScale = float(kEntries - 1) / 1000.0f;
    f.ertT = 0.05f;
    f.gradScale = glm::vec3(0.5f / 1000.0f);
    f.bricks = bricks.data();
    constexpr std::uint32_t kSide = 16;
    auto march = [&](std::int64_t reach, detail::RayCount& n) {
        std::vector<detail::RayState> states(kSide * kSide);
        std::vector<detail::RayResume> resumes(kSide * kSide);
        std::vector<detail::PacketRay> rays;
        for (std::uint32_t by = 0; by < kSide; by += 4)
            for (std::uint32_t bx = 0; bx < kSide; bx += 4)
                for (std::uint32_t y = by; y < by + 4; ++y)
                    for (std::uint32_t x = bx; x < bx + 4; ++x)
                        rays.push_back({2.0f * (float(x) + 0.5f) / kSide - 1.0f,
                                        1.0f - 2.0f * (float(y) + 0.5f) / kSide, 0.0f,
                                        &states[y * kSide + x], &resumes[y * kSide + x]});
        if (reach < 0) { // the scalar walk and loop
            for (const detail::PacketRay& r : rays) {
                detail::RayWalk w;
                if (!w.begin(f, r.sx, r.sy, r.shift, *r.state, *r.resume)) continue;
                while (w.next(f, *r.state, *r.resume)) {
                    int k = w.k;
                    if (!detail::marchBrick(f, voxels[std::size_t(w.index)].data(), nullptr,
                                            nullptr, w.local(f), w.dv, w.d, w.t0, k, w.kEnd,
                                            r.state->acc, n))
                        break;
                }
            }
        } else {
            f.gatherReach = reach;
            detail::marchPacketSimd(brickstore::VoxelType::U16, f, rays.data(), rays.size(), n);
        }
        return states;
    };
    detail::RayCount scalarCount, nearCount, farCount;
    const auto scalar = march(-1, scalarCount);
    const auto near = march(std::numeric_limits<std::int32_t>::max(), nearCount);
    const auto far = march(0, farCount);
    double alpha = 0.0;
    int opaque = 0;
    for (std::size_t i = 0; i < scalar.size(); ++i) {
        const detail::Accum& a = scalar[i].acc;
        for (const auto* got : {&near[i].acc, &far[i].acc}) {
            EXPECT_EQ(got->r, a.r) << "ray " << i;
            EXPECT_EQ(got->g, a.g) << "ray " << i;
            EXPECT_EQ(got->b, a.b) << "ray " << i;
            EXPECT_EQ(got->t, a.t) << "ray " << i;
        }
        alpha += 1.0 - a.t;
        opaque += a.t <= f.ertT ? 1 : 0;
    }
    EXPECT_EQ(nearCount.samples, scalarCount.samples);
    EXPECT_EQ(farCount.samples, scalarCount.samples);
    EXPECT_GT(alpha, 0.2 * double(scalar.size())) << "the rays see almost nothing";
    EXPECT_GT(opaque, 0) << "no ray reaches early termination";
}
} // namespace
} // namespace bc::render
