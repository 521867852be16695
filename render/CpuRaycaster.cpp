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

#include <tbb/blocked_range.h>
#include <tbb/blocked_range2d.h>
#include <tbb/parallel_for.h>

#include <algorithm>
#include <atomic>
#include <chrono>
#include <cmath>
#include <limits>
#include <memory>
#include <optional>
#include <type_traits>

#include <glm/geometric.hpp>
#include <glm/vec2.hpp>

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

using detail::Accum;
using detail::BrickRef;
using detail::Frame;
using detail::RayCount;
using detail::RayResume;
using detail::RayState;
using detail::Rgba;
using detail::Slot;

/// The region's ray states, left unconstructed here: the pass's workers construct each on
/// batch 0 as they first touch it (marchPass; planBatches always gives a batch 0, every pixel
/// of the region in it), so a 512² frame's 5 MB is not written twice, once by one thread.
/// Beside them the rays' resume data (RayResume), written only by rays that stop to wait for a
/// later batch: a frame of one batch never touches it.
class RayStates {
  public:
    explicit RayStates(std::size_t n)
        : mData(std::allocator<RayState>().allocate(n)),
          mResume(std::allocator<RayResume>().allocate(n)), mSize(n) {}
    ~RayStates() {
        std::allocator<RayState>().deallocate(mData, mSize);
        std::allocator<RayResume>().deallocate(mResume, mSize);
    }
    RayStates(const RayStates&) = delete;
    RayStates& operator=(const RayStates&) = delete;
    RayState& operator[](std::size_t i) { return mData[i]; }
    const RayState& operator[](std::size_t i) const { return mData[i]; }
    RayResume& resume(std::size_t i) { return mResume[i]; }

  private:
    static_assert(std::is_trivially_destructible_v<RayState>);
    static_assert(std::is_trivially_destructible_v<RayResume>);
    RayState* mData;
    RayResume* mResume;
    std::size_t mSize;
};

template <class T> constexpr brickstore::VoxelType voxelTypeOf() {
    if constexpr (std::is_same_v<T, std::uint8_t>) return brickstore::VoxelType::U8;
    if constexpr (std::is_same_v<T, std::uint16_t>) return brickstore::VoxelType::U16;
    if constexpr (std::is_same_v<T, std::int16_t>) return brickstore::VoxelType::I16;
    return brickstore::VoxelType::F32;
}

/// One ray (the shader's main()) for the bricks of batch f.batch, one brick after the other
/// (RayWalk). `front`: the ray's link between samples under pre-integration (f.pre), else
/// null.
template <class T>
void marchRay(const Frame& f, float sx, float sy, float shift, RayState& s, RayResume& r,
              detail::Front* front, RayCount& n) {
    detail::RayWalk w;
    if (!w.begin(f, sx, sy, shift, s, r)) return;
    Accum& acc = s.acc;
    while (w.next(f, s, r)) {
        const BrickRef& b = f.bricks[w.index];
        int& k = w.k;
        const int kEnd = w.kEnd;
        if (b.slot == Slot::Sampled) {
            const std::uint32_t* words =
                f.occ ? f.occ + std::size_t(w.index) * f.occWords : nullptr;
            const auto* map =
                f.fine && b.fine ? reinterpret_cast<const std::uint8_t*>(f.fine + b.fine) : nullptr;
            const glm::vec3 local = w.local(f);
            const T* voxels = static_cast<const T*>(b.voxels);
            // Pre-integration walks the whole range itself: a segment may begin at a sample
            // that a leap skipped. The others narrow it to the box of sampled leaves first.
            int kFirst = k, kLast = kEnd;
            bool more = true;
            if (f.pre)
                more = detail::marchBrickPre(f, voxels, words, local, w.dv, w.d, w.t0, k, kEnd, acc,
                                             *front, n);
            else if (!words || detail::clipToSampled(f, f.boxes[w.index], local, w.dv, w.invDv,
                                                     w.invStep, w.t0, kFirst, kLast))
                more = f.simd ? detail::marchBrickSimd(voxelTypeOf<T>(), f, b.voxels, words, local,
                                                       w.dv, w.d, w.t0, kFirst, kLast, acc, n)
                              : detail::marchBrick(f, voxels, words, map, local, w.dv, w.d, w.t0,
                                                   kFirst, kLast, acc, n);
            if (!more) return;
        } else if (f.pre) {
            // One value throughout: the first segment runs from the last sample's value to it,
            // every later one is that value alone.
            const PreintegratedTable::End e = f.pre->end(double(b.constant));
            n.samples += std::uint64_t(kEnd - k);
            for (; k < kEnd; ++k) {
                const Rgba c = segmentColour(f, *front, k, e);
                *front = {e, k};
                if (c.a <= 0.0f) continue;
                composite(acc, c);
                if (acc.t <= f.ertT) return;
            }
        } else if (!detail::marchConstant(f, b.constant, k, kEnd, acc, n)) {
            return;
        }
    }
}

/// The image-plane position (Frame's sx, sy in [-1, 1]) of the centre of lattice pixel (x, y).
glm::vec2 planeOf(const Frame& f, PixelLattice lattice, std::uint32_t x, std::uint32_t y) {
    return {2.0f * (float(lattice.pixel(x)) + 0.5f) / f.width - 1.0f,
            1.0f - 2.0f * (float(lattice.pixel(y)) + 0.5f) / f.height};
}

/// One pass over the rays of `rect` (within `region`) for the bricks of batch f.batch (rays:
/// the region's, row by row; only those of rect are touched). Both rectangles are of the
/// lattice's pixels (RenderOptions::stride): ray (x, y) is the ray of image pixel
/// (lattice.pixel(x), lattice.pixel(y)).
template <class T>
void marchPass(const Frame& f, PixelLattice lattice, const PixelRect& region, const PixelRect& rect,
               RayStates& rays, std::vector<detail::Front>& fronts, RayCount& total) {
    std::atomic<std::uint64_t> samples{0}, leaps{0};
    const auto x0 = region.x, y0 = region.y, w = region.width;
    auto ray = [&](std::uint32_t x, std::uint32_t y) {
        detail::PacketRay p;
        const glm::vec2 at = planeOf(f, lattice, x, y);
        p.sx = at.x;
        p.sy = at.y;
        p.shift = f.jitter ? rayJitter(lattice.pixel(x), lattice.pixel(y)) - 0.5f : 0.0f;
        const std::size_t i = std::size_t(y - y0) * w + (x - x0);
        p.state = &rays[i];
        p.resume = &rays.resume(i);
        if (f.batch == 0) std::construct_at(p.state);
        return p;
    };
    tbb::parallel_for(
        tbb::blocked_range2d<std::uint32_t>(rect.y, rect.y + rect.height, 8, rect.x,
                                            rect.x + rect.width, 8),
        [&](const tbb::blocked_range2d<std::uint32_t>& r) {
            RayCount n;
            if (f.packets) { // the rays in 4x4 blocks (partial at an edge)
                const auto ye = r.rows().end(), xe = r.cols().end();
                std::vector<detail::PacketRay> list;
                list.reserve(r.rows().size() * r.cols().size());
                for (std::uint32_t by = r.rows().begin(); by < ye; by += 4)
                    for (std::uint32_t bx = r.cols().begin(); bx < xe; bx += 4)
                        for (std::uint32_t y = by; y < std::min(by + 4, ye); ++y)
                            for (std::uint32_t x = bx; x < std::min(bx + 4, xe); ++x) {
                                list.push_back(ray(x, y));
                                // The states were written by the thread that
                                // made them: fetch them here, well before use.
                                __builtin_prefetch(list.back().state, 1);
                            }
                detail::marchPacketSimd(voxelTypeOf<T>(), f, list.data(), list.size(), n);
                samples += n.samples;
                leaps += n.leaps;
                return;
            }
            for (std::uint32_t y = r.rows().begin(); y < r.rows().end(); ++y)
                for (std::uint32_t x = r.cols().begin(); x < r.cols().end(); ++x) {
                    const detail::PacketRay p = ray(x, y);
                    const std::size_t i = std::size_t(y - y0) * w + (x - x0);
                    marchRay<T>(f, p.sx, p.sy, p.shift, *p.state, *p.resume,
                                fronts.empty() ? nullptr : &fronts[i], n);
                }
            samples += n.samples;
            leaps += n.leaps;
        });
    total.samples += samples;
    total.leaps += leaps;
}

void marchPassOfType(brickstore::VoxelType type, const Frame& f, PixelLattice lattice,
                     const PixelRect& region, const PixelRect& rect, RayStates& rays,
                     std::vector<detail::Front>& fronts, RayCount& total) {
    switch (type) {
    case brickstore::VoxelType::U8:
        return marchPass<std::uint8_t>(f, lattice, region, rect, rays, fronts, total);
    case brickstore::VoxelType::U16:
        return marchPass<std::uint16_t>(f, lattice, region, rect, rays, fronts, total);
    case brickstore::VoxelType::I16:
        return marchPass<std::int16_t>(f, lattice, region, rect, rays, fronts, total);
    case brickstore::VoxelType::F32:
        return marchPass<float>(f, lattice, region, rect, rays, fronts, total);
    }
}

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
    f.simd = o.simd;
    f.packets = o.simd && o.packets && !o.preintegrate;
    f.jitter = o.jitter;
    f.segment = o.stepVoxels;
    f.gradScale = glm::vec3(0.5 / span * g.minSpacing() / g.spacing);
    return f;
}

/// Every brick of the level: what it draws and in which batch (`ends` as planBatches gives).
std::vector<BrickRef> brickRefs(const BrickPlan& plan, const std::vector<std::size_t>& ends,
                                std::uint64_t brickCount) {
    std::vector<BrickRef> bricks(std::max<std::uint64_t>(brickCount, 1));
    for (std::size_t batch = 0, i = 0; batch < ends.size(); ++batch)
        for (; i < ends[batch]; ++i) {
            const PlannedBrick& b = plan.drawn[i];
            BrickRef& ref = bricks[b.index];
            ref.batch = std::uint32_t(batch);
            ref.slot = b.draw == BrickDraw::Constant ? Slot::Constant : Slot::Sampled;
            ref.constant = b.constantValue;
        }
    return bricks;
}

/// The region's image: the rays' colours over `marched` (region coordinates; not visible: no
/// pixel), transparent black elsewhere; clamped to [0, 1] unless `clamp` is false (a part's
/// segments, which the compositing clamps once laid together: a shaded segment's colour may
/// exceed 1).
Image imageOf(const RayStates& rays, std::uint32_t width, std::uint32_t height,
              const Footprint& marched, bool clamp) {
    Image image(width, height); // transparent black
    if (!marched.visible) return image;
    const PixelRect& m = marched.rect;
    const float top = clamp ? 1.0f : std::numeric_limits<float>::max();
    tbb::parallel_for(tbb::blocked_range<std::uint32_t>(m.y, m.y + m.height, 16),
                      [&](const tbb::blocked_range<std::uint32_t>& r) {
                          for (std::uint32_t y = r.begin(); y < r.end(); ++y)
                              for (std::uint32_t x = m.x; x < m.x + m.width; ++x) {
                                  const Accum& c = rays[std::size_t(y) * width + x].acc;
                                  float* px = image.pixel(x, y);
                                  px[0] = std::clamp(c.r, 0.0f, top);
                                  px[1] = std::clamp(c.g, 0.0f, top);
                                  px[2] = std::clamp(c.b, 0.0f, top);
                                  px[3] = std::clamp(1.0f - c.t, 0.0f, 1.0f);
                              }
                      });
    return image;
}

/// Pins plan.drawn[first, end) but those `unreached` marks (decompressing misses on every
/// core) and points their refs at the voxels; the pins are the batch's and go when it is
/// drawn.
std::vector<brickstore::BrickPin> pinBatch(const BrickPlan& plan, std::size_t first,
                                           std::size_t end,
                                           const std::vector<std::uint8_t>& unreached,
                                           brickstore::BrickCache& cache,
                                           std::vector<BrickRef>& bricks) {
    std::vector<brickstore::BrickPin> pins(end - first);
    tbb::parallel_for(tbb::blocked_range<std::size_t>(first, end),
                      [&](const tbb::blocked_range<std::size_t>& r) {
                          for (std::size_t i = r.begin(); i != r.end(); ++i) {
                              const PlannedBrick& b = plan.drawn[i];
                              if (b.draw != BrickDraw::Sampled || unreached[i]) continue;
                              pins[i - first] = cache.pin(b.key);
                              bricks[b.index].voxels = pins[i - first].data().data();
                          }
                      });
    return pins;
}

/// The distance maps (FineOccupancy) of the batch's sampled bricks, built from their pinned
/// voxels where a frame has not yet; their offsets into the pool go to their refs.
void cellsOfBatch(const BrickPlan& plan, std::size_t first, std::size_t end,
                  const std::vector<std::uint8_t>& unreached, FineOccupancy& fine,
                  brickstore::VoxelType type, const Frame& f, std::vector<BrickRef>& bricks,
                  FrameStats& stats) {
    const FineOccupancyStats before = fine.stats();
    std::atomic<std::uint64_t> withCells{0};
    tbb::parallel_for(tbb::blocked_range<std::size_t>(first, end, 1),
                      [&](const tbb::blocked_range<std::size_t>& r) {
                          for (std::size_t i = r.begin(); i != r.end(); ++i) {
                              const PlannedBrick& b = plan.drawn[i];
                              if (b.draw != BrickDraw::Sampled || unreached[i]) continue;
                              BrickRef& ref = bricks[b.index];
                              ref.fine = fine.offsetOf(b.index, ref.voxels, type, f.brick, f.apron);
                              if (ref.fine != 0) ++withCells;
                          }
                      });
    fine.addFrameCost(before, withCells, stats);
}

/// The rays still marching (waiting for a later batch) after a pass, for ray guidance: a
/// summed-area table of them over `marched` (rays, as marchPass numbers them), so that whether
/// a rectangle holds any takes four reads, and then which of them meet a box.
class MarchingRays {
  public:
    MarchingRays(const RayStates& rays, PixelLattice lattice, const PixelRect& region,
                 const PixelRect& marched)
        : mRays(rays), mLattice(lattice), mRegion(region), mRect(marched),
          mStride(std::size_t(marched.width) + 1),
          mSum(mStride * (std::size_t(marched.height) + 1), 0) {
        for (std::uint32_t y = 0; y < marched.height; ++y) {
            std::uint32_t line = 0;
            for (std::uint32_t x = 0; x < marched.width; ++x) {
                line += marching(marched.x + x, marched.y + y) ? 1u : 0u;
                mSum[(y + 1) * mStride + x + 1] = mSum[y * mStride + x + 1] + line;
            }
        }
    }

    /// Whether a ray still marching, of a pixel of `r` (image pixels), passes within a voxel
    /// of the box [lo, hi] (voxels of the level): the ray as RayWalk::begin sets it up, the
    /// voxel of margin for the floats of its walk.
    bool anyMeets(const Frame& f, const PixelRect& r, glm::vec3 lo, glm::vec3 hi) const {
        const std::optional<PixelRect> rays = mLattice.of(r);
        const std::optional<PixelRect> in = rays ? overlap(*rays, mRect) : std::nullopt;
        if (!in || !any(*in)) return false;
        lo -= 1.0f;
        hi += 1.0f;
        for (std::uint32_t y = in->y; y < in->y + in->height; ++y)
            for (std::uint32_t x = in->x; x < in->x + in->width; ++x) {
                if (!marching(x, y)) continue;
                const glm::vec2 at = planeOf(f, mLattice, x, y);
                const float sx = at.x, sy = at.y;
                const glm::vec3 o = f.ortho ? f.eye + sx * f.right + sy * f.up : f.eye;
                const glm::vec3 d =
                    f.ortho ? f.forward : glm::normalize(f.forward + sx * f.right + sy * f.up);
                if (meets(o * f.invSpacing, d * f.invSpacing, lo, hi)) return true;
            }
        return false;
    }

  private:
    bool marching(std::uint32_t x, std::uint32_t y) const {
        const std::size_t i = std::size_t(y - mRegion.y) * mRegion.width + (x - mRegion.x);
        return mRays[i].phase == detail::RayPhase::Waiting;
    }
    /// `in` lies within mRect.
    bool any(const PixelRect& in) const {
        const std::size_t x0 = in.x - mRect.x, y0 = in.y - mRect.y;
        const std::size_t x1 = x0 + in.width, y1 = y0 + in.height;
        return mSum[y1 * mStride + x1] + mSum[y0 * mStride + x0] !=
               mSum[y0 * mStride + x1] + mSum[y1 * mStride + x0];
    }
    /// Whether the ray o + t dv, t >= 0, meets the box [lo, hi] (slabs).
    static bool meets(glm::vec3 o, glm::vec3 dv, glm::vec3 lo, glm::vec3 hi) {
        float t0 = 0.0f, t1 = 3.0e38f;
        for (int a = 0; a < 3; ++a) {
            if (dv[a] == 0.0f) {
                if (o[a] < lo[a] || o[a] > hi[a]) return false;
                continue;
            }
            const float inv = 1.0f / dv[a];
            const float ta = (lo[a] - o[a]) * inv, tb = (hi[a] - o[a]) * inv;
            t0 = std::max(t0, std::min(ta, tb));
            t1 = std::min(t1, std::max(ta, tb));
        }
        return t0 <= t1;
    }

    const RayStates& mRays;
    PixelLattice mLattice;
    PixelRect mRegion, mRect;
    std::size_t mStride;
    std::vector<std::uint32_t> mSum;
};

/// Ray guidance (RenderOptions::rayGuided): marks in `unreached` the sampled bricks of
/// plan.drawn[first, end) that no ray still marching meets (every ray of their footprint has
/// terminated early, left the volume or misses the brick). A ray meets the bricks of later
/// batches only after those it waits for, so no ray would sample them: they are not loaded.
/// Returns how many it marked.
std::uint64_t markUnreached(const LevelGeometry& g, const BrickPlan& plan, std::size_t first,
                            std::size_t end, const View& view, const Frame& f,
                            const MarchingRays& marching, std::vector<std::uint8_t>& unreached) {
    std::atomic<std::uint64_t> n{0};
    tbb::parallel_for(tbb::blocked_range<std::size_t>(first, end, 8), [&](const tbb::blocked_range<
                                                                          std::size_t>& r) {
        for (std::size_t i = r.begin(); i != r.end(); ++i) {
            const PlannedBrick& b = plan.drawn[i];
            if (b.draw != BrickDraw::Sampled) continue;
            const auto& p = b.key.pos;
            const Footprint fp = footprint(g, BrickBox{p, {p[0] + 1, p[1] + 1, p[2] + 1}}, view);
            const glm::vec3 lo = glm::vec3(p[0], p[1], p[2]) * float(f.brick);
            if (fp.visible && marching.anyMeets(f, fp.rect, lo, lo + float(f.brick))) continue;
            unreached[i] = 1;
            ++n;
        }
    });
    return n;
}

/// Ray guidance's batches: plan.drawn's sampled bricks that are not resident now.
std::vector<std::uint8_t> missingBricks(const BrickPlan& plan, const brickstore::BrickCache& cache,
                                        std::uint64_t& count) {
    std::vector<std::uint8_t> missing(plan.drawn.size(), 0);
    count = 0;
    for (std::size_t i = 0; i < plan.drawn.size(); ++i) {
        const PlannedBrick& b = plan.drawn[i];
        if (b.draw != BrickDraw::Sampled || cache.resident(b.key)) continue;
        missing[i] = 1;
        ++count;
    }
    return missing;
}

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
    brickstore::BrickCache& cache = scene.cache;
    const auto levels = std::uint32_t(store.layout().levels().size());
    const std::uint32_t level = std::min<std::uint32_t>(std::uint32_t(options.level), levels - 1);
    const LevelGeometry g = LevelGeometry::of(store, level);
    const FrameClassification classified =
        classifyFrame(scene, level, options, options.stepVoxels, stats);
    const TransferFunctionTable& table = *classified.table;
    const OccupancyTrees* occupancy = classified.occupancy;
    const bool octree = occupancy != nullptr;
    // A slice (options.region) plans the bricks its own rays reach: under a host budget the
    // frame's slices then load each brick about once, not once per slice.
    // Under pre-integration a segment may run from a drawn brick into a transparent one,
    // whose value it reads: transparent bricks next to drawn ones are drawn too.
    const auto keepNear =
        options.preintegrate
            ? std::max(1u, std::uint32_t(std::ceil(options.stepVoxels / g.brickVoxels)))
            : 0u;
    BrickPlan plan =
        planBricks(store, g, table, view, options.region, options.skip, occupancy, keepNear);
    if (options.parts > 1) // only this part's bricks: the others' samples are theirs
        keepOwned(plan, mPartitions.get(store, level, options.parts).region(options.part));
    recordPlan(plan, level, stats);

    // Batches of the front-to-back order whose bricks fit the host budget, drawn one after
    // the other, each pinned only while it is drawn (the cache can then evict behind it).
    // Ray guidance: the bricks to load come in about kGuidedSteps batches, and a later batch's
    // bricks that no ray still marching can enter are left out (markUnreached). Only where the
    // level outgrows the budget: where it fits, a brick loaded stays, and the next frames of a
    // moving camera reach the bricks this frame's rays did not (left out, each would be loaded
    // by a later frame of the flight instead of this one).
    const std::uint64_t budget = cache.stats().budgetBytes; // one read: the daemon may change it
    const bool guided = options.rayGuided && g.brickCount() * store.brickBytes() > budget;
    std::uint64_t toLoad = 0;
    const std::vector<std::uint8_t> missing =
        guided ? missingBricks(plan, cache, toLoad) : std::vector<std::uint8_t>{};
    const std::uint64_t loadStep =
        guided
            ? std::max(toLoad / kGuidedSteps, std::uint64_t(kGuidedStepBricks)) * store.brickBytes()
            : 0;
    const auto ends = planBatches(plan, store.brickBytes(), budget, missing, loadStep);
    std::vector<std::uint8_t> unreached(plan.drawn.size(), 0);
    // A frame whose bricks outgrow the budget streams them: it keeps its front bricks (with
    // its earlier slices'), as many as leave room for two batches of loads, and lets the
    // others go first when the cache needs room. The next pass of this view (or of one near
    // it) then starts on resident bricks; under plain LRU each brick would be evicted just
    // before that pass wanted it.
    const std::uint64_t room = 2 * std::max(loadStep, kGuidedStepBricks * store.brickBytes());
    const std::uint64_t keepBytes = budget - std::min(budget, room);
    std::uint64_t keptBytes = options.hostKeptBefore;
    stats.batches = std::uint32_t(ends.size());
    std::vector<BrickRef> bricks = brickRefs(plan, ends, g.brickCount());
    Frame f = frameOf(g, view.basis, options, table);
    const std::vector<float> tfPairs = detail::tfPairTable(f.tf, f.entries);
    f.tfPairs = tfPairs.data();
    f.bricks = bricks.data();
    f.pre = classified.preintegrated.get();
    if (octree && occupancy->depth() > 0) {
        f.occ = occupancy->words().data();
        f.octDepth = int(occupancy->depth());
        f.occWords = int(occupancy->wordsPerBrick());
        f.leafAxis = int(occupancy->leavesPerAxis());
        f.leaf = float(occupancy->leafVoxels());
        f.boxes = occupancy->sampledBoxes().data();
    }
    FineOccupancy* fine = f.occ && classified.classification
                              ? classified.classification->fine(options.cellVoxels)
                              : nullptr;
    if (fine) {
        f.fine = fine->pool();
        f.cell = float(fine->cellVoxels());
        f.cellAxis = int(fine->cellsPerAxis());
    }
    // The rays: one per pixel of the region, or of its lattice under a stride (validate() keeps
    // the lattice from being empty). `region` and `marched` number them, not image pixels.
    const PixelLattice lattice = options.lattice();
    const PixelRect region = *lattice.of(options.drawn());
    // Only the rays that may meet a drawn brick are marched (the others stay transparent
    // black); without skipping every ray is, the reference of the skipping invariant.
    Footprint marched{region, region.pixels() > 0};
    if (options.skip != SkipMode::None) {
        const Footprint reach = raysToMarch(g, plan, view, options.drawn());
        const std::optional<PixelRect> rays = reach.visible ? lattice.of(reach.rect) : std::nullopt;
        marched = rays ? Footprint{*rays, true} : Footprint{};
    }
    RayStates rays(region.pixels());
    std::vector<detail::Front> fronts(f.pre ? region.pixels() : 0);
    RayCount count;
    for (std::size_t batch = 0, first = 0; batch < ends.size(); first = ends[batch++]) {
        if (guided && batch > 0 && marched.visible)
            stats.bricksUnreached +=
                markUnreached(g, plan, first, ends[batch], view, f,
                              MarchingRays(rays, lattice, region, marched.rect), unreached);
        const auto loadStart = Clock::now();
        std::vector<brickstore::BrickPin> pins =
            pinBatch(plan, first, ends[batch], unreached, cache, bricks);
        stats.uploadMs += msSince(loadStart);
        if (fine)
            cellsOfBatch(plan, first, ends[batch], unreached, *fine, store.info().volume.type, f,
                         bricks, stats);
        const auto renderStart = Clock::now();
        f.batch = std::uint32_t(batch);
        if (marched.visible)
            marchPassOfType(store.info().volume.type, f, lattice, region, marched.rect, rays,
                            fronts, count);
        stats.renderMs += msSince(renderStart);
        for (brickstore::BrickPin& pin : pins) {
            if (!pin) continue;
            if (keptBytes + store.brickBytes() <= keepBytes) {
                keptBytes += store.brickBytes();
                pin = {};
            } else {
                pin.releaseCold();
            }
        }
    }
    stats.hostKeptBytes = keptBytes - options.hostKeptBefore;
    stats.samples = count.samples;
    stats.octreeLeaps = count.leaps;
    stats.occlusionReason = "not on the CPU raycaster";
    stats.totalMs = msSince(frameStart);
    Footprint local = marched; // in the region's coordinates
    local.rect.x -= region.x;
    local.rect.y -= region.y;
    return imageOf(rays, region.width, region.height, local, options.parts == 1);
}

} // namespace bc::render
