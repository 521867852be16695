#include "render/BrickPlan.h"

#include "brickstore/BrickStore.h"
#include "render/Occupancy.h"
#include "render/TransferFunction.h"

#include <algorithm>
#include <cmath>

#include <glm/geometric.hpp>

namespace bc::render {

LevelGeometry LevelGeometry::of(const brickstore::BrickStore& store, std::uint32_t level) {
    const auto& layout = store.layout();
    const auto& info = store.info();
    LevelGeometry g;
    g.level = level;
    const auto& l = layout.levels().at(level);
    g.dims = l.dims;
    g.bricks = l.bricks;
    g.brickVoxels = layout.geometry().brickVoxels;
    g.apronVoxels = layout.geometry().apronVoxels;
    const auto& d0 = layout.levels()[0].dims;
    for (int a = 0; a < 3; ++a) {
        g.box.max[a] = double(d0[a]) * info.volume.spacingMm[a];
        g.spacing[a] = g.box.max[a] / double(g.dims[a]);
    }
    return g;
}

double LevelGeometry::minSpacing() const {
    return std::min({spacing.x, spacing.y, spacing.z});
}

Box LevelGeometry::brickBox(const std::array<std::uint32_t, 3>& pos) const {
    Box b;
    for (int a = 0; a < 3; ++a) {
        b.min[a] = double(std::uint64_t(pos[a]) * brickVoxels) * spacing[a];
        b.max[a] =
            double(std::min<std::uint64_t>(std::uint64_t(pos[a] + 1) * brickVoxels, dims[a])) *
            spacing[a];
    }
    return b;
}

namespace {

struct Plane {
    glm::dvec3 point, normal; ///< inside where dot(p - point, normal) >= 0
};

/// The planes bounding the rays through the image rectangle [sx0, sx1] x [sy0, sy1] of `v`,
/// in its screen coordinates (-1..1, y up; ViewBasis::ray), and the eye plane.
std::vector<Plane> viewPlanes(const ViewBasis& v, double sx0, double sx1, double sy0, double sy1) {
    std::vector<Plane> planes{{v.eye, v.forward}};
    const glm::dvec3 r = v.right, u = v.upScaled;
    if (v.orthographic) {
        planes.push_back({v.eye + sx1 * r, -glm::normalize(r)});
        planes.push_back({v.eye + sx0 * r, glm::normalize(r)});
        planes.push_back({v.eye + sy1 * u, -glm::normalize(u)});
        planes.push_back({v.eye + sy0 * u, glm::normalize(u)});
        return planes;
    }
    const glm::dvec3 f = v.forward;
    const glm::dvec3 corners[4] = {f + sx1 * r + sy1 * u, f + sx0 * r + sy1 * u,
                                   f + sx0 * r + sy0 * u, f + sx1 * r + sy0 * u};
    const glm::dvec3 centre = f + 0.5 * (sx0 + sx1) * r + 0.5 * (sy0 + sy1) * u;
    for (int i = 0; i < 4; ++i) {
        glm::dvec3 n = glm::normalize(glm::cross(corners[i], corners[(i + 1) % 4]));
        if (glm::dot(n, centre) < 0.0) n = -n;
        planes.push_back({v.eye, n});
    }
    return planes;
}

std::vector<Plane> viewPlanes(const ViewBasis& v) {
    return viewPlanes(v, -1.0, 1.0, -1.0, 1.0);
}

/// The planes of the rays through `region` of a width x height image: its pixels' outer
/// edges, so every ray of the region (through a pixel centre) is strictly inside.
std::vector<Plane> regionPlanes(const ViewBasis& v, const PixelRect& region, std::uint32_t width,
                                std::uint32_t height) {
    if (region.whole()) return viewPlanes(v);
    const double w = width, h = height;
    return viewPlanes(v, 2.0 * region.x / w - 1.0, 2.0 * (region.x + region.width) / w - 1.0,
                      1.0 - 2.0 * (region.y + region.height) / h, 1.0 - 2.0 * region.y / h);
}

bool outsidePlanes(const Box& box, const ViewBasis& view, const std::vector<Plane>& planes) {
    const double slack = 1e-9 * (1.0 + glm::length(box.size()) + glm::length(box.min - view.eye));
    for (const Plane& p : planes) {
        bool allOut = true;
        for (int c = 0; c < 8 && allOut; ++c) {
            const glm::dvec3 q{(c & 1) ? box.max.x : box.min.x, (c & 2) ? box.max.y : box.min.y,
                               (c & 4) ? box.max.z : box.min.z};
            allOut = glm::dot(q - p.point, p.normal) < -slack;
        }
        if (allOut) return true;
    }
    return false;
}

} // namespace

bool outsideView(const Box& box, const ViewBasis& view) {
    return outsidePlanes(box, view, viewPlanes(view));
}

bool outsideRegion(const Box& box, const View& view, const PixelRect& region) {
    return outsidePlanes(box, view.basis,
                         regionPlanes(view.basis, region, view.width, view.height));
}

namespace {

/// Sum over axes of |i - eye cell| (perspective) or of sign(forward) * i (orthographic):
/// crossing a brick face along any ray moves this key up by one.
std::int64_t visibilityKey(const std::array<std::uint32_t, 3>& pos, const LevelGeometry& g,
                           const ViewBasis& v) {
    std::int64_t key = 0;
    for (int a = 0; a < 3; ++a) {
        if (v.orthographic) {
            key += v.forward[a] > 0   ? std::int64_t(pos[a])
                   : v.forward[a] < 0 ? -std::int64_t(pos[a])
                                      : 0;
        } else {
            const double cell = std::floor(v.eye[a] / g.spacing[a] / g.brickVoxels);
            const double clamped = std::clamp(cell, -1e12, 1e12);
            key += std::int64_t(std::abs(double(pos[a]) - clamped));
        }
    }
    return key;
}

} // namespace

namespace {

enum class Verdict { Cull, Skip, Draw };

/// Every brick of the level that `verdict(key, index, record)` keeps, sorted front to back
/// (stable: index order among equal keys), with the counts of those culled and skipped. A
/// skipped brick within `keepNear` bricks (per axis) of a kept one is kept too.
template <typename VerdictOf>
BrickPlan planLevel(const brickstore::BrickStore& store, const LevelGeometry& g,
                    const ViewBasis& view, const VerdictOf& verdict, std::uint32_t keepNear = 0) {
    BrickPlan plan;
    plan.total = g.brickCount();
    std::vector<Verdict> verdicts(plan.total);
    std::uint64_t index = 0;
    for (std::uint32_t z = 0; z < g.bricks[2]; ++z)
        for (std::uint32_t y = 0; y < g.bricks[1]; ++y)
            for (std::uint32_t x = 0; x < g.bricks[0]; ++x, ++index) {
                const brickstore::BrickKey key{g.level, {x, y, z}};
                verdicts[index] = verdict(key, index, store.record(key));
            }
    const auto kept = [&](std::uint32_t x, std::uint32_t y, std::uint32_t z) {
        const auto r = std::int64_t(keepNear);
        const std::int64_t p[3] = {x, y, z};
        std::int64_t lo[3], hi[3];
        for (int a = 0; a < 3; ++a) {
            lo[a] = std::max<std::int64_t>(p[a] - r, 0);
            hi[a] = std::min<std::int64_t>(p[a] + r, std::int64_t(g.bricks[a]) - 1);
        }
        for (std::int64_t k = lo[2]; k <= hi[2]; ++k)
            for (std::int64_t j = lo[1]; j <= hi[1]; ++j)
                for (std::int64_t i = lo[0]; i <= hi[0]; ++i)
                    if (verdicts[std::uint64_t((k * g.bricks[1] + j) * g.bricks[0] + i)] ==
                        Verdict::Draw)
                        return true;
        return false;
    };
    index = 0;
    for (std::uint32_t z = 0; z < g.bricks[2]; ++z)
        for (std::uint32_t y = 0; y < g.bricks[1]; ++y)
            for (std::uint32_t x = 0; x < g.bricks[0]; ++x, ++index) {
                const brickstore::BrickKey key{g.level, {x, y, z}};
                const auto& record = store.record(key);
                switch (verdicts[index]) {
                case Verdict::Cull:
                    ++plan.culled;
                    continue;
                case Verdict::Skip:
                    if (keepNear == 0 || !kept(x, y, z)) {
                        ++plan.skipped;
                        continue;
                    }
                    break;
                case Verdict::Draw:
                    break;
                }
                PlannedBrick b{index, key,
                               record.stored() ? BrickDraw::Sampled : BrickDraw::Constant,
                               record.range.min, visibilityKey(key.pos, g, view)};
                ++(b.draw == BrickDraw::Sampled ? plan.sampled : plan.constant);
                plan.drawn.push_back(b);
            }
    std::stable_sort(
        plan.drawn.begin(), plan.drawn.end(),
        [](const PlannedBrick& a, const PlannedBrick& b) { return a.order < b.order; });
    return plan;
}

BrickPlan planBricks(const brickstore::BrickStore& store, const LevelGeometry& g,
                     const TransferFunctionTable& table, const ViewBasis& view,
                     const std::vector<Plane>& cull, SkipMode skip, const OccupancyTrees* occupancy,
                     std::uint32_t keepNear) {
    return planLevel(
        store, g, view,
        [&](const brickstore::BrickKey& key, std::uint64_t index,
            const brickstore::BrickRecord& record) {
            if (outsidePlanes(g.brickBox(key.pos), view, cull)) return Verdict::Cull;
            const bool leavesEmpty = skip == SkipMode::All && occupancy && record.stored() &&
                                     !occupancy->occupied(index, 0, {});
            if (leavesEmpty ||
                (skip != SkipMode::None && table.transparent(record.range.min, record.range.max)))
                return Verdict::Skip;
            return Verdict::Draw;
        },
        keepNear);
}

} // namespace

BrickPlan planBricks(const brickstore::BrickStore& store, const LevelGeometry& g,
                     const TransferFunctionTable& table, const ViewBasis& view, SkipMode skip,
                     const OccupancyTrees* occupancy, std::uint32_t keepNear) {
    return planBricks(store, g, table, view, viewPlanes(view), skip, occupancy, keepNear);
}

BrickPlan planBricks(const brickstore::BrickStore& store, const LevelGeometry& g,
                     const TransferFunctionTable& table, const View& view, const PixelRect& region,
                     SkipMode skip, const OccupancyTrees* occupancy, std::uint32_t keepNear) {
    return planBricks(store, g, table, view.basis,
                      regionPlanes(view.basis, region, view.width, view.height), skip, occupancy,
                      keepNear);
}

BrickPlan planEveryBrick(const brickstore::BrickStore& store, const LevelGeometry& g,
                         const ViewBasis& view) {
    return planLevel(store, g, view,
                     [](const brickstore::BrickKey&, std::uint64_t,
                        const brickstore::BrickRecord&) { return Verdict::Draw; });
}

std::vector<std::size_t> planBatches(const BrickPlan& plan, std::uint64_t brickBytes,
                                     std::uint64_t budgetBytes) {
    return planBatches(plan, brickBytes, budgetBytes, {}, 0);
}

std::vector<std::size_t> planBatches(const BrickPlan& plan, std::uint64_t brickBytes,
                                     std::uint64_t budgetBytes,
                                     const std::vector<std::uint8_t>& missing,
                                     std::uint64_t loadBytes) {
    std::vector<std::size_t> ends;
    std::uint64_t bytes = 0, loads = 0;
    for (std::size_t i = 0; i < plan.drawn.size(); ++i) {
        if (plan.drawn[i].draw != BrickDraw::Sampled) continue;
        const bool load = i < missing.size() && missing[i] != 0;
        if (bytes > 0 && (bytes + brickBytes > budgetBytes ||
                          (load && loadBytes > 0 && loads + brickBytes > loadBytes))) {
            ends.push_back(i);
            bytes = 0;
            loads = 0;
        }
        bytes += brickBytes;
        if (load) loads += brickBytes;
    }
    ends.push_back(plan.drawn.size());
    return ends;
}

void recordPlan(const BrickPlan& plan, std::uint32_t level, FrameStats& stats) {
    stats.level = level;
    stats.bricksTotal = plan.total;
    stats.bricksCulled = plan.culled;
    stats.bricksSkipped = plan.skipped;
    stats.bricksVisited = plan.drawn.size();
    stats.bricksConstant = plan.constant;
}

void keepInside(BrickPlan& plan, const LevelGeometry& geometry, const Clip& clip) {
    std::uint64_t dropped = 0;
    std::erase_if(plan.drawn, [&](const PlannedBrick& b) {
        if (!clip.outside(geometry.brickBox(b.key.pos))) return false;
        ++dropped;
        (b.draw == BrickDraw::Constant ? plan.constant : plan.sampled) -= 1;
        return true;
    });
    plan.culled += dropped;
}

} // namespace bc::render
