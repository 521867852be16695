#include "render/Partition.h"

#include "brickstore/BrickStore.h"

#include <glm/geometric.hpp>

#include <algorithm>
#include <cmath>
#include <limits>
#include <stdexcept>
#include <string>

namespace bc::render {

namespace {

std::uint64_t indexOf(const std::array<std::uint32_t, 3>& grid,
                      const std::array<std::uint32_t, 3>& pos) {
    return (std::uint64_t(pos[2]) * grid[1] + pos[1]) * grid[0] + pos[0];
}

/// |low * parts - lowParts * total|: how far a cut's low side is from its share (exact: split()
/// keeps total * parts within 64 bits).
std::uint64_t miss(std::uint64_t low, std::uint64_t total, std::uint32_t lowParts,
                   std::uint32_t parts) {
    const std::uint64_t a = low * parts, b = total * lowParts;
    return a > b ? a - b : b - a;
}

} // namespace

Partition Partition::split(const std::array<std::uint32_t, 3>& grid,
                           std::span<const std::uint64_t> weights, std::uint32_t parts) {
    if (parts == 0 || parts > kMaxParts)
        throw std::invalid_argument("partition: parts must lie in 1.." + std::to_string(kMaxParts) +
                                    ", got " + std::to_string(parts));
    const std::uint64_t bricks = std::uint64_t(grid[0]) * grid[1] * grid[2];
    if (bricks == 0) throw std::invalid_argument("partition: the brick grid is empty");
    if (weights.size() != bricks)
        throw std::invalid_argument("partition: " + std::to_string(weights.size()) +
                                    " weights for " + std::to_string(bricks) + " bricks");
    constexpr std::uint64_t kMaxTotal = std::numeric_limits<std::uint64_t>::max() / kMaxParts;
    std::uint64_t total = 0;
    for (const std::uint64_t w : weights) {
        if (w > kMaxTotal - total)
            throw std::invalid_argument("partition: the weights add up to more than " +
                                        std::to_string(kMaxTotal));
        total += w;
    }
    if (bricks > kMaxTotal)
        throw std::invalid_argument("partition: " + std::to_string(bricks) + " bricks");
    Partition p;
    p.mGrid = grid;
    p.mRegions.assign(parts, BrickBox{});
    p.mWeights.assign(parts, 0);
    p.build(BrickBox{{0, 0, 0}, grid}, 0, parts, weights);
    return p;
}

std::uint32_t Partition::build(const BrickBox& box, std::uint32_t firstPart, std::uint32_t parts,
                               std::span<const std::uint64_t> weights) {
    const auto node = std::uint32_t(mNodes.size());
    mNodes.emplace_back();
    // Each axis's slabs: weight and brick count per plane position, as prefix sums.
    struct Cut {
        int axis = -1;
        std::uint32_t plane = 0;
        std::uint64_t weightMiss = 0, countMiss = 0;
    } best;
    const std::uint32_t lowParts = parts / 2;
    if (parts > 1) {
        std::uint64_t total = 0;
        std::array<std::vector<std::uint64_t>, 3> slab;
        for (int a = 0; a < 3; ++a)
            slab[a].assign(box.hi[a] - box.lo[a], 0);
        std::array<std::uint32_t, 3> pos{};
        for (pos[2] = box.lo[2]; pos[2] < box.hi[2]; ++pos[2])
            for (pos[1] = box.lo[1]; pos[1] < box.hi[1]; ++pos[1])
                for (pos[0] = box.lo[0]; pos[0] < box.hi[0]; ++pos[0]) {
                    const std::uint64_t w = weights[indexOf(mGrid, pos)];
                    total += w;
                    for (int a = 0; a < 3; ++a)
                        slab[a][pos[a] - box.lo[a]] += w;
                }
        const std::uint64_t count = box.count();
        for (int a = 0; a < 3; ++a) {
            const std::uint32_t extent = box.hi[a] - box.lo[a];
            const std::uint64_t perSlab = count / extent;
            std::uint64_t low = 0;
            for (std::uint32_t i = 1; i < extent; ++i) {
                low += slab[a][i - 1];
                const Cut c{a, box.lo[a] + i, miss(low, total, lowParts, parts),
                            miss(perSlab * i, count, lowParts, parts)};
                // Closest in weight, then in bricks, then the longer axis (the earlier on a tie).
                const bool better = best.axis < 0 || c.weightMiss < best.weightMiss ||
                                    (c.weightMiss == best.weightMiss &&
                                     (c.countMiss < best.countMiss ||
                                      (c.countMiss == best.countMiss &&
                                       extent > box.hi[best.axis] - box.lo[best.axis])));
                if (better) best = c;
            }
        }
    }
    if (best.axis < 0) { // one part, or one brick: a leaf; extra parts get nothing
        mNodes[node].part = firstPart;
        mRegions[firstPart] = box;
        std::uint64_t w = 0;
        std::array<std::uint32_t, 3> pos{};
        for (pos[2] = box.lo[2]; pos[2] < box.hi[2]; ++pos[2])
            for (pos[1] = box.lo[1]; pos[1] < box.hi[1]; ++pos[1])
                for (pos[0] = box.lo[0]; pos[0] < box.hi[0]; ++pos[0])
                    w += weights[indexOf(mGrid, pos)];
        mWeights[firstPart] = w;
        return node;
    }
    BrickBox low = box, high = box;
    low.hi[best.axis] = high.lo[best.axis] = best.plane;
    const std::uint32_t l = build(low, firstPart, lowParts, weights);
    const std::uint32_t h = build(high, firstPart + lowParts, parts - lowParts, weights);
    Node& n = mNodes[node];
    n.axis = best.axis;
    n.plane = best.plane;
    n.low = l;
    n.high = h;
    return node;
}

Partition Partition::ofLevel(const brickstore::BrickStore& store, std::uint32_t level,
                             std::uint32_t parts) {
    const auto& levels = store.layout().levels();
    if (level >= levels.size())
        throw std::invalid_argument("partition: level " + std::to_string(level) +
                                    " is not in the store (" + std::to_string(levels.size()) +
                                    " levels)");
    const auto& grid = levels[level].bricks;
    std::vector<std::uint64_t> weights(std::uint64_t{grid[0]} * grid[1] * grid[2], 0);
    const std::uint64_t bytes = store.brickBytes();
    brickstore::BrickKey key{level, {}};
    for (key.pos[2] = 0; key.pos[2] < grid[2]; ++key.pos[2])
        for (key.pos[1] = 0; key.pos[1] < grid[1]; ++key.pos[1])
            for (key.pos[0] = 0; key.pos[0] < grid[0]; ++key.pos[0])
                if (store.record(key).stored()) weights[indexOf(grid, key.pos)] = bytes;
    return split(grid, weights, parts);
}

std::vector<std::uint32_t> Partition::frontToBack(const LevelGeometry& g,
                                                  const ViewBasis& view) const {
    std::vector<std::uint32_t> order;
    order.reserve(parts());
    std::vector<std::uint32_t> stack{0};
    while (!stack.empty()) {
        const Node& n = mNodes[stack.back()];
        stack.pop_back();
        if (n.axis < 0) {
            if (!mRegions[n.part].empty()) order.push_back(n.part);
            continue;
        }
        const int a = n.axis;
        bool lowFirst;
        if (view.orthographic) {
            lowFirst = view.forward[a] >= 0.0;
        } else {
            const double plane =
                double(std::min<std::uint64_t>(std::uint64_t(n.plane) * g.brickVoxels, g.dims[a])) *
                g.spacing[a];
            lowFirst = view.eye[a] < plane;
        }
        // The stack pops the last pushed first.
        stack.push_back(lowFirst ? n.high : n.low);
        stack.push_back(lowFirst ? n.low : n.high);
    }
    return order;
}

const Partition& PartitionCache::get(const brickstore::BrickStore& store, std::uint32_t level,
                                     std::uint32_t parts) {
    if (!mPartition || mStore != store.instance() || mLevel != level ||
        mPartition->parts() != parts) {
        mPartition = Partition::ofLevel(store, level, parts);
        mStore = store.instance();
        mLevel = level;
    }
    return *mPartition;
}

Box worldBox(const LevelGeometry& g, const BrickBox& box) {
    Box b;
    for (int a = 0; a < 3; ++a) {
        b.min[a] =
            double(std::min<std::uint64_t>(std::uint64_t(box.lo[a]) * g.brickVoxels, g.dims[a])) *
            g.spacing[a];
        b.max[a] =
            double(std::min<std::uint64_t>(std::uint64_t(box.hi[a]) * g.brickVoxels, g.dims[a])) *
            g.spacing[a];
    }
    return b;
}

Footprint footprint(const LevelGeometry& g, const BrickBox& box, const View& view) {
    Footprint out;
    if (box.empty()) return out;
    const Box w = worldBox(g, box);
    const ViewBasis& v = view.basis;
    const double rr = glm::dot(v.right, v.right), uu = glm::dot(v.upScaled, v.upScaled);
    double x0 = std::numeric_limits<double>::infinity(), y0 = x0, x1 = -x0, y1 = -x0;
    for (int c = 0; c < 8; ++c) {
        const glm::dvec3 corner((c & 1) ? w.max.x : w.min.x, (c & 2) ? w.max.y : w.min.y,
                                (c & 4) ? w.max.z : w.min.z);
        const glm::dvec3 d = corner - v.eye;
        double sx, sy;
        if (v.orthographic) {
            sx = glm::dot(d, v.right) / rr;
            sy = glm::dot(d, v.upScaled) / uu;
        } else {
            const double z = glm::dot(d, v.forward);
            if (!(z > 1e-9 * glm::length(d))) { // at or behind the eye plane: every pixel
                out.rect = {0, 0, view.width, view.height};
                out.visible = true;
                return out;
            }
            sx = glm::dot(d, v.right) / (z * rr);
            sy = glm::dot(d, v.upScaled) / (z * uu);
        }
        // ViewBasis::ray: sx = 2 (x + 1/2) / width - 1, sy = 1 - 2 (y + 1/2) / height.
        const double px = (sx + 1.0) * 0.5 * view.width - 0.5;
        const double py = (1.0 - sy) * 0.5 * view.height - 0.5;
        x0 = std::min(x0, px);
        x1 = std::max(x1, px);
        y0 = std::min(y0, py);
        y1 = std::max(y1, py);
    }
    const double lastX = double(view.width) - 1.0, lastY = double(view.height) - 1.0;
    const double fx0 = std::max(0.0, std::floor(x0) - 1.0),
                 fx1 = std::min(lastX, std::ceil(x1) + 1.0);
    const double fy0 = std::max(0.0, std::floor(y0) - 1.0),
                 fy1 = std::min(lastY, std::ceil(y1) + 1.0);
    if (!(fx0 <= fx1 && fy0 <= fy1)) return out;
    out.rect = {std::uint32_t(fx0), std::uint32_t(fy0), std::uint32_t(fx1 - fx0) + 1,
                std::uint32_t(fy1 - fy0) + 1};
    out.visible = true;
    return out;
}

void keepOwned(BrickPlan& plan, const BrickBox& owned) {
    std::uint64_t dropped = 0;
    std::erase_if(plan.drawn, [&](const PlannedBrick& b) {
        if (owned.contains(b.key.pos)) return false;
        ++dropped;
        (b.draw == BrickDraw::Constant ? plan.constant : plan.sampled) -= 1;
        return true;
    });
    plan.culled += dropped;
}

} // namespace bc::render
