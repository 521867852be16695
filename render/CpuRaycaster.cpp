#include "render/CpuRaycaster.h"

#include "brickstore/BrickCache.h"
#include "brickstore/BrickStore.h"
#include "render/BrickPlan.h"
#include "render/Classification.h"
#include "render/Composite.h"
#include "render/FineOccupancy.h"
#include "render/Occupancy.h"
#include "render/Partition.h"
#include "render/TransferFunction.h"
#include "render/detail/CpuMarchSimd.h"
#include "render/detail/CpuRay.h"
#include "render/detail/CpuRaycastBatches.h"
#include "render/detail/CpuRaycastPass.h"
#include "render/detail/CpuRaycastRays.h"

#include <algorithm>
#include <chrono>
#include <cmath>
#include <limits>
#include <optional>
#include <vector>

namespace bc::render {
namespace {

/// Ray guidance: the bricks a frame loads come in about this many batches, of at least
/// kGuidedStepBricks bricks each (fewer batches cost fewer passes over the rays).
constexpr std::uint64_t kGuidedSteps = 16;
constexpr std::uint64_t kGuidedStepBricks = 16;

using Clock = std::chrono::steady_clock;
double msSince(Clock::time_point t) {
    return std::chrono::duration<double, std::milli>(Clock::now() - t).count();
}

using detail::BrickRef;
using detail::Frame;
using detail::RayCount;
using detail::RayStates;
using detail::Slot;

/// The pixels of `region` (image pixels) whose rays may meet a brick the plan draws: the
/// footprint of the drawn bricks' bounding box (render/Partition.h), within the region; not
/// visible when none is left. The rays of the other pixels could only miss every drawn brick.
Footprint raysToMarch(const LevelGeometry& g, const BrickPlan& plan, const View& view,
                      const PixelRect& region) {
    if (plan.drawn.empty()) return {};
    constexpr auto kMax = std::numeric_limits<std::uint32_t>::max();
    BrickBox box{{kMax, kMax, kMax}, {0, 0, 0}};
    for (const PlannedBrick& b : plan.drawn)
        for (int a = 0; a < 3; ++a) {
            box.lo[a] = std::min(box.lo[a], b.key.pos[a]);
            box.hi[a] = std::max(box.hi[a], b.key.pos[a] + 1);
        }
    const Footprint fp = footprint(g, box, view);
    const std::optional<PixelRect> in = fp.visible ? overlap(fp.rect, region) : std::nullopt;
    return in ? Footprint{*in, true} : Footprint{};
}

Frame frameOf(const LevelGeometry& g, const ViewBasis& view, const RenderOptions& o,
              const TransferFunctionTable& table) {
    Frame f;
    f.eye = glm::vec3(view.eye);
    f.forward = glm::vec3(view.forward);
    f.right = glm::vec3(view.right);
    f.up = glm::vec3(view.upScaled);
    f.ortho = view.orthographic;
    f.width = float(o.width);
    f.height = float(o.height);
    f.invSpacing = glm::vec3(1.0 / g.spacing);
    f.dims = glm::vec3(float(g.dims[0]), float(g.dims[1]), float(g.dims[2]));
    f.stepMm = float(o.stepVoxels * g.minSpacing());
    f.brick = int(g.brickVoxels);
    f.apron = int(g.apronVoxels);
    f.edge = f.brick + 2 * f.apron;
    f.grid = glm::ivec3(int(g.bricks[0]), int(g.bricks[1]), int(g.bricks[2]));
    f.tf = table.rgba.data();
    f.entries = int(table.entries);
    const double span = table.domainMax - table.domainMin, last = double(table.entries - 1);
    f.tfScale = float(last / span);
    f.tfOffset = float(-table.domainMin * last / span);
    f.ertT = o.earlyTermination ? float(1.0 - o.ertThreshold) : -1.0f;
    f.shading = o.shading;
    f.mode = o.mode;
    f.clip = ClipF::of(o.clip);
    f.iso = float(o.isoValue);
    f.capping = capsCuts(o);
    f.capPower = o.mode == BlendMode::Composite ? float(1.0 / o.stepVoxels) : 1.0f;
    f.simd = o.simd;
    f.packets = f.simd && o.packets && !o.preintegrate;
    f.jitter = o.jitter;
    f.running = runsSkip(o);
    f.segment = o.stepVoxels;
    f.gradScale = glm::vec3(0.5 / span * g.minSpacing() / g.spacing);
    return f;
}

/// Every brick of the level: what it draws and in which batch (`ends` as planBatches gives),
/// and under a running skip (f.running) the bound on its values that the mode compares.
std::vector<BrickRef> brickRefs(const brickstore::BrickStore& store, const BrickPlan& plan,
                                const std::vector<std::size_t>& ends, std::uint64_t brickCount,
                                const Frame& f) {
    std::vector<BrickRef> bricks(std::max<std::uint64_t>(brickCount, 1));
    for (std::size_t batch = 0, i = 0; batch < ends.size(); ++batch)
        for (; i < ends[batch]; ++i) {
            const PlannedBrick& b = plan.drawn[i];
            BrickRef& ref = bricks[b.index];
            ref.batch = std::uint32_t(batch);
            ref.slot = b.draw == BrickDraw::Constant ? Slot::Constant : Slot::Sampled;
            ref.constant = b.constantValue;
            if (!f.running) continue;
            const brickstore::ValueRange r = store.record(b.key).range;
            ref.bound = interpolatedBound(f.mode == BlendMode::Maximum, r.min, r.max);
        }
    return bricks;
}

/// The bricks of `level` the frame draws, recorded in `stats`.
BrickPlan planOf(const brickstore::BrickStore& store, const LevelGeometry& g, std::uint32_t level,
                 const FrameClassification& classified, const View& view,
                 const RenderOptions& options, PartitionCache& partitions, FrameStats& stats) {
    // A slice (options.region) plans the bricks its own rays reach: under a host budget the
    // frame's slices then load each brick about once, not once per slice.
    // Under pre-integration a segment may run from a drawn brick into a transparent one,
    // whose value it reads: transparent bricks next to drawn ones are drawn too.
    const auto keepNear =
        options.preintegrate
            ? std::max(1u, std::uint32_t(std::ceil(options.stepVoxels / g.brickVoxels)))
            : 0u;
    BrickPlan plan = planBricks(store, g, *classified.skipTable, view, options.region, options.skip,
                                classified.occupancy, keepNear);
    if (options.parts > 1) // only this part's bricks: the others' samples are theirs
        keepOwned(plan, partitions.get(store, level, options.parts).region(options.part));
    if (options.clip.any()) keepInside(plan, g, options.clip); // neither loaded nor drawn
    recordPlan(plan, level, stats);
    return plan;
}

/// How a frame's plan is drawn: in batches, and what the cache keeps of its bricks.
struct Batches {
    std::vector<std::size_t> ends;       ///< each batch's end in plan.drawn (planBatches)
    std::vector<std::uint8_t> unreached; ///< per planned brick: left out by ray guidance
    bool guided = false;                 ///< ray guidance on
    std::uint64_t keepBytes = 0;         ///< the most of the frame's bricks the cache keeps
};

/// The batches `plan` is drawn in under the host cache's budget.
Batches batchesOf(const brickstore::BrickStore& store, const brickstore::BrickCache& cache,
                  const LevelGeometry& g, const BrickPlan& plan, const RenderOptions& options) {
    // Batches of the front-to-back order whose bricks fit the host budget, drawn one after
    // the other, each pinned only while it is drawn (the cache can then evict behind it).
    // Ray guidance: the bricks to load come in about kGuidedSteps batches, and a later batch's
    // bricks that no ray still marching can enter are left out (markUnreached). Only where the
    // level outgrows the budget: where it fits, a brick loaded stays, and the next frames of a
    // moving camera reach the bricks this frame's rays did not (left out, each would be loaded
    // by a later frame of the flight instead of this one).
    Batches b;
    const std::uint64_t budget = cache.stats().budgetBytes; // one read: the daemon may change it
    b.guided = options.rayGuided && g.brickCount() * store.brickBytes() > budget;
    std::uint64_t toLoad = 0;
    const std::vector<std::uint8_t> missing =
        b.guided ? detail::missingBricks(plan, cache, toLoad) : std::vector<std::uint8_t>{};
    const std::uint64_t loadStep =
        b.guided
            ? std::max(toLoad / kGuidedSteps, std::uint64_t(kGuidedStepBricks)) * store.brickBytes()
            : 0;
    b.ends = planBatches(plan, store.brickBytes(), budget, missing, loadStep);
    b.unreached.assign(plan.drawn.size(), 0);
    // A frame whose bricks outgrow the budget streams them: it keeps its front bricks (with
    // its earlier slices'), as many as leave room for two batches of loads, and lets the
    // others go first when the cache needs room. The next pass of this view (or of one near
    // it) then starts on resident bricks; under plain LRU each brick would be evicted just
    // before that pass wanted it.
    const std::uint64_t room = 2 * std::max(loadStep, kGuidedStepBricks * store.brickBytes());
    b.keepBytes = budget - std::min(budget, room);
    return b;
}

/// Points `f` at the octrees' words and boxes (when they have levels below the brick and some
/// drawn brick of `plan` is not drawn whole: else they would leap over nothing) and at the
/// distance maps of the classification's octrees; returns those maps, null when none. Under a
/// running skip, points it at the leaves' bounds.
FineOccupancy* useOccupancy(Frame& f, const FrameClassification& classified,
                            const RenderOptions& options, const BrickPlan& plan) {
    const OccupancyTrees* occupancy = classified.occupancy;
    const bool octree = occupancy != nullptr;
    if (octree && occupancy->depth() > 0) {
        f.octDepth = int(occupancy->depth());
        f.leafAxis = int(occupancy->leavesPerAxis());
        f.leaf = float(occupancy->leafVoxels());
        const bool leaps = std::any_of(plan.drawn.begin(), plan.drawn.end(), [&](const auto& b) {
            return b.draw == BrickDraw::Sampled && !occupancy->drawnWhole(b.index);
        });
        if (leaps) {
            f.occ = occupancy->words().data();
            f.occWords = int(occupancy->wordsPerBrick());
            f.boxes = occupancy->sampledBoxes().data();
        }
        if (f.running) {
            f.leafBound = occupancy->leafBounds(f.mode == BlendMode::Maximum).data();
            f.leafCount = f.leafAxis * f.leafAxis * f.leafAxis;
        }
    }
    FineOccupancy* fine = f.occ && classified.classification
                              ? classified.classification->fine(options.cellVoxels)
                              : nullptr;
    if (fine) {
        f.fine = fine->pool();
        f.cell = float(fine->cellVoxels());
        f.cellAxis = int(fine->cellsPerAxis());
    }
    return fine;
}

/// The rays marched, of `region` (rays, not image pixels): only those that may meet a drawn
/// brick (the others stay transparent black); without skipping every ray is, the reference of
/// the skipping invariant.
Footprint marchedRays(const LevelGeometry& g, const BrickPlan& plan, const View& view,
                      const RenderOptions& options, PixelLattice lattice, const PixelRect& region) {
    Footprint marched{region, region.pixels() > 0};
    if (options.skip != SkipMode::None) {
        const Footprint reach = raysToMarch(g, plan, view, options.drawn());
        const std::optional<PixelRect> rays = reach.visible ? lattice.of(reach.rect) : std::nullopt;
        marched = rays ? Footprint{*rays, true} : Footprint{};
    }
    return marched;
}

/// Lets a drawn batch's pins go: its bricks stay hot in the cache while the kept ones
/// (`keptBytes`, the earlier slices' included) fit `keepBytes`; the others are released cold,
/// to go first when the cache needs room.
void letGo(std::vector<brickstore::BrickPin>& pins, std::uint64_t brickBytes,
           std::uint64_t keepBytes, std::uint64_t& keptBytes) {
    for (brickstore::BrickPin& pin : pins) {
        if (!pin) continue;
        if (keptBytes + brickBytes <= keepBytes) {
            keptBytes += brickBytes;
            pin = {};
        } else {
            pin.releaseCold();
        }
    }
}

/// The passes of a frame, one per batch, over its rays: one per pixel of the region, or of its
/// lattice under a stride (validate() keeps the lattice from being empty). mRegion and mMarched
/// number them, not image pixels. Every ray carries its colour and its place in the brick grid
/// from pass to pass.
class FramePasses {
  public:
    FramePasses(const Scene& scene, const View& view, const RenderOptions& options,
                const LevelGeometry& g, const BrickPlan& plan, Frame& f,
                std::vector<BrickRef>& bricks, FineOccupancy* fine)
        : mStore(scene.store), mCache(scene.cache), mView(view), mG(g), mPlan(plan), mF(f),
          mBricks(bricks), mFine(fine), mLattice(options.lattice()),
          mRegion(*mLattice.of(options.drawn())),
          mMarched(marchedRays(g, plan, view, options, mLattice, mRegion)), mRays(mRegion.pixels()),
          mFronts(f.pre ? mRegion.pixels() : 0) {}

    /// Draws the batches in order, each pinned only while its pass runs; returns the bytes of
    /// bricks kept, `keptBytes` (the earlier slices') included.
    std::uint64_t draw(Batches& b, std::uint64_t keptBytes, FrameStats& stats) {
        for (std::size_t batch = 0, first = 0; batch < b.ends.size(); first = b.ends[batch++]) {
            // A maximum's or minimum's segment end may lie in a brick that only a ray done
            // with its lattice still needs (samplesEnds()), a cut's face in one that no ray's
            // lattice enters (capping): those frames load every brick.
            if (b.guided && batch > 0 && mMarched.visible && !samplesEnds(mF.mode) && !mF.capping)
                stats.bricksUnreached += detail::markUnreached(
                    mG, mPlan, first, b.ends[batch], mView, mF,
                    detail::MarchingRays(mRays, mLattice, mRegion, mMarched.rect), b.unreached);
            std::vector<brickstore::BrickPin> pins = load(first, b.ends[batch], b.unreached, stats);
            march(std::uint32_t(batch), stats);
            letGo(pins, mStore.brickBytes(), b.keepBytes, keptBytes);
        }
        return keptBytes;
    }
    const RayCount& count() const { return mCount; }
    /// The region's image; clamped to [0, 1] unless `clamp` is false, a projection's raw
    /// pixels when `raw` (imageOf).
    Image image(bool clamp, bool raw) const {
        Footprint local = mMarched; // in the region's coordinates
        local.rect.x -= mRegion.x;
        local.rect.y -= mRegion.y;
        return detail::imageOf(mRays, mRegion.width, mRegion.height, local, clamp, raw);
    }

  private:
    /// Pins plan.drawn[first, end) but the unreached, with their distance maps.
    std::vector<brickstore::BrickPin> load(std::size_t first, std::size_t end,
                                           const std::vector<std::uint8_t>& unreached,
                                           FrameStats& stats) {
        const auto loadStart = Clock::now();
        std::vector<brickstore::BrickPin> pins =
            detail::pinBatch(mPlan, first, end, unreached, mCache, mBricks);
        stats.uploadMs += msSince(loadStart);
        if (mFine)
            detail::cellsOfBatch(mPlan, first, end, unreached, *mFine, mStore.info().volume.type,
                                 mF, mBricks, stats);
        return pins;
    }
    void march(std::uint32_t batch, FrameStats& stats) {
        const auto renderStart = Clock::now();
        mF.batch = batch;
        if (mMarched.visible)
            detail::marchPass(mStore.info().volume.type, mF, mLattice, mRegion, mMarched.rect,
                              mRays, mFronts, mCount);
        stats.renderMs += msSince(renderStart);
    }

    const brickstore::BrickStore& mStore;
    brickstore::BrickCache& mCache;
    const View& mView;
    const LevelGeometry& mG;
    const BrickPlan& mPlan;
    Frame& mF;
    std::vector<BrickRef>& mBricks;
    FineOccupancy* const mFine;
    const PixelLattice mLattice;
    const PixelRect mRegion;
    const Footprint mMarched;
    RayStates mRays;
    std::vector<detail::Front> mFronts;
    RayCount mCount;
};

} // namespace

CpuRaycaster::CpuRaycaster() = default;

std::string CpuRaycaster::simdTarget() {
    return detail::simdTargetName() + " x" + std::to_string(detail::simdLanes());
}
CpuRaycaster::~CpuRaycaster() = default;

Image CpuRaycaster::render(const Scene& scene, const View& view, const RenderOptions& options,
                           FrameStats& stats) {
    const auto frameStart = Clock::now();
    options.validate();
    checkView(view, options, true, true, true);
    stats = FrameStats{};
    const brickstore::BrickStore& store = scene.store;
    const auto levels = std::uint32_t(store.layout().levels().size());
    const std::uint32_t level = std::min<std::uint32_t>(std::uint32_t(options.level), levels - 1);
    const LevelGeometry g = LevelGeometry::of(store, level);
    const FrameClassification classified =
        classifyFrame(scene, level, options, options.stepVoxels, stats);
    const BrickPlan plan = planOf(store, g, level, classified, view, options, mPartitions, stats);
    Batches batches = batchesOf(store, scene.cache, g, plan, options);
    stats.batches = std::uint32_t(batches.ends.size());
    Frame f = frameOf(g, view.basis, options, *classified.table);
    std::vector<BrickRef> bricks = brickRefs(store, plan, batches.ends, g.brickCount(), f);
    const std::vector<float> tfPairs = detail::tfPairTable(f.tf, f.entries);
    f.tfPairs = tfPairs.data();
    f.bricks = bricks.data();
    f.pre = classified.preintegrated.get();
    FineOccupancy* fine = useOccupancy(f, classified, options, plan);

    FramePasses passes(scene, view, options, g, plan, f, bricks, fine);
    stats.hostKeptBytes =
        passes.draw(batches, options.hostKeptBefore, stats) - options.hostKeptBefore;
    stats.samples = passes.count().samples;
    stats.octreeLeaps = passes.count().leaps;
    stats.samplesRaising = passes.count().raises;
    stats.occlusionReason = "not on the CPU raycaster";
    stats.totalMs = msSince(frameStart);
    // A projection's parts stay raw: they combine by their mode (render/Composite.h).
    const bool projection = isProjection(options.mode);
    Image image = passes.image(options.parts == 1, projection);
    if (projection && options.parts == 1)
        resolveProjections(image, options.mode, *classified.table);
    return image;
}

} // namespace bc::render
