#include "render/detail/SplatPrep.h"

#include "brickstore/BrickStore.h"
#include "render/Occupancy.h"
#include "render/SplatFootprint.h"

#include <tbb/parallel_for.h>

#include <algorithm>
#include <cmath>
#include <utility>
#include <vector>

#include <glm/geometric.hpp>

namespace bc::render::detail {
namespace {

/// OPTICS.md shading with the gradient from central differences of the stored voxels.
template <class T>
void shade(const Frame& f, const T* v, int edge, std::uint32_t stored, const glm::dvec3& dir,
           float* c) {
    const int x = int(stored % edge), y = int(stored / edge % edge), z = int(stored / edge / edge);
    auto at = [&](int i, int j, int k) {
        i = std::clamp(i, 0, edge - 1), j = std::clamp(j, 0, edge - 1),
        k = std::clamp(k, 0, edge - 1);
        return double(v[(std::size_t(k) * edge + j) * edge + i]);
    };
    const glm::dvec3 g =
        glm::dvec3(at(x + 1, y, z) - at(x - 1, y, z), at(x, y + 1, z) - at(x, y - 1, z),
                   at(x, y, z + 1) - at(x, y, z - 1)) *
        f.gradScale;
    const double len = glm::length(g);
    if (!(len > 0.0)) return;
    const double d = std::abs(glm::dot(g / len, dir));
    const double spec = ShadingModel::kSpecular * std::pow(d, ShadingModel::kShininess);
    const double k = ShadingModel::kAmbient + ShadingModel::kDiffuse * d;
    const double w = std::clamp(len / ShadingModel::kGradientFade, 0.0, 1.0);
    for (int i = 0; i < 3; ++i)
        c[i] = float(c[i] + ((c[i] * k + spec) - c[i]) * w);
}

struct BrickJob {
    const PlannedBrick* brick;
    const void* voxels; ///< null for a constant brick
    const OccupancyTrees* occupancy;
};

/// False when the leaf or any node above it is empty (the raycaster's walk leaps it).
bool leafOccupied(const OccupancyTrees& occ, std::uint64_t brick, std::uint32_t depth,
                  std::uint32_t x, std::uint32_t y, std::uint32_t z) {
    for (std::uint32_t l = 1; l <= depth; ++l) {
        const std::uint32_t s = depth - l;
        if (!occ.occupied(brick, l, {x >> s, y >> s, z >> s})) return false;
    }
    return true;
}

/// The visible voxels of one brick, front to back.
template <class T>
std::vector<Visible> visibleVoxels(const Frame& f, const BrickJob& job, std::uint64_t& leaves) {
    const LevelGeometry& g = f.g;
    const auto& pos = job.brick->key.pos;
    const std::uint32_t b = g.brickVoxels, a = g.apronVoxels, edge = b + 2 * a;
    std::uint32_t extent[3];
    for (int i = 0; i < 3; ++i)
        extent[i] =
            std::uint32_t(std::min<std::uint64_t>(b, g.dims[i] - std::uint64_t(pos[i]) * b));
    const T* v = static_cast<const T*>(job.voxels);
    const std::uint32_t leaf = job.occupancy ? job.occupancy->leafVoxels() : b;
    const std::uint32_t depth = job.occupancy ? job.occupancy->depth() : 0;
    auto centreOf = [&](std::uint32_t x, std::uint32_t y, std::uint32_t z) {
        const glm::dvec3 voxel{double(pos[0]) * b + x, double(pos[1]) * b + y,
                               double(pos[2]) * b + z};
        return (voxel + 0.5) * g.spacing;
    };
    auto valueOf = [&](std::uint32_t s) { return v ? float(v[s]) : job.brick->constantValue; };
    // Sorted as (depth, stored index) keys, the voxels built after: a quarter of the data
    // moved, and the same comparisons, so the same order as sorting the voxels themselves.
    std::vector<std::pair<double, std::uint32_t>> keys;
    for (std::uint32_t lz = 0; lz * leaf < extent[2]; ++lz)
        for (std::uint32_t ly = 0; ly * leaf < extent[1]; ++ly)
            for (std::uint32_t lx = 0; lx * leaf < extent[0]; ++lx) {
                if (job.occupancy &&
                    !leafOccupied(*job.occupancy, job.brick->index, depth, lx, ly, lz)) {
                    ++leaves;
                    continue;
                }
                for (std::uint32_t z = lz * leaf; z < std::min(extent[2], (lz + 1) * leaf); ++z)
                    for (std::uint32_t y = ly * leaf; y < std::min(extent[1], (ly + 1) * leaf); ++y)
                        for (std::uint32_t x = lx * leaf; x < std::min(extent[0], (lx + 1) * leaf);
                             ++x) {
                            const std::uint32_t s = ((z + a) * edge + (y + a)) * edge + (x + a);
                            if (f.table->lookup(valueOf(s))[3] <= 0.0f) continue;
                            const glm::dvec3 rel = centreOf(x, y, z) - f.view.eye;
                            const double d = f.view.orthographic ? glm::dot(rel, f.view.forward)
                                                                 : glm::length(rel);
                            keys.emplace_back(d, s);
                        }
            }
    std::sort(keys.begin(), keys.end(),
              [](const auto& l, const auto& r) { return l.first < r.first; });
    std::vector<Visible> out;
    out.reserve(keys.size());
    for (const auto& [d, s] : keys) {
        const std::uint32_t x = s % edge - a, y = s / edge % edge - a, z = s / edge / edge - a;
        out.push_back({d, s, centreOf(x, y, z), valueOf(s)});
    }
    return out;
}

/// The visible voxels of one brick, front to back, classified and shaded. Thread-safe.
template <class T>
std::vector<Visible> prepareBrick(const Frame& f, const BrickJob& job, std::uint64_t& leaves) {
    const int edge = int(f.g.brickVoxels + 2 * f.g.apronVoxels);
    const T* v = static_cast<const T*>(job.voxels);
    std::vector<Visible> voxels = visibleVoxels<T>(f, job, leaves);
    for (Visible& vis : voxels) {
        vis.rgba = f.table->lookup(vis.value);
        if (!f.shading || !v) continue; // a constant brick has no gradient
        const glm::dvec3 dir =
            f.view.orthographic ? f.view.forward : glm::normalize(vis.centre - f.view.eye);
        shade(f, v, edge, vis.stored, dir, vis.rgba.data());
    }
    return voxels;
}

std::vector<Visible> prepareOfType(brickstore::VoxelType type, const Frame& f, const BrickJob& job,
                                   std::uint64_t& leaves) {
    switch (type) {
    case brickstore::VoxelType::U8:
        return prepareBrick<std::uint8_t>(f, job, leaves);
    case brickstore::VoxelType::U16:
        return prepareBrick<std::uint16_t>(f, job, leaves);
    case brickstore::VoxelType::I16:
        return prepareBrick<std::int16_t>(f, job, leaves);
    case brickstore::VoxelType::F32:
        return prepareBrick<float>(f, job, leaves);
    }
    return {};
}

} // namespace

Frame frameOf(const HybridSplatterConfig& config, const LevelGeometry& g, const ViewBasis& basis,
              const RenderOptions& o, const TransferFunctionTable& table) {
    Frame f;
    f.view = SplatView::from(basis, o.width, o.height);
    f.g = g;
    f.table = &table;
    const double maxSpacing = std::max({g.spacing.x, g.spacing.y, g.spacing.z});
    f.radiusMm = config.radiusVoxels * maxSpacing;
    f.depthScale =
        g.spacing.x * g.spacing.y * g.spacing.z / (f.radiusMm * f.radiusMm * g.minSpacing());
    f.slabMm = maxSpacing;
    const double edgeMm = std::cbrt(g.spacing.x * g.spacing.y * g.spacing.z);
    f.voxelSteps = edgeMm / g.minSpacing();
    f.voxelAreaMm2 = edgeMm * edgeMm;
    f.pointThreshold = config.pointThresholdPixels;
    f.pointFilter = config.pointFilterPixels;
    f.shading = o.shading;
    f.cull = config.occlusionCulling && o.earlyTermination;
    f.gradScale = 0.5 / (table.domainMax - table.domainMin) * g.minSpacing() / g.spacing;
    return f;
}

SplatScene sceneOf(const Scene& scene, const View& view, const RenderOptions& options,
                   FrameStats& stats) {
    options.validate();
    Renderer::checkView(view, options, true); // both splatters draw regions
    Renderer::refusePreintegration(options, "splatters");
    Renderer::refuseModesAndClips(options, "splatters");
    const auto levels = std::uint32_t(scene.store.layout().levels().size());
    const std::uint32_t level = std::min<std::uint32_t>(std::uint32_t(options.level), levels - 1);
    return {level, LevelGeometry::of(scene.store, level),
            classifyFrame(scene, level, options, 1.0, stats)};
}

bool pixelRect(const glm::dvec2& lo, const glm::dvec2& hi, std::uint32_t w, std::uint32_t h,
               std::uint32_t r[4]) {
    const double x0 = std::ceil(lo.x + 0.5 * w - 0.5), x1 = std::floor(hi.x + 0.5 * w - 0.5);
    const double y0 = std::ceil(0.5 * h - 0.5 - hi.y), y1 = std::floor(0.5 * h - 0.5 - lo.y);
    if (!(x1 >= 0.0 && y1 >= 0.0 && x0 <= double(w) - 1 && y0 <= double(h) - 1 && x0 <= x1 &&
          y0 <= y1))
        return false;
    r[0] = std::uint32_t(std::max(x0, 0.0));
    r[1] = std::uint32_t(std::max(y0, 0.0));
    r[2] = std::uint32_t(std::min(x1, double(w) - 1));
    r[3] = std::uint32_t(std::min(y1, double(h) - 1));
    return true;
}

bool meetsRegion(const std::uint32_t r[4], const PixelRect& region) {
    return r[0] < region.x + region.width && r[2] >= region.x && r[1] < region.y + region.height &&
           r[3] >= region.y;
}

BrickReach brickReach(const Frame& f, const PlannedBrick& b, std::uint32_t w, std::uint32_t h) {
    const Box box = f.g.brickBox(b.key.pos);
    glm::dvec2 lo(1e300), hi(-1e300);
    for (int corner = 0; corner < 8; ++corner) {
        const glm::dvec3 c((corner & 1) ? box.max.x + f.radiusMm : box.min.x - f.radiusMm,
                           (corner & 2) ? box.max.y + f.radiusMm : box.min.y - f.radiusMm,
                           (corner & 4) ? box.max.z + f.radiusMm : box.min.z - f.radiusMm);
        const glm::dvec3 rel = c - f.view.eye;
        const double z = glm::dot(rel, f.view.forward);
        if (!f.view.orthographic && !(z > 0.0)) return {}; // reaches behind the eye
        const double scale = f.view.orthographic ? f.view.orthoScale : f.view.focalLength / z;
        const glm::dvec2 p =
            scale * glm::dvec2(glm::dot(rel, f.view.right), glm::dot(rel, f.view.up));
        lo = glm::min(lo, p);
        hi = glm::max(hi, p);
    }
    const double grow = f.pointFilter + 1.0;
    BrickReach reach;
    reach.kind = pixelRect(lo - grow, hi + grow, w, h, reach.rect) ? BrickReach::Kind::Rect
                                                                   : BrickReach::Kind::Nowhere;
    return reach;
}

void cullOutsideRegion(const Frame& f, const PixelRect& region, std::uint32_t width,
                       std::uint32_t height, BrickPlan& plan) {
    if (region.whole()) return;
    std::erase_if(plan.drawn, [&](const PlannedBrick& b) {
        if (!brickReach(f, b, width, height).misses(region)) return false;
        ++plan.culled;
        --(b.draw == BrickDraw::Constant ? plan.constant : plan.sampled);
        return true;
    });
}

std::size_t chunkEnd(const BrickPlan& plan, std::size_t first, std::uint64_t brickBytes,
                     std::uint64_t budgetBytes) {
    const std::size_t last = std::min(plan.drawn.size(), first + kChunkBricks);
    std::uint64_t bytes = 0;
    std::size_t end = first;
    for (; end < last; ++end) {
        if (plan.drawn[end].draw != BrickDraw::Sampled) continue;
        if (bytes > 0 && bytes + brickBytes > budgetBytes) break;
        bytes += brickBytes;
    }
    return end;
}

void prepareChunk(const Frame& f, const BrickPlan& plan, std::size_t first,
                  brickstore::BrickCache& cache, brickstore::VoxelType type,
                  const OccupancyTrees* occupancy, std::vector<PreparedBrick>& chunk) {
    tbb::parallel_for(std::size_t(0), chunk.size(), [&](std::size_t i) {
        const PlannedBrick& b = plan.drawn[first + i];
        PreparedBrick& p = chunk[i];
        if (p.culled) return;
        if (b.draw == BrickDraw::Sampled) p.pin = cache.pin(b.key);
        const BrickJob job{&b, p.pin ? p.pin.data().data() : nullptr,
                           b.draw == BrickDraw::Sampled ? occupancy : nullptr};
        p.voxels = prepareOfType(type, f, job, p.leavesSkipped);
    });
}

VoxelDraw classifyDraw(const Frame& f, const glm::dvec3& centre, float a) {
    VoxelDraw d;
    const glm::dvec3 rel = centre - f.view.eye;
    const double z = glm::dot(rel, f.view.forward);
    if (!(z > f.radiusMm)) return d; // touches the eye plane: no ellipse
    d.scale = f.view.orthographic ? f.view.orthoScale : f.view.focalLength / z;
    const double rho = f.radiusMm * d.scale;
    d.lnT = -std::log(1.0 - std::min(double(a), kMaxOpacity));
    d.kind = rho < f.pointThreshold ? VoxelDraw::Kind::Point : VoxelDraw::Kind::Splat;
    if (d.kind == VoxelDraw::Kind::Point)
        d.image = d.scale * glm::dvec2(glm::dot(rel, f.view.right), glm::dot(rel, f.view.up));
    return d;
}

PointFilter pointFilterOf(const Frame& f, const SplatFootprint& fp, const VoxelDraw& d,
                          std::uint32_t width, std::uint32_t height) {
    // A point covers its voxel's projected area (pixels^2) with the voxel's opacity over one
    // voxel of path; that coverage is spread by the footprint at each pixel centre,
    // normalised over the unclipped lattice, so no point is lost between pixel centres.
    const double R = f.pointFilter;
    PointFilter pf;
    pf.fx = d.image.x + 0.5 * width - 0.5;
    pf.fy = 0.5 * height - 0.5 - d.image.y;
    const int x0 = int(std::ceil(pf.fx - R)), x1 = int(std::floor(pf.fx + R));
    const int y0 = int(std::ceil(pf.fy - R)), y1 = int(std::floor(pf.fy + R));
    for (int y = y0; y <= y1; ++y)
        for (int x = x0; x <= x1; ++x)
            pf.sum += pointWeight(f, fp, pf, x, y);
    pf.total = (1.0 - std::exp(-d.lnT * f.voxelSteps)) * f.voxelAreaMm2 * d.scale * d.scale;
    return pf;
}

double pointWeight(const Frame& f, const SplatFootprint& fp, const PointFilter& pf, int x, int y) {
    return fp.lineIntegral(std::hypot(x - pf.fx, y - pf.fy) / f.pointFilter);
}

} // namespace bc::render::detail
