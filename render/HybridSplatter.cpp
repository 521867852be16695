#include "render/HybridSplatter.h"

#include "brickstore/BrickCache.h"
#include "brickstore/BrickStore.h"
#include "render/BrickPlan.h"
#include "render/Occupancy.h"
#include "render/SplatFootprint.h"
#include "render/SplatGeometry.h"
#include "render/TransferFunction.h"

#include <tbb/parallel_for.h>

#include <algorithm>
#include <array>
#include <chrono>
#include <cmath>
#include <stdexcept>
#include <vector>

#include <glm/geometric.hpp>

namespace bc::render {
namespace {

using Clock = std::chrono::steady_clock;
double msSince(Clock::time_point t) {
    return std::chrono::duration<double, std::milli>(Clock::now() - t).count();
}

constexpr std::uint32_t kTfEntries = 4096; // as the raycasters' table
constexpr double kMaxOpacity = 1.0 - 1e-6; // keeps -log(1 - a) finite

/// Everything a voxel needs to be drawn.
struct Frame {
    SplatView view;
    LevelGeometry g;
    const TransferFunctionTable* table = nullptr;
    double radiusMm = 1.0;
    double depthScale = 1.0; ///< V / (r^2 minSpacing): footprint -> steps of one voxel
    double slabMm = 1.0;
    double voxelSteps = 1.0;   ///< cube root of the voxel volume, in steps of minSpacing
    double voxelAreaMm2 = 1.0; ///< the voxel volume to the power 2/3
    double pointThreshold = 0.5, pointFilter = 1.0;
    bool shading = true, cull = true;
    glm::dvec3 gradScale{1.0};
};

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

/// Pixel rectangle of image-plane box [lo, hi], clipped; false when empty.
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

/// One visible voxel of a brick, waiting for its turn.
struct Visible {
    double depth;
    std::uint32_t stored; ///< index in the stored brick (apron included); voxel for constants
    glm::dvec3 centre;
    float value;
    std::array<float, 4> rgba{}; ///< classified and shaded: straight colour, opacity per step
};

class Drawer {
  public:
    Drawer(const Frame& f, const SplatFootprint& fp, Canvas& canvas, HybridSplatStats& n)
        : mF(f), mFp(fp), mCanvas(canvas), mN(n) {}

    /// Draws one classified voxel (straight colour c, opacity a per unit step) at `depth`.
    void draw(const glm::dvec3& centre, double depth, const float* c, float a) {
        const glm::dvec3 rel = centre - mF.view.eye;
        const double z = glm::dot(rel, mF.view.forward);
        if (!(z > mF.radiusMm)) return; // touches the eye plane: no ellipse
        const double scale = mF.view.orthographic ? mF.view.orthoScale : mF.view.focalLength / z;
        const double rho = mF.radiusMm * scale;
        const double lnT = -std::log(1.0 - std::min(double(a), kMaxOpacity));
        if (rho < mF.pointThreshold)
            point(scale * glm::dvec2(glm::dot(rel, mF.view.right), glm::dot(rel, mF.view.up)),
                  scale, depth, c, lnT);
        else
            splat(centre, c, lnT);
    }

  private:
    void point(const glm::dvec2& p, double scale, double depth, const float* c, double lnT) {
        const double R = mF.pointFilter;
        std::uint32_t r[4];
        if (!pixelRect(p - R, p + R, mCanvas.image.width, mCanvas.image.height, r)) return;
        if (mF.cull && mCanvas.occluded(r[0], r[1], r[2], r[3])) {
            ++mN.culled;
            return;
        }
        if (mCanvas.slabOpen() && depth > mCanvas.slabEnd()) mN.slabs += mCanvas.flushSlab();
        if (!mCanvas.slabOpen()) mCanvas.openSlab(depth + mF.slabMm);
        ++mN.points;
        // A point covers its voxel's projected area (pixels^2) with the voxel's opacity over
        // one voxel of path; that coverage is spread by the footprint at each pixel centre,
        // normalised over the unclipped lattice, so no point is lost between pixel centres.
        // The slab adds coverages: an area average, as a box filter of the pixel would.
        const std::uint32_t w = mCanvas.image.width, h = mCanvas.image.height;
        const double fx = p.x + 0.5 * w - 0.5, fy = 0.5 * h - 0.5 - p.y;
        const int x0 = int(std::ceil(fx - R)), x1 = int(std::floor(fx + R));
        const int y0 = int(std::ceil(fy - R)), y1 = int(std::floor(fy + R));
        auto weight = [&](int x, int y) {
            return mFp.lineIntegral(std::hypot(x - fx, y - fy) / R);
        };
        double sum = 0.0;
        for (int y = y0; y <= y1; ++y)
            for (int x = x0; x <= x1; ++x)
                sum += weight(x, y);
        const double total =
            (1.0 - std::exp(-lnT * mF.voxelSteps)) * mF.voxelAreaMm2 * scale * scale;
        if (!(sum > 0.0)) {
            const long nx = std::lround(fx), ny = std::lround(fy);
            if (nx >= 0 && ny >= 0 && nx < long(w) && ny < long(h))
                mCanvas.deposit(std::uint32_t(nx), std::uint32_t(ny), float(total), c);
            return;
        }
        for (std::uint32_t y = r[1]; y <= r[3]; ++y)
            for (std::uint32_t x = r[0]; x <= r[2]; ++x) {
                const double fp = weight(int(x), int(y));
                if (fp > 0.0) mCanvas.deposit(x, y, float(total * fp / sum), c);
            }
    }

    void splat(const glm::dvec3& centre, const float* c, double lnT) {
        const SplatProjection proj = projectSphere(mF.view, centre, mF.radiusMm);
        if (!proj.ok()) return;
        const SplatEllipse& e = proj.ellipse;
        const glm::dvec2 half = e.halfExtent();
        std::uint32_t r[4];
        const std::uint32_t w = mCanvas.image.width, h = mCanvas.image.height;
        if (!pixelRect(e.centre - half, e.centre + half, w, h, r)) return;
        if (mF.cull && mCanvas.occluded(r[0], r[1], r[2], r[3])) {
            ++mN.culled;
            return;
        }
        mN.slabs += mCanvas.flushSlab(); // points in front go first
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
    std::vector<Visible> out;
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
                            const float value = v ? float(v[s]) : job.brick->constantValue;
                            if (f.table->lookup(value)[3] <= 0.0f) continue;
                            const glm::dvec3 voxel{double(pos[0]) * b + x, double(pos[1]) * b + y,
                                                   double(pos[2]) * b + z};
                            const glm::dvec3 c = (voxel + 0.5) * g.spacing;
                            const glm::dvec3 rel = c - f.view.eye;
                            const double d = f.view.orthographic ? glm::dot(rel, f.view.forward)
                                                                 : glm::length(rel);
                            out.push_back({d, s, c, value});
                        }
            }
    std::sort(out.begin(), out.end(),
              [](const Visible& l, const Visible& r) { return l.depth < r.depth; });
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
    if (!pixelRect(lo - grow, hi + grow, canvas.image.width, canvas.image.height, r)) return true;
    return canvas.occluded(r[0], r[1], r[2], r[3]);
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

/// A brick made ready on a worker: pinned, its visible voxels sorted and shaded.
struct PreparedBrick {
    brickstore::BrickPin pin;
    std::vector<Visible> voxels;
    std::uint64_t leavesSkipped = 0;
    bool culled = false;
};

/// Bricks prepared in parallel per chunk, drawn in order: enough bricks to keep the workers
/// busy, few enough that the culling test before a chunk is still sharp.
constexpr std::size_t kChunkBricks = 16;

} // namespace

Image HybridSplatter::render(const brickstore::BrickStore& store, brickstore::BrickCache& cache,
                             const TransferFunction& tf, const Camera& camera,
                             const RenderOptions& options, FrameStats& stats) {
    const auto frameStart = Clock::now();
    options.validate();
    camera.validate();
    stats = FrameStats{};
    mLast = HybridSplatStats{};
    const auto levels = std::uint32_t(store.layout().levels().size());
    const std::uint32_t level = std::min<std::uint32_t>(std::uint32_t(options.level), levels - 1);
    const LevelGeometry g = LevelGeometry::of(store, level);
    const ViewBasis basis = ViewBasis::from(camera, options.width, options.height);
    // Opacity per unit step: the footprint supplies each voxel's own path length.
    const TransferFunctionTable table = tf.table(1.0, kTfEntries);
    const bool octree = options.skip == SkipMode::All && g.apronVoxels > 0;
    if (octree) updateOccupancy(store, level, table, options, stats);
    const BrickPlan plan =
        planBricks(store, g, table, basis, options.skip, octree ? mOccupancy.get() : nullptr);
    recordPlan(plan, level, stats);
    stats.batches = 1;

    const Frame f = frameOf(mConfig, g, basis, options, table);
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
        tbb::parallel_for(std::size_t(0), count, [&](std::size_t i) {
            const PlannedBrick& b = plan.drawn[first + i];
            PreparedBrick& p = chunk[i];
            if (p.culled) return;
            if (b.draw == BrickDraw::Sampled) p.pin = cache.pin(b.key);
            const BrickJob job{&b, p.pin ? p.pin.data().data() : nullptr,
                               octree && b.draw == BrickDraw::Sampled ? mOccupancy.get() : nullptr};
            p.voxels = prepareOfType(type, f, job, p.leavesSkipped);
        });
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
    if (!mOccupancy || mStore != &store || mStorePath != store.path() ||
        mOccupancy->level() != level) {
        mOccupancy = std::make_unique<OccupancyTrees>(store, level);
        mStore = &store;
        mStorePath = store.path();
    }
    const auto rebuild = mOccupancy->update(table, options.octree);
    stats.octreeBricksRebuilt = rebuild.bricksRebuilt;
    stats.octreeRebuildMs = rebuild.ms;
}

} // namespace bc::render
