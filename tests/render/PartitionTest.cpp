// Sort-last scale-out's rendering core: the k-d split of a brick grid into parts,
// their front-to-back order, their footprints, and the CPU raycaster drawing one part's
// samples: the parts' frames composited front to back give the one-part frame (within float
// rounding, measured under 1e-6; early termination's bound with it on), and the parts take
// exactly its samples.
#include "render/Partition.h"
#include "RenderTestSupport.h"
#include "render/Composite.h"

#include <random>

#include <glm/geometric.hpp>

namespace bc::render {
namespace {

using Grid = std::array<std::uint32_t, 3>;

std::vector<std::uint64_t> randomWeights(const Grid& grid, std::uint32_t seed, double emptyShare) {
    std::mt19937 rng(seed);
    std::uniform_real_distribution<double> u(0.0, 1.0);
    std::vector<std::uint64_t> w(std::uint64_t{grid[0]} * grid[1] * grid[2]);
    for (auto& v : w)
        v = u(rng) < emptyShare ? 0 : 1000 + std::uint64_t(u(rng) * 9000);
    return w;
}

/// Every brick lies in exactly one part's box, and each part's weight is its bricks'.
void expectATiling(const Partition& p, const Grid& grid, const std::vector<std::uint64_t>& w) {
    std::vector<std::uint64_t> weight(p.parts(), 0);
    Grid pos{};
    for (pos[2] = 0; pos[2] < grid[2]; ++pos[2])
        for (pos[1] = 0; pos[1] < grid[1]; ++pos[1])
            for (pos[0] = 0; pos[0] < grid[0]; ++pos[0]) {
                int owners = 0;
                for (std::uint32_t i = 0; i < p.parts(); ++i)
                    if (p.region(i).contains(pos)) {
                        ++owners;
                        weight[i] +=
                            w[(std::uint64_t(pos[2]) * grid[1] + pos[1]) * grid[0] + pos[0]];
                    }
                ASSERT_EQ(owners, 1) << "brick " << pos[0] << "," << pos[1] << "," << pos[2];
            }
    for (std::uint32_t i = 0; i < p.parts(); ++i)
        EXPECT_EQ(p.weight(i), weight[i]) << "part " << i;
}

TEST(Partition, TilesTheGridForEveryPartCount) {
    for (const Grid grid : {Grid{8, 8, 4}, Grid{5, 3, 7}, Grid{1, 1, 9}, Grid{16, 1, 1}})
        for (std::uint32_t parts : {1u, 2u, 3u, 4u, 5u, 7u, 8u, 16u})
            for (std::uint32_t seed : {1u, 2u}) {
                const auto w = randomWeights(grid, seed, 0.4);
                const Partition p = Partition::split(grid, w, parts);
                ASSERT_EQ(p.parts(), parts);
                expectATiling(p, grid, w);
            }
}

TEST(Partition, BalancesEqualWeightsExactlyWhereTheGridAllows) {
    const Grid grid{8, 8, 8};
    const std::vector<std::uint64_t> w(512, 7);
    for (std::uint32_t parts : {2u, 4u, 8u, 16u, 64u}) {
        const Partition p = Partition::split(grid, w, parts);
        for (std::uint32_t i = 0; i < parts; ++i)
            EXPECT_EQ(p.region(i).count(), 512u / parts) << parts << " parts, part " << i;
    }
}

TEST(Partition, BalancesByWeightNotByBricks) {
    // The weight sits in the low half of x (the high half is of one value, weight 0): two
    // parts split the low half, not the grid.
    const Grid grid{16, 4, 4};
    std::vector<std::uint64_t> w(16 * 4 * 4, 0);
    for (std::uint32_t z = 0; z < 4; ++z)
        for (std::uint32_t y = 0; y < 4; ++y)
            for (std::uint32_t x = 0; x < 8; ++x)
                w[(z * 4 + y) * 16 + x] = 100;
    const Partition p = Partition::split(grid, w, 2);
    EXPECT_EQ(p.weight(0), p.weight(1));
    // Random weights: the heaviest part is within one slab's weight of the mean.
    const Grid big{24, 20, 16};
    for (std::uint32_t parts : {2u, 3u, 4u, 6u}) {
        const auto rw = randomWeights(big, 7, 0.5);
        const Partition q = Partition::split(big, rw, parts);
        std::uint64_t total = 0, heaviest = 0;
        for (std::uint32_t i = 0; i < parts; ++i) {
            total += q.weight(i);
            heaviest = std::max(heaviest, q.weight(i));
        }
        const double mean = double(total) / parts;
        EXPECT_LT(double(heaviest), 1.1 * mean) << parts << " parts";
    }
}

TEST(Partition, MorePartsThanBricksLeavesPartsEmpty) {
    const Grid grid{2, 1, 2};
    const std::vector<std::uint64_t> w(4, 1);
    const Partition p = Partition::split(grid, w, 7);
    std::uint32_t empty = 0;
    for (std::uint32_t i = 0; i < 7; ++i) {
        if (p.region(i).empty())
            ++empty;
        else
            EXPECT_EQ(p.region(i).count(), 1u);
    }
    EXPECT_EQ(empty, 3u);
    expectATiling(p, grid, w);
    // All weight 0 (every brick of one value): split by bricks.
    const Partition z = Partition::split({4, 4, 4}, std::vector<std::uint64_t>(64, 0), 4);
    for (std::uint32_t i = 0; i < 4; ++i)
        EXPECT_EQ(z.region(i).count(), 16u);
}

TEST(Partition, RefusesBadArguments) {
    const std::vector<std::uint64_t> w(8, 1);
    EXPECT_THROW(Partition::split({2, 2, 2}, w, 0), std::invalid_argument);
    EXPECT_THROW(Partition::split({2, 2, 2}, w, Partition::kMaxParts + 1), std::invalid_argument);
    EXPECT_THROW(Partition::split({2, 2, 3}, w, 2), std::invalid_argument);
    EXPECT_THROW(Partition::split({0, 2, 2}, {}, 2), std::invalid_argument);
    RenderOptions o;
    o.parts = 2;
    o.part = 2;
    EXPECT_THROW(o.validate(), std::invalid_argument);
    o.parts = 0;
    o.part = 0;
    EXPECT_THROW(o.validate(), std::invalid_argument);
}

/// A level of `dims` voxels in bricks of `brick`, spacing `spacing`.
LevelGeometry geometryOf(std::array<std::uint64_t, 3> dims, std::uint32_t brick,
                         glm::dvec3 spacing) {
    LevelGeometry g;
    g.dims = dims;
    g.spacing = spacing;
    g.brickVoxels = brick;
    for (int a = 0; a < 3; ++a) {
        g.bricks[a] = std::uint32_t((dims[a] + brick - 1) / brick);
        g.box.min[a] = 0.0;
        g.box.max[a] = double(dims[a]) * spacing[a];
    }
    return g;
}

std::vector<Camera> testCameras(const Box& box) {
    std::vector<Camera> cams;
    for (double az : {0.0, 30.0, 135.0, 250.0})
        for (double el : {-60.0, 10.0, 80.0})
            cams.push_back(Camera::orbit(box, az, el));
    Camera inside; // inside the volume, looking across it
    inside.eye = box.min + (box.max - box.min) * glm::dvec3(0.3, 0.6, 0.45);
    inside.target = box.max;
    inside.up = {0, 0, 1};
    inside.fovYDeg = 70;
    cams.push_back(inside);
    Camera ortho = Camera::orbit(box, 60, 25);
    ortho.orthographic = true;
    ortho.orthoHeight = glm::length(box.max - box.min);
    cams.push_back(ortho);
    return cams;
}

// Along every ray the parts it meets come in frontToBack's order, and every pixel whose ray
// meets a part's box lies in the part's footprint.
TEST(Partition, RaysMeetThePartsInTheirOrderInsideTheirFootprints) {
    const LevelGeometry g = geometryOf({150, 100, 70}, 16, {1.0, 1.3, 2.0});
    const auto w = randomWeights(g.bricks, 3, 0.3);
    for (std::uint32_t parts : {2u, 3u, 5u, 8u}) {
        const Partition p = Partition::split(g.bricks, w, parts);
        for (const Camera& cam : testCameras(g.box)) {
            const std::uint32_t size = 48;
            const View view = View::of(cam, size, size);
            const auto order = p.frontToBack(g, view.basis);
            std::vector<int> rank(parts, -1);
            for (std::size_t i = 0; i < order.size(); ++i)
                rank[order[i]] = int(i);
            std::vector<Footprint> feet(parts);
            for (std::uint32_t i = 0; i < parts; ++i)
                feet[i] = footprint(g, p.region(i), view);
            for (std::uint32_t y = 0; y < size; ++y)
                for (std::uint32_t x = 0; x < size; ++x) {
                    const Ray ray = view.basis.ray(x, y, size, size);
                    for (std::uint32_t i = 0; i < parts; ++i) {
                        const auto [t0, t1] = intersectBox(ray, worldBox(g, p.region(i)));
                        if (!(std::max(t0, 0.0) < t1)) continue;
                        ASSERT_TRUE(feet[i].visible) << "part " << i;
                        const PixelRect& r = feet[i].rect;
                        EXPECT_TRUE(x >= r.x && x < r.x + r.width && y >= r.y && y < r.y + r.height)
                            << "pixel " << x << "," << y << " part " << i;
                    }
                    // Walk the ray: the part of each point never goes back in the order.
                    const auto [e0, e1] = intersectBox(ray, g.box);
                    int last = -1;
                    for (int k = 0; k < 400; ++k) {
                        const double t =
                            std::max(e0, 0.0) + (e1 - std::max(e0, 0.0)) * (k + 0.5) / 400;
                        if (!(t < e1)) break;
                        const glm::dvec3 q = ray.origin + ray.direction * t;
                        Grid pos;
                        for (int a = 0; a < 3; ++a)
                            pos[a] = std::min(
                                g.bricks[a] - 1,
                                std::uint32_t(std::max(
                                    0.0, std::floor(q[a] / g.spacing[a] / g.brickVoxels))));
                        for (std::uint32_t i = 0; i < parts; ++i)
                            if (p.region(i).contains(pos)) {
                                ASSERT_GE(rank[i], last) << "pixel " << x << "," << y;
                                last = rank[i];
                            }
                    }
                }
        }
    }
}

/// The frame of `parts` parts, each drawn by `renderer` over its footprint and composited
/// front to back; `samples`: the parts' samples together.
Image partsFrame(Renderer& renderer, test::TestStore& t, const TransferFunction& tf,
                 const Camera& cam, const RenderOptions& o, std::uint32_t parts,
                 std::uint64_t& samples) {
    const LevelGeometry g = LevelGeometry::of(*t.store, 0);
    const Partition p = Partition::ofLevel(*t.store, 0, parts);
    const View view = View::of(cam, o.width, o.height);
    std::vector<PartialImage> images;
    samples = 0;
    for (std::uint32_t part : p.frontToBack(g, view.basis)) {
        const Footprint f = footprint(g, p.region(part), view);
        if (!f.visible) continue;
        RenderOptions po = o;
        po.parts = parts;
        po.part = part;
        po.region = f.rect;
        FrameStats stats;
        images.push_back({f.rect, renderer.render(*t.store, *t.cache, tf, cam, po, stats)});
        samples += stats.samples;
    }
    const PartsCombine how = combineFor(o.mode);
    Image frame = compositeFrontToBack(o.width, o.height, images, how);
    if (how != PartsCombine::Over) // a projection's combined values: the table's colours
        resolveProjections(frame, o.mode, tf.table(1.0, kClassificationTableEntries));
    return frame;
}

Image partsFrame(test::TestStore& t, const TransferFunction& tf, const Camera& cam,
                 const RenderOptions& o, std::uint32_t parts, std::uint64_t& samples) {
    CpuRaycaster raycaster;
    return partsFrame(raycaster, t, tf, cam, o, parts, samples);
}

// The other modes: the projections' parts combine by max, min and sums, the isosurface's over
// (the front-most hit), whole and cut, to the one-part frame.
TEST(PartitionFrames, EveryModesPartsCombineToTheOnePartFrame) {
    auto t = test::ingestRealScan("cthead");
    if (!t) return test::missingData("scan cthead");
    const LevelGeometry g = LevelGeometry::of(*t->store, 0);
    const auto bone = TransferFunction::preset("ct-bone", t->stats);
    const auto ramp = test::greyRamp(t->stats);    // the average's radiograph
    const auto low = TransferFunction::fromPoints( // the minimum's: opaque at the lowest values
        {{Placement::Value, t->stats.valueMin, {1, 1, 1, 1}},
         {Placement::Value, t->stats.valueMax, {0, 0, 0, 0}}},
        "low", t->stats);
    const Camera cam = testCameras(g.box)[3];
    for (const BlendMode mode :
         {BlendMode::Maximum, BlendMode::Minimum, BlendMode::Average, BlendMode::Isosurface})
        for (const bool cut : {false, true}) {
            const TransferFunction& tf = mode == BlendMode::Average   ? ramp
                                         : mode == BlendMode::Minimum ? low
                                                                      : bone;
            RenderOptions o;
            o.width = o.height = 80;
            o.mode = mode;
            o.isoValue = 0.4 * (tf.domainMin() + tf.domainMax());
            if (cut) {
                o.clip.cropped = true;
                o.clip.cropMin = {20, 10, 30};
                o.clip.cropMax = {230, 240, 200};
                o.clip.planeCount = 1;
                o.clip.planes[0] = {{-1, 0.2, 0.3}, 170};
            }
            FrameStats whole;
            const Image one = test::cpuFrame(*t, tf, cam, o, &whole);
            for (std::uint32_t parts : {2u, 5u}) {
                std::uint64_t samples = 0;
                const Image composited = partsFrame(*t, tf, cam, o, parts, samples);
                // The average's sums add in another order: within float rounding.
                EXPECT_LE(compareImages(one, composited).maxAbs,
                          mode == BlendMode::Average ? 1e-5 : 0.0)
                    << toString(mode) << (cut ? " cut, " : ", ") << parts << " parts";
                EXPECT_GT(test::alphaSum(composited), 1.0) << toString(mode);
            }
        }
}

// Capped cuts (render/MODES.md "Capping"): a face is drawn by the part whose brick holds it, in
// front of that part's segment, so the parts still composite to the one-part frame.
TEST(PartitionFrames, CappedPartsCombineToTheOnePartFrame) {
    auto t = test::ingestRealScan("cthead");
    if (!t) return test::missingData("scan cthead");
    const LevelGeometry g = LevelGeometry::of(*t->store, 0);
    const auto bone = TransferFunction::preset("ct-bone", t->stats);
    const Camera cam = testCameras(g.box)[3];
    for (const BlendMode mode : {BlendMode::Composite, BlendMode::Isosurface}) {
        RenderOptions o;
        o.width = o.height = 80;
        o.mode = mode;
        o.earlyTermination = false;
        o.isoValue = 0.4 * (bone.domainMin() + bone.domainMax());
        o.clip.cropped = true;
        o.clip.cropMin = {20, 10, 30};
        o.clip.cropMax = {230, 240, 200};
        o.clip.planeCount = 1;
        o.clip.planes[0] = {{-1, 0.2, 0.3}, 170};
        o.clip.cap = true;
        FrameStats whole;
        const Image one = test::cpuFrame(*t, bone, cam, o, &whole);
        RenderOptions uncapped = o;
        uncapped.clip.cap = false;
        EXPECT_GT(compareImages(one, test::cpuFrame(*t, bone, cam, uncapped)).maxAbs, 0.05)
            << toString(mode) << ": the faces must show";
        for (std::uint32_t parts : {2u, 5u}) {
            std::uint64_t samples = 0;
            const Image composited = partsFrame(*t, bone, cam, o, parts, samples);
            if (mode == BlendMode::Composite) // an isosurface's parts behind a hit still march
                EXPECT_EQ(samples, whole.samples) << parts << " parts";
            EXPECT_LE(compareImages(one, composited).maxAbs, 1e-5)
                << toString(mode) << ", " << parts << " parts";
        }
    }
    // Each part in batches of one brick: a ray whose part holds its face but none of its
    // samples is done with its march before the face's batch, and still draws the face (on
    // this phantom and view, pixel (22, 32) of 72^2 is such a ray).
    auto source = brickstore::makeSynthetic(brickstore::SynthKind::Phantom, {96, 96, 96}, 1);
    auto p = test::ingestStore(*source, {32, 2, 8});
    p->cache = std::make_unique<brickstore::BrickCache>(
        *p->store, brickstore::BrickCacheConfig{p->store->brickBytes()});
    const auto ramp = test::greyRamp(p->stats);
    RenderOptions o;
    o.width = o.height = 72;
    o.earlyTermination = false;
    o.jitter = true;
    o.clip.cropped = true;
    o.clip.cropMin = {9.6, 9.6, 9.6};
    o.clip.cropMax = {76.8, 76.8, 76.8};
    o.clip.planeCount = 1;
    o.clip.planes[0] = {{1, 0.3, 0}, -38.4};
    o.clip.cap = true;
    const Camera orbit = Camera::orbit(LevelGeometry::of(*p->store, 0).box, 160.0, 20.0);
    FrameStats batched;
    const Image one = test::cpuFrame(*p, ramp, orbit, o, &batched);
    EXPECT_GE(batched.batches, 4u);
    std::uint64_t samples = 0;
    EXPECT_LE(compareImages(one, partsFrame(*p, ramp, orbit, o, 2, samples)).maxAbs, 1e-5)
        << "2 parts in batches";
}

TEST(PartitionFrames, PartsCompositeToTheOnePartFrameWithItsSamples) {
    auto t = test::ingestRealScan("cthead");
    if (!t) return test::missingData("scan cthead");
    const LevelGeometry g = LevelGeometry::of(*t->store, 0);
    for (const char* preset : {"ct-skin", "ct-bone"}) {
        const auto tf = TransferFunction::preset(preset, t->stats);
        auto cams = testCameras(g.box);
        cams = {cams[1], cams[8], cams[cams.size() - 2], cams.back()};
        for (const Camera& cam : cams)
            for (std::uint32_t parts : {2u, 3u, 4u, 7u}) {
                RenderOptions o;
                o.width = o.height = 96;
                o.earlyTermination = false;
                FrameStats whole;
                const Image one = test::cpuFrame(*t, tf, cam, o, &whole);
                std::uint64_t samples = 0;
                const Image composited = partsFrame(*t, tf, cam, o, parts, samples);
                // The parts took exactly the one-part frame's samples...
                EXPECT_EQ(samples, whole.samples) << preset << ", " << parts << " parts";
                // ...and their segments composite to its image within float rounding.
                const double diff = compareImages(one, composited).maxAbs;
                std::printf("%s %d parts: max abs %.3g\n", preset, int(parts), diff);
                EXPECT_LE(diff, 1e-5) << preset << ", " << parts << " parts";
                // Pre-integration: a part's first segment reads the sample before it from
                // the brick's apron, the value the one-part march had.
                RenderOptions pre = o;
                pre.preintegrate = true;
                std::uint64_t preSamples = 0;
                const Image preOne = test::cpuFrame(*t, tf, cam, pre);
                EXPECT_LE(
                    compareImages(preOne, partsFrame(*t, tf, cam, pre, parts, preSamples)).maxAbs,
                    1e-5)
                    << preset << ", " << parts << " parts, pre-integrated";
                // With early termination each part stops its own segment at the threshold:
                // within its bound of the full image, as one part is.
                o.earlyTermination = true;
                std::uint64_t ertSamples = 0;
                const Image ert = partsFrame(*t, tf, cam, o, parts, ertSamples);
                EXPECT_LE(compareImages(one, ert).maxAbs,
                          1.25 * (1.0 - o.ertThreshold) + 1.0 / 255.0)
                    << preset << ", " << parts << " parts";
                EXPECT_LE(ertSamples, samples);
            }
    }
}

// The GPU raycaster draws parts the same way (its shader walks the same brick grid): the parts
// take its samples and composite to its frame. Occlusion frustums and ray guidance stay on:
// each part keeps its own.
TEST(PartitionFramesGl, GpuPartsCompositeToTheOnePartFrameWithItsSamples) {
    auto t = test::ingestRealScan("headsq");
    if (!t) return test::missingData("scan headsq");
    test::glContext();
    const auto tf = TransferFunction::preset("ct-bone", t->stats);
    const LevelGeometry g = LevelGeometry::of(*t->store, 0);
    GpuRaycaster whole, parted;
    for (const double az : {30.0, 200.0})
        for (std::uint32_t parts : {2u, 3u}) {
            const Camera cam = Camera::orbit(g.box, az, 20);
            RenderOptions o;
            o.width = o.height = 64;
            o.earlyTermination = false;
            FrameStats one;
            const Image a = test::gpuFrame(*t, whole, tf, cam, o, &one);
            std::uint64_t samples = 0;
            for (int frame = 0; frame < 2; ++frame) { // the second with the first's frustums
                const Image b = partsFrame(parted, *t, tf, cam, o, parts, samples);
                EXPECT_EQ(samples, one.samples) << parts << " parts, frame " << frame;
                EXPECT_LE(compareImages(a, b).maxAbs, 1e-5) << parts << " parts, frame " << frame;
            }
        }
}

TEST(PartitionFrames, RenderersThatDrawWholeVolumesRefuseParts) {
    auto t = test::ingestRealScan("headsq");
    if (!t) return test::missingData("scan headsq");
    const auto tf = TransferFunction::preset("ct-skin", t->stats);
    RenderOptions o;
    o.width = o.height = 32;
    o.parts = 2;
    o.part = 1;
    ReferenceRenderer reference;
    FrameStats stats;
    const Camera cam = Camera::orbit(LevelGeometry::of(*t->store, 0).box, 30, 20);
    EXPECT_THROW(reference.render(*t->store, *t->cache, tf, cam, o, stats), std::invalid_argument);
    // A part of a volume smaller than one brick per part: the extra parts draw nothing.
    o.parts = 64;
    const Partition p = Partition::ofLevel(*t->store, 0, 64);
    std::uint32_t empty = 0;
    for (std::uint32_t i = 0; i < 64; ++i)
        if (p.region(i).empty()) {
            ++empty;
            o.part = i;
            const Image image = test::cpuFrame(*t, tf, cam, o, &stats);
            EXPECT_EQ(stats.samples, 0u);
            EXPECT_EQ(test::alphaSum(image), 0.0);
        }
    EXPECT_GT(empty, 0u); // headsq is 2x2x3 bricks of 32
}

} // namespace
} // namespace bc::render
