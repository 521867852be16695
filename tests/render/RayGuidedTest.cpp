// Ray-guided residency (render/RESIDENCY.md): bricks the last frame's unsaturated rays never
// entered are not uploaded while the pool lacks them, rays that reach one anyway stop and go
// on once it is loaded, and the images stay those of the raycaster without it. The volumes
// are dense (a generated CT-like head, and cthead when the scans are there) under an opaque
// skin surface, so most of their bricks lie behind saturated rays.
#include "RenderTestSupport.h"

#include <glm/geometric.hpp>

namespace bc::render {
namespace {

using test::TestStore;

/// Bricks a frame needs resident: drawn, less constant ones, less those left deferred.
std::uint64_t residentBricks(const FrameStats& s) {
    return s.bricksVisited - s.bricksConstant - s.bricksDeferred + s.bricksRequested;
}

RenderOptions frameOptions(bool guided, std::uint32_t edge = 96) {
    RenderOptions o;
    o.width = o.height = edge;
    o.rayGuided = guided;
    return o;
}

/// Skin as an opaque surface (ct-skin, the preset, is see-through: rays go deep).
TransferFunction opaqueSkin(const VolumeValueStats& stats) {
    return TransferFunction::parse(R"({"name": "opaque-skin", "shading": true, "points": [
        {"fraction": 0.22, "rgba": [0.90, 0.70, 0.55, 0.0]},
        {"fraction": 0.29, "rgba": [0.93, 0.74, 0.61, 0.6]},
        {"fraction": 1.0, "rgba": [1.00, 0.95, 0.90, 0.6]}]})",
                                   "<opaque skin>", stats);
}

std::unique_ptr<TestStore> phantomStore() {
    test::glContext();
    brickstore::SourceSpec spec;
    spec.input = "synth:phantom";
    spec.dims = std::array<std::uint64_t, 3>{128, 128, 128};
    return test::ingestSpec(spec, {16, 2, 8});
}

std::uint64_t slotBytes(const TestStore& t) {
    const std::uint64_t e = t.store->layout().storedEdge();
    return e * e * e * brickstore::voxelBytes(t.store->info().volume.type);
}

/// A pool budget of `slots` bricks of `t`.
GpuRaycasterConfig budgetOf(const TestStore& t, std::uint64_t slots) {
    return GpuRaycasterConfig{slots * slotBytes(t)};
}

struct PlanSize {
    std::uint64_t sampled = 0, entered = 0;
};

/// What a frame at `camera` plans and what its rays enter, drawn with room for everything.
PlanSize planSize(TestStore& t, const TransferFunction& tf, const Camera& camera,
                  const RenderOptions& options = frameOptions(true)) {
    GpuRaycaster big({1ull << 30});
    FrameStats s;
    test::gpuFrame(t, big, tf, camera, options, &s);
    return {s.bricksVisited - s.bricksConstant, s.bricksEntered};
}

/// An orbit drawn by a guided and an unguided raycaster with the same small pool (between
/// what rays enter and what the plan holds), and by one with room for everything: every frame
/// the same image, and the guided one uploads less.
void checkOrbit(TestStore& t, const TransferFunction& tf, const std::string& what) {
    const Box box = LevelGeometry::of(*t.store, 0).box;
    const PlanSize size = planSize(t, tf, Camera::orbit(box, 0, 20));
    std::printf("[guided] %s: %llu sampled bricks planned, %llu entered by unsaturated rays\n",
                what.c_str(), (unsigned long long)size.sampled, (unsigned long long)size.entered);
    ASSERT_LT(size.entered * 10, size.sampled * 8) << "too little is hidden to test deferral";
    const std::uint64_t slots = (size.entered * 3 / 2 + size.sampled) / 2;
    GpuRaycaster guided(budgetOf(t, slots)), plain(budgetOf(t, slots)), big({1ull << 30});
    std::uint64_t uploadsGuided = 0, uploadsPlain = 0, deferred = 0, requested = 0;
    std::uint32_t resumes = 0, passesGuided = 0, passesPlain = 0;
    double worst = 0.0;
    for (int f = 0; f < 24; ++f) {
        const Camera camera = Camera::orbit(box, 3.0 * f, 20);
        FrameStats sg, sp, sb;
        const Image a = test::gpuFrame(t, guided, tf, camera, frameOptions(true), &sg);
        const Image b = test::gpuFrame(t, plain, tf, camera, frameOptions(false), &sp);
        const Image c = test::gpuFrame(t, big, tf, camera, frameOptions(false), &sb);
        ASSERT_LT(guided.pool()->capacity() + 0u, size.sampled);
        const double diff = std::max(compareImages(a, b).maxAbs, compareImages(a, c).maxAbs);
        worst = std::max(worst, diff);
        EXPECT_LE(diff, 1e-6) << what << " frame " << f;
        EXPECT_FALSE(sg.guidedFallback) << what << " frame " << f;
        EXPECT_EQ(sp.bricksDeferred, 0u);
        EXPECT_EQ(sp.bricksEntered, 0u) << "feedback is off without rayGuided";
        if (f > 0) {
            EXPECT_GT(sg.bricksDeferred, 0u) << what << " frame " << f;
            EXPECT_EQ(sg.batches, 1u) << what << " frame " << f;
            EXPECT_GE(sp.batches, 2u) << what << " frame " << f;
            EXPECT_LE(residentBricks(sg), guided.pool()->capacity()) << what << " frame " << f;
        }
        uploadsGuided += sg.bricksUploaded;
        uploadsPlain += sp.bricksUploaded;
        deferred += sg.bricksDeferred;
        requested += sg.bricksRequested;
        resumes += sg.resumePasses;
        passesGuided += sg.batches + sg.resumePasses;
        passesPlain += sp.batches;
    }
    std::printf("[guided] %s, 24 frames at 3 deg, pool %u slots: uploads %llu guided vs %llu "
                "plain (%.2fx), deferred %llu, asked for %llu, passes %u (%u resuming) vs %u, "
                "worst max abs %.2g\n",
                what.c_str(), guided.pool()->capacity(), (unsigned long long)uploadsGuided,
                (unsigned long long)uploadsPlain,
                double(uploadsPlain) / double(std::max<std::uint64_t>(uploadsGuided, 1)),
                (unsigned long long)deferred, (unsigned long long)requested, passesGuided, resumes,
                passesPlain, worst);
    EXPECT_LT(uploadsGuided * 2, uploadsPlain) << what;
}

TEST(RayGuided, GeneratedHeadOrbitUploadsLessWithTheSameImages) {
    auto t = phantomStore();
    const auto tf = opaqueSkin(t->stats);
    checkOrbit(*t, tf, "phantom 128^3 opaque skin");
}

TEST(RayGuided, CtheadOrbitUploadsLessWithTheSameImages) {
    auto spec = test::realScan("cthead");
    if (!spec) return test::missingData("scan cthead");
    test::glContext();
    auto t = test::ingestSpec(*spec, {16, 2, 8});
    const auto tf = opaqueSkin(t->stats);
    checkOrbit(*t, tf, "cthead opaque skin");
}

// The last frame hid the back of the head; from behind, rays reach those bricks, stop, have
// them loaded and go on: the image is still the unguided one.
TEST(RayGuided, JumpToTheFarSideAsksForWhatTheLastFrameHid) {
    auto t = phantomStore();
    const auto tf = opaqueSkin(t->stats);
    const Box box = LevelGeometry::of(*t->store, 0).box;
    const PlanSize size = planSize(*t, tf, Camera::orbit(box, 0, 20));
    const std::uint64_t slots = (size.entered * 3 / 2 + size.sampled) / 2;
    GpuRaycaster guided(budgetOf(*t, slots)), plain(budgetOf(*t, slots));
    FrameStats s;
    for (double az : {0.0, 180.0}) {
        const Camera camera = Camera::orbit(box, az, 20);
        const Image a = test::gpuFrame(*t, guided, tf, camera, frameOptions(true), &s);
        const Image b = test::gpuFrame(*t, plain, tf, camera, frameOptions(false));
        EXPECT_LE(compareImages(a, b).maxAbs, 1e-6) << "azimuth " << az;
    }
    std::printf("[guided] jump 0 -> 180 deg: deferred %llu, asked for %llu in %u resuming "
                "passes, fallback %d\n",
                (unsigned long long)s.bricksDeferred, (unsigned long long)s.bricksRequested,
                s.resumePasses, int(s.guidedFallback));
    EXPECT_GT(s.bricksRequested, 0u);
    EXPECT_GE(s.resumePasses, 1u);
}

// Capped: the last frame, from the front, saw the skin and hid the middle; from behind, rays
// enter through a plane cut through the middle, whose faces lie in bricks the last frame hid.
// A ray waits for its face's brick before any sample, has it loaded and goes on: the images
// are the unguided ones.
TEST(RayGuided, ARayWaitsForItsCutFacesBrickAndTheImageIsTheUnguidedOne) {
    auto t = phantomStore();
    const auto tf = opaqueSkin(t->stats);
    const Box box = LevelGeometry::of(*t->store, 0).box;
    // Keeps the half towards the first camera: the second one looks at the cut.
    const glm::dvec3 n = glm::normalize(Camera::orbit(box, 0, 20).eye - box.centre());
    RenderOptions o = frameOptions(true);
    o.clip.planeCount = 1;
    o.clip.planes[0] = {{n.x, n.y, n.z}, -glm::dot(n, box.centre())};
    o.clip.cap = true;
    const PlanSize size = planSize(*t, tf, Camera::orbit(box, 0, 20), o);
    const std::uint64_t slots = size.sampled - 1; // the plan does not fit
    GpuRaycaster guided(budgetOf(*t, slots)), plain(budgetOf(*t, slots));
    RenderOptions unguided = o;
    unguided.rayGuided = false;
    FrameStats s;
    for (double az : {0.0, 180.0}) {
        const Camera camera = Camera::orbit(box, az, 20);
        const Image a = test::gpuFrame(*t, guided, tf, camera, o, &s);
        const Image b = test::gpuFrame(*t, plain, tf, camera, unguided);
        EXPECT_LE(compareImages(a, b).maxAbs, 1e-6) << "azimuth " << az;
        EXPECT_GT(test::alphaSum(a), 100.0) << "azimuth " << az;
    }
    std::printf("[guided] capped, 0 -> 180 deg: deferred %llu, asked for %llu in %u resuming "
                "passes\n",
                (unsigned long long)s.bricksDeferred, (unsigned long long)s.bricksRequested,
                s.resumePasses);
    EXPECT_GT(s.bricksRequested, 0u);
    EXPECT_GE(s.resumePasses, 1u);
}

// A transfer function that shows different values is another scene: nothing is deferred on
// its first frame (what hid bricks before need not hide them now).
TEST(RayGuided, ANewTransferFunctionStartsWithoutDeferral) {
    auto t = phantomStore();
    const auto skin = opaqueSkin(t->stats);
    const auto bone = TransferFunction::preset("ct-bone", t->stats);
    const Box box = LevelGeometry::of(*t->store, 0).box;
    const PlanSize size = planSize(*t, skin, Camera::orbit(box, 0, 20));
    GpuRaycaster guided(budgetOf(*t, (size.entered * 3 / 2 + size.sampled) / 2));
    const Camera camera = Camera::orbit(box, 0, 20);
    FrameStats s;
    test::gpuFrame(*t, guided, skin, camera, frameOptions(true), &s);
    test::gpuFrame(*t, guided, skin, camera, frameOptions(true), &s);
    EXPECT_GT(s.bricksDeferred, 0u);
    test::gpuFrame(*t, guided, bone, camera, frameOptions(true), &s);
    EXPECT_EQ(s.bricksDeferred, 0u);
}

// A pool too small for even the bricks rays enter: deferral cannot make the frame fit, so it
// is drawn in batches as without it, with the same image.
TEST(RayGuided, PoolSmallerThanWhatRaysEnterFallsBackToBatches) {
    auto t = phantomStore();
    const auto tf = opaqueSkin(t->stats);
    const Box box = LevelGeometry::of(*t->store, 0).box;
    const PlanSize size = planSize(*t, tf, Camera::orbit(box, 0, 20));
    GpuRaycaster guided(budgetOf(*t, size.entered / 2)), plain(budgetOf(*t, size.entered / 2));
    const Camera camera = Camera::orbit(box, 0, 20);
    FrameStats s;
    for (int f = 0; f < 2; ++f) {
        const Image a = test::gpuFrame(*t, guided, tf, camera, frameOptions(true), &s);
        const Image b = test::gpuFrame(*t, plain, tf, camera, frameOptions(false));
        EXPECT_LE(compareImages(a, b).maxAbs, 1e-6) << "frame " << f;
    }
    EXPECT_GE(s.batches, 2u);
}

// Prefetch skips what the last frame found hidden; the frame after it loads no more at frame
// time than with a prefetch that loaded hidden bricks too.
TEST(RayGuided, PrefetchSkipsBricksBehindSaturatedRays) {
    auto t = phantomStore();
    const auto tf = opaqueSkin(t->stats);
    const Box box = LevelGeometry::of(*t->store, 0).box;
    const PlanSize size = planSize(*t, tf, Camera::orbit(box, 0, 20));
    const std::uint64_t slots = (size.entered * 3 / 2 + size.sampled) / 2;
    GpuRaycaster skips(budgetOf(*t, slots)), loadsAll(budgetOf(*t, slots));
    FrameStats s;
    std::uint64_t lastFrame = 0;
    for (double az : {0.0, 4.0}) {
        for (GpuRaycaster* r : {&skips, &loadsAll})
            test::gpuFrame(*t, *r, tf, Camera::orbit(box, az, 20), frameOptions(true), &s);
        lastFrame = residentBricks(s);
    }
    const auto room = std::uint32_t(skips.pool()->capacity() - lastFrame);
    const Camera next = Camera::orbit(box, 8.0, 20);
    ClassificationCache classifications;
    const Scene scene{*t->store, *t->cache, tf, classifications};
    const auto viewOf = [&](const RenderOptions& o) { return View::of(next, o.width, o.height); };
    const std::uint32_t a =
        skips.prefetch(scene, viewOf(frameOptions(true)), frameOptions(true), room);
    const std::uint32_t b =
        loadsAll.prefetch(scene, viewOf(frameOptions(false)), frameOptions(false), room);
    FrameStats sa, sb;
    const Image ia = test::gpuFrame(*t, skips, tf, next, frameOptions(true), &sa);
    const Image ib = test::gpuFrame(*t, loadsAll, tf, next, frameOptions(true), &sb);
    std::printf("[guided] prefetch of the next view: %u bricks skipping hidden ones, %u without; "
                "frame-time uploads after it %llu vs %llu\n",
                a, b, (unsigned long long)sa.bricksUploaded, (unsigned long long)sb.bricksUploaded);
    EXPECT_LT(a, b);
    EXPECT_LE(sa.bricksUploaded, sb.bricksUploaded);
    EXPECT_LE(compareImages(ia, ib).maxAbs, 1e-6);
}

} // namespace
} // namespace bc::render
