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

std::vector<Plane> viewPlanes(const ViewBasis& v) {
    std::vector<Plane> planes{{v.eye, v.forward}};
    if (v.orthographic) {
        planes.push_back({v.eye + v.right, -glm::normalize(v.right)});
        planes.push_back({v.eye - v.right, glm::normalize(v.right)});
        planes.push_back({v.eye + v.upScaled, -glm::normalize(v.upScaled)});
        planes.push_back({v.eye - v.upScaled, glm::normalize(v.upScaled)});
        return planes;
    }
    const glm::dvec3 f = v.forward, r = v.right, u = v.upScaled;
    const glm::dvec3 corners[4] = {f + r + u, f - r + u, f - r - u, f + r - u};
    for (int i = 0; i < 4; ++i) {
        glm::dvec3 n = glm::normalize(glm::cross(corners[i], corners[(i + 1) % 4]));
        if (glm::dot(n, f) < 0.0) n = -n;
        planes.push_back({v.eye, n});
    }
    return planes;
}

} // namespace

bool outsideView(const Box& box, const ViewBasis& view) {
    const double slack = 1e-9 * (1.0 + glm::length(box.size()) + glm::length(box.min - view.eye));
    for (const Plane& p : viewPlanes(view)) {
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

BrickPlan planBricks(const brickstore::BrickStore& store, const LevelGeometry& g,
                     const TransferFunctionTable& table, const ViewBasis& view, SkipMode skip,
                     const OccupancyTrees* occupancy) {
    BrickPlan plan;
    plan.total = g.brickCount();
    std::uint64_t index = 0;
    for (std::uint32_t z = 0; z < g.bricks[2]; ++z)
        for (std::uint32_t y = 0; y < g.bricks[1]; ++y)
            for (std::uint32_t x = 0; x < g.bricks[0]; ++x, ++index) {
                const brickstore::BrickKey key{g.level, {x, y, z}};
                if (outsideView(g.brickBox(key.pos), view)) {
                    ++plan.culled;
                    continue;
                }
                const auto& record = store.record(key);
                const bool leavesEmpty = skip == SkipMode::All && occupancy && record.stored() &&
                                         !occupancy->occupied(index, 0, {});
                if (leavesEmpty || (skip != SkipMode::None &&
                                    table.transparent(record.range.min, record.range.max))) {
                    ++plan.skipped;
                    continue;
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

BrickPlan planEveryBrick(const brickstore::BrickStore& store, const LevelGeometry& g,
                         const ViewBasis& view) {
    BrickPlan plan;
    plan.total = g.brickCount();
    std::uint64_t index = 0;
    for (std::uint32_t z = 0; z < g.bricks[2]; ++z)
        for (std::uint32_t y = 0; y < g.bricks[1]; ++y)
            for (std::uint32_t x = 0; x < g.bricks[0]; ++x, ++index) {
                const brickstore::BrickKey key{g.level, {x, y, z}};
                const auto& record = store.record(key);
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

std::vector<std::size_t> planBatches(const BrickPlan& plan, std::uint64_t brickBytes,
                                     std::uint64_t budgetBytes) {
    std::vector<std::size_t> ends;
    std::uint64_t bytes = 0;
    for (std::size_t i = 0; i < plan.drawn.size(); ++i) {
        if (plan.drawn[i].draw != BrickDraw::Sampled) continue;
        if (bytes > 0 && bytes + brickBytes > budgetBytes) {
            ends.push_back(i);
            bytes = 0;
        }
        bytes += brickBytes;
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

} // namespace bc::render
