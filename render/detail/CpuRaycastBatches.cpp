#include "render/detail/CpuRaycastBatches.h"

#include "render/Composite.h"
#include "render/FineOccupancy.h"
#include "render/Partition.h"

#include <tbb/blocked_range.h>
#include <tbb/parallel_for.h>

#include <algorithm>
#include <atomic>
#include <optional>

#include <glm/geometric.hpp>
#include <glm/vec2.hpp>

namespace bc::render::detail {

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

MarchingRays::MarchingRays(const RayStates& rays, PixelLattice lattice, const PixelRect& region,
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

bool MarchingRays::anyMeets(const Frame& f, const PixelRect& r, glm::vec3 lo, glm::vec3 hi) const {
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

bool MarchingRays::marching(std::uint32_t x, std::uint32_t y) const {
    const std::size_t i = std::size_t(y - mRegion.y) * mRegion.width + (x - mRegion.x);
    return mRays[i].phase == RayPhase::Waiting;
}

bool MarchingRays::any(const PixelRect& in) const {
    const std::size_t x0 = in.x - mRect.x, y0 = in.y - mRect.y;
    const std::size_t x1 = x0 + in.width, y1 = y0 + in.height;
    return mSum[y1 * mStride + x1] + mSum[y0 * mStride + x0] !=
           mSum[y0 * mStride + x1] + mSum[y1 * mStride + x0];
}

bool MarchingRays::meets(glm::vec3 o, glm::vec3 dv, glm::vec3 lo, glm::vec3 hi) {
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

} // namespace bc::render::detail
