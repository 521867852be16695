#include "render/HybridSplatter.h"

#include "brickstore/BrickCache.h"
#include "brickstore/BrickStore.h"
#include "render/BrickPlan.h"
#include "render/Occupancy.h"
#include "render/SplatFootprint.h"
#include "render/SplatGeometry.h"
#include "render/TransferFunction.h"
#include "render/detail/SplatPrep.h"

#include <algorithm>
#include <chrono>
#include <cmath>
#include <stdexcept>
#include <vector>

#include <glm/geometric.hpp>

namespace bc::render {
namespace {

using detail::Frame;
using detail::kChunkBricks;
using detail::PointFilter;
using detail::PreparedBrick;
using detail::SplatScene;
using detail::Visible;
using detail::VoxelDraw;

using Clock = std::chrono::steady_clock;
double msSince(Clock::time_point t) {
    return std::chrono::duration<double, std::milli>(Clock::now() - t).count();
}

/// The image, its per-tile count of pixels still below the threshold, and the point slab.
class Canvas {
  public:
    Canvas(std::uint32_t w, std::uint32_t h, std::uint32_t tile, double ert)
        : image(w, h), mTile(tile), mTilesX((w + tile - 1) / tile), mErt(float(ert)),
          mSlab(std::size_t(w) * h * 4, 0.0f) {
        mOpen.assign(std::size_t(mTilesX) * ((h + tile - 1) / tile), 0);
        for (std::uint32_t y = 0; y < h; ++y)
            for (std::uint32_t x = 0; x < w; ++x)
                ++mOpen[tileOf(x, y)];
        if (mErt > 1.0f) mOpen.assign(mOpen.size(), 1u << 30); // never opaque
    }

    Image image;

    /// Front-to-back 'over' of straight colour `c` with opacity `a` into pixel (x, y).
    void over(std::uint32_t x, std::uint32_t y, float a, const float* c) {
        float* p = image.pixel(x, y);
        if (p[3] >= mErt) return;
        const float w = (1.0f - p[3]) * a;
        p[0] += w * c[0];
        p[1] += w * c[1];
        p[2] += w * c[2];
        p[3] += w;
        if (p[3] >= mErt) --mOpen[tileOf(x, y)];
    }
    /// True when every tile meeting the pixel rectangle [x0, x1] x [y0, y1] is opaque.
    bool occluded(std::uint32_t x0, std::uint32_t y0, std::uint32_t x1, std::uint32_t y1) const {
        for (std::uint32_t ty = y0 / mTile; ty <= y1 / mTile; ++ty)
            for (std::uint32_t tx = x0 / mTile; tx <= x1 / mTile; ++tx)
                if (mOpen[std::size_t(ty) * mTilesX + tx] > 0) return false;
        return true;
    }
    /// Adds coverage `cover` (area share times opacity) of colour `c` to the slab at (x, y).
    void deposit(std::uint32_t x, std::uint32_t y, float cover, const float* c) {
        float* s = mSlab.data() + (std::size_t(y) * image.width + x) * 4;
        if (s[3] == 0.0f) mDirty.push_back(std::uint32_t(y * image.width + x));
        s[0] += cover * c[0];
        s[1] += cover * c[1];
        s[2] += cover * c[2];
        s[3] += cover;
    }
    bool slabOpen() const { return mSlabOpen; }
    double slabEnd() const { return mSlabEnd; }
    void openSlab(double end) {
        mSlabOpen = true;
        mSlabEnd = end;
    }
    /// Composites the slab (summed coverage, at most 1; coverage-weighted colour), empties it.
    bool flushSlab() {
        if (!mSlabOpen) return false;
        for (std::uint32_t i : mDirty) {
            float* s = mSlab.data() + std::size_t(i) * 4;
            if (s[3] > 0.0f) {
                const float c[3] = {s[0] / s[3], s[1] / s[3], s[2] / s[3]};
                over(i % image.width, i / image.width, std::min(s[3], 1.0f), c);
            }
            s[0] = s[1] = s[2] = s[3] = 0.0f;
        }
        mDirty.clear();
        mSlabOpen = false;
        return true;
    }

  private:
    std::size_t tileOf(std::uint32_t x, std::uint32_t y) const {
        return std::size_t(y / mTile) * mTilesX + x / mTile;
    }
    std::uint32_t mTile, mTilesX;
    float mErt;
    std::vector<std::uint32_t> mOpen;
    std::vector<float> mSlab;
    std::vector<std::uint32_t> mDirty;
    bool mSlabOpen = false;
    double mSlabEnd = 0.0;
};

class Drawer {
  public:
    Drawer(const Frame& f, const SplatFootprint& fp, Canvas& canvas, HybridSplatStats& n)
        : mF(f), mFp(fp), mCanvas(canvas), mN(n) {}

    /// Draws one classified voxel (straight colour c, opacity a per unit step) at `depth`.
    void draw(const glm::dvec3& centre, double depth, const float* c, float a) {
        const VoxelDraw d = detail::classifyDraw(mF, centre, a);
        if (d.kind == VoxelDraw::Kind::Point)
            point(d, depth, c);
        else if (d.kind == VoxelDraw::Kind::Splat)
            splat(centre, c, d.lnT);
    }

  private:
    void point(const VoxelDraw& d, double depth, const float* c) {
        const double R = mF.pointFilter;
        std::uint32_t r[4];
        if (!detail::pixelRect(d.image - R, d.image + R, mCanvas.image.width, mCanvas.image.height,
                               r))
            return;
        // Slabs are cut as if nothing were culled, so that culling changes no slab's sum.
        if (mCanvas.slabOpen() && depth > mCanvas.slabEnd()) mN.slabs += mCanvas.flushSlab();
        if (!mCanvas.slabOpen()) mCanvas.openSlab(depth + mF.slabMm);
        if (mF.cull && mCanvas.occluded(r[0], r[1], r[2], r[3])) {
            ++mN.culled;
            return;
        }
        ++mN.points;
        // The slab adds coverages: an area average, as a box filter of the pixel would.
        const std::uint32_t w = mCanvas.image.width, h = mCanvas.image.height;
        const PointFilter pf = detail::pointFilterOf(mF, mFp, d, w, h);
        if (!(pf.sum > 0.0)) {
            const long nx = std::lround(pf.fx), ny = std::lround(pf.fy);
            if (nx >= 0 && ny >= 0 && nx < long(w) && ny < long(h))
                mCanvas.deposit(std::uint32_t(nx), std::uint32_t(ny), float(pf.total), c);
            return;
        }
        for (std::uint32_t y = r[1]; y <= r[3]; ++y)
            for (std::uint32_t x = r[0]; x <= r[2]; ++x) {
                const double fp = detail::pointWeight(mF, mFp, pf, int(x), int(y));
                if (fp > 0.0) mCanvas.deposit(x, y, float(pf.total * fp / pf.sum), c);
            }
    }

    void splat(const glm::dvec3& centre, const float* c, double lnT) {
        const SplatProjection proj = projectSphere(mF.view, centre, mF.radiusMm);
        if (!proj.ok()) return;
        const SplatEllipse& e = proj.ellipse;
        const glm::dvec2 half = e.halfExtent();
        std::uint32_t r[4];
        const std::uint32_t w = mCanvas.image.width, h = mCanvas.image.height;
        if (!detail::pixelRect(e.centre - half, e.centre + half, w, h, r)) return;
        mN.slabs += mCanvas.flushSlab(); // points in front go first, culled or not
        if (mF.cull && mCanvas.occluded(r[0], r[1], r[2], r[3])) {
            ++mN.culled;
            return;
        }
        ++mN.splats;
        const double k = lnT * mF.depthScale;
        for (std::uint32_t y = r[1]; y <= r[3]; ++y)
            for (std::uint32_t x = r[0]; x <= r[2]; ++x) {
                const double i =
                    coneIndex(mF.view, centre, mF.radiusMm, SplatView::pixelCentre(x, y, w, h));
                if (!(i < 1.0)) continue;
                const double fp = mFp.lookup(i, e.halfAngleRad);
                if (fp > 0.0) mCanvas.over(x, y, float(1.0 - std::exp(-k * fp)), c);
            }
    }

    const Frame& mF;
    const SplatFootprint& mFp;
    Canvas& mCanvas;
    HybridSplatStats& mN;
};

} // namespace

void HybridSplatterConfig::validate() const {
    if (!(radiusVoxels >= 0.5 && radiusVoxels <= 8.0))
        throw std::invalid_argument("HybridSplatterConfig.radiusVoxels must be in [0.5, 8]");
    SplatFootprintConfig{sigmaOverRadius}.validate();
    if (!(pointThresholdPixels >= 0.0 && std::isfinite(pointThresholdPixels)))
        throw std::invalid_argument("HybridSplatterConfig.pointThresholdPixels must be >= 0");
    if (!(pointFilterPixels >= 0.5 && pointFilterPixels <= 16.0))
        throw std::invalid_argument("HybridSplatterConfig.pointFilterPixels must be in [0.5, 16]");
    if (tilePixels < 1 || tilePixels > 256)
        throw std::invalid_argument("HybridSplatterConfig.tilePixels must be in [1, 256]");
}

HybridSplatter::HybridSplatter(const HybridSplatterConfig& config)
    : mConfig((config.validate(), config)),
      mFootprint(SplatFootprintConfig{config.sigmaOverRadius}) {}
HybridSplatter::~HybridSplatter() = default;

namespace {

/// True when every pixel brick `b` can touch is opaque: the tiles meeting the screen box of
/// its world box grown by the sphere radius (and a point's filter) are all at the threshold.
bool brickOccluded(const Frame& f, const Canvas& canvas, const PlannedBrick& b) {
    const Box box = f.g.brickBox(b.key.pos);
    glm::dvec2 lo(1e300), hi(-1e300);
    for (int corner = 0; corner < 8; ++corner) {
        const glm::dvec3 c((corner & 1) ? box.max.x + f.radiusMm : box.min.x - f.radiusMm,
                           (corner & 2) ? box.max.y + f.radiusMm : box.min.y - f.radiusMm,
                           (corner & 4) ? box.max.z + f.radiusMm : box.min.z - f.radiusMm);
        const glm::dvec3 rel = c - f.view.eye;
        const double z = glm::dot(rel, f.view.forward);
        if (!f.view.orthographic && !(z > 0.0)) return false; // reaches behind the eye
        const double scale = f.view.orthographic ? f.view.orthoScale : f.view.focalLength / z;
        const glm::dvec2 p =
            scale * glm::dvec2(glm::dot(rel, f.view.right), glm::dot(rel, f.view.up));
        lo = glm::min(lo, p);
        hi = glm::max(hi, p);
    }
    const double grow = f.pointFilter + 1.0;
    std::uint32_t r[4];
    if (!detail::pixelRect(lo - grow, hi + grow, canvas.image.width, canvas.image.height, r))
        return true;
    return canvas.occluded(r[0], r[1], r[2], r[3]);
}

} // namespace

Image HybridSplatter::render(const brickstore::BrickStore& store, brickstore::BrickCache& cache,
                             const TransferFunction& tf, const Camera& camera,
                             const RenderOptions& options, FrameStats& stats) {
    const auto frameStart = Clock::now();
    // Opacity per unit step: the footprint supplies each voxel's own path length.
    const SplatScene scene = detail::sceneOf(store, tf, camera, options);
    stats = FrameStats{};
    mLast = HybridSplatStats{};
    const std::uint32_t level = scene.level;
    const LevelGeometry& g = scene.g;
    const ViewBasis& basis = scene.basis;
    const TransferFunctionTable& table = scene.table;
    const bool octree = scene.octree;
    if (octree) updateOccupancy(store, level, table, options, stats);
    const BrickPlan plan =
        planBricks(store, g, table, basis, options.skip, octree ? mOccupancy.get() : nullptr);
    recordPlan(plan, level, stats);
    stats.batches = 1;

    const Frame f = detail::frameOf(mConfig, g, basis, options, table);
    Canvas canvas(options.width, options.height, mConfig.tilePixels,
                  options.earlyTermination ? options.ertThreshold : 2.0);
    Drawer drawer(f, mFootprint, canvas, mLast);
    const auto type = store.info().volume.type;
    for (std::size_t first = 0; first < plan.drawn.size(); first += kChunkBricks) {
        const std::size_t count = std::min(kChunkBricks, plan.drawn.size() - first);
        std::vector<PreparedBrick> chunk(count);
        for (std::size_t i = 0; i < count; ++i)
            chunk[i].culled = f.cull && brickOccluded(f, canvas, plan.drawn[first + i]);
        const auto prepareStart = Clock::now();
        detail::prepareChunk(f, plan, first, cache, type, octree ? mOccupancy.get() : nullptr,
                             chunk);
        stats.uploadMs += msSince(prepareStart);
        for (std::size_t i = 0; i < count; ++i) {
            PreparedBrick& p = chunk[i];
            // Bricks drawn earlier in the chunk may have covered this one since.
            if (p.culled || (f.cull && brickOccluded(f, canvas, plan.drawn[first + i]))) {
                ++mLast.bricksCulled;
                continue;
            }
            mLast.leavesSkipped += p.leavesSkipped;
            for (const Visible& vis : p.voxels)
                drawer.draw(vis.centre, vis.depth, vis.rgba.data(), vis.rgba[3]);
            mLast.slabs += canvas.flushSlab(); // the next brick may lie in front of this slab
        }
    }
    for (float& v : canvas.image.rgba)
        v = std::clamp(v, 0.0f, 1.0f);
    stats.samples = mLast.points + mLast.splats;
    stats.octreeLeaps = mLast.leavesSkipped;
    stats.occlusionReason = "not on the splatter";
    stats.totalMs = msSince(frameStart);
    stats.renderMs = stats.totalMs - stats.uploadMs;
    return std::move(canvas.image);
}

void HybridSplatter::updateOccupancy(const brickstore::BrickStore& store, std::uint32_t level,
                                     const TransferFunctionTable& table,
                                     const RenderOptions& options, FrameStats& stats) {
    detail::updateOccupancy(mOccupancy, mStore, mStorePath, store, level, table, options, stats);
}

} // namespace bc::render
