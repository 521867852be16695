#include "render/HybridSplatter.h"

#include "brickstore/BrickCache.h"
#include "brickstore/BrickStore.h"
#include "render/BrickPlan.h"
#include "render/Occupancy.h"
#include "render/SplatFootprint.h"
#include "render/SplatGeometry.h"
#include "render/TransferFunction.h"
#include "render/detail/SplatPrep.h"

#include <tbb/blocked_range.h>
#include <tbb/parallel_for.h>
#include <tbb/task_arena.h>

#include <algorithm>
#include <chrono>
#include <cmath>
#include <stdexcept>
#include <vector>

#include <glm/geometric.hpp>

namespace bc::render {
namespace {

using detail::BrickReach;
using detail::Frame;
using detail::PreparedBrick;
using detail::SplatScene;
using detail::Visible;
using detail::VoxelDraw;

using Clock = std::chrono::steady_clock;
double msSince(Clock::time_point t) {
    return std::chrono::duration<double, std::milli>(Clock::now() - t).count();
}

/// The region's pixels of the image, their per-tile count of pixels still below the threshold
/// (tiles counted from the region's corner), and the point slab. Pixels are addressed in
/// whole-image coordinates. Workers draw disjoint bands of whole tile rows: each owns its rows
/// of all three, and keeps its own list of the slab pixels it dirtied.
class Canvas {
  public:
    Canvas(const PixelRect& region, std::uint32_t tile, double ert)
        : image(region.width, region.height), mRegion(region), mTile(tile),
          mTilesX((region.width + tile - 1) / tile), mErt(float(ert)),
          mSlab(std::size_t(region.pixels()) * 4, 0.0f) {
        mOpen.assign(std::size_t(mTilesX) * ((region.height + tile - 1) / tile), 0);
        for (std::uint32_t y = 0; y < region.height; ++y)
            for (std::uint32_t x = 0; x < region.width; ++x)
                ++mOpen[tileOf(x, y)];
        if (mErt > 1.0f) mOpen.assign(mOpen.size(), 1u << 30); // never opaque
    }

    Image image; ///< the region's pixels

    std::uint32_t tile() const { return mTile; }
    const PixelRect& region() const { return mRegion; }
    /// Front-to-back 'over' of straight colour `c` with opacity `a` into pixel (x, y).
    void over(std::uint32_t x, std::uint32_t y, float a, const float* c) {
        overLocal(x - mRegion.x, y - mRegion.y, a, c);
    }
    /// True when every tile meeting the pixel rectangle [x0, x1] x [y0, y1] (inside the
    /// region) is opaque.
    bool occluded(std::uint32_t x0, std::uint32_t y0, std::uint32_t x1, std::uint32_t y1) const {
        x0 -= mRegion.x, x1 -= mRegion.x, y0 -= mRegion.y, y1 -= mRegion.y;
        for (std::uint32_t ty = y0 / mTile; ty <= y1 / mTile; ++ty)
            for (std::uint32_t tx = x0 / mTile; tx <= x1 / mTile; ++tx)
                if (mOpen[std::size_t(ty) * mTilesX + tx] > 0) return false;
        return true;
    }
    /// Adds coverage `cover` (area share times opacity) of colour `c` to the slab at (x, y).
    void deposit(std::uint32_t x, std::uint32_t y, float cover, const float* c,
                 std::vector<std::uint32_t>& dirty) {
        const std::uint32_t i = (y - mRegion.y) * image.width + (x - mRegion.x);
        float* s = mSlab.data() + std::size_t(i) * 4;
        if (s[3] == 0.0f) dirty.push_back(i);
        s[0] += cover * c[0];
        s[1] += cover * c[1];
        s[2] += cover * c[2];
        s[3] += cover;
    }
    /// Composites the `dirty` slab pixels (summed coverage, at most 1; coverage-weighted
    /// colour) and empties them.
    void flushSlab(std::vector<std::uint32_t>& dirty) {
        for (std::uint32_t i : dirty) {
            float* s = mSlab.data() + std::size_t(i) * 4;
            if (s[3] > 0.0f) {
                const float c[3] = {s[0] / s[3], s[1] / s[3], s[2] / s[3]};
                overLocal(i % image.width, i / image.width, std::min(s[3], 1.0f), c);
            }
            s[0] = s[1] = s[2] = s[3] = 0.0f;
        }
        dirty.clear();
    }

  private:
    /// over() at (x, y) of the region.
    void overLocal(std::uint32_t x, std::uint32_t y, float a, const float* c) {
        float* p = image.pixel(x, y);
        if (p[3] >= mErt) return;
        const float w = (1.0f - p[3]) * a;
        p[0] += w * c[0];
        p[1] += w * c[1];
        p[2] += w * c[2];
        p[3] += w;
        if (p[3] >= mErt) --mOpen[tileOf(x, y)];
    }
    std::size_t tileOf(std::uint32_t x, std::uint32_t y) const {
        return std::size_t(y / mTile) * mTilesX + x / mTile;
    }
    PixelRect mRegion;
    std::uint32_t mTile, mTilesX;
    float mErt;
    std::vector<std::uint32_t> mOpen;
    std::vector<float> mSlab;
};

/// A visible voxel made ready to draw (on every core): the pixels it may touch and the
/// constants of its per-pixel loop.
struct DrawRecord {
    enum class Kind : std::uint8_t { None, Point, Splat };
    Kind kind = Kind::None;     ///< None: nothing to draw (no ellipse, or off the image)
    bool nearest = false;       ///< a point without a pixel centre under its filter
    std::uint16_t rect[4] = {}; ///< x0, y0, x1, y1, clipped to the image
    std::uint32_t slab = 0;     ///< slab cuts before it in the chunk: bands flush on a change
    /// Point: pixel (rect[0], rect[1]) minus the filter centre (pixels, y down) and the
    /// coverage per unit weight (the whole coverage, to pixel nearX, nearY, when `nearest`).
    /// Splat: that pixel's image point minus the projected centre (pixels, y up), the scale
    /// of d^2 (splatDistance2), the projected centre's tangents, optical depth per footprint.
    float dx = 0.0f, dy = 0.0f, scale = 0.0f, tanX = 0.0f, tanY = 0.0f, opticalDepth = 0.0f;
    std::int32_t nearX = -1, nearY = -1;
    const Visible* voxel = nullptr;
};

/// A point's footprint argument (distance / filter radius)^2 at the pixel i columns and j rows
/// from (rect[0], rect[1]). One expression for the weights' sum and for the deposits.
inline float pointDistance2(const DrawRecord& r, int i, int j, float invFilter2) {
    const float x = r.dx + float(i), y = r.dy + float(j);
    return (x * x + y * y) * invFilter2;
}

/// The squared distance, in radii, between a splat's centre and the eye ray of the image point
/// (da, db) pixels from its projected centre, sx, sy from the view axis. With a = sx / f, the
/// ray q = (a, b, 1) and the centre c = c.z (a0, b0, 1) in view coordinates,
/// |q x c|^2 = c.z^2 ((a - a0)^2 + (b - b0)^2 + ((a - a0) b0 - (b - b0) a0)^2): no cancellation
/// however far the sphere, so float suffices. `perspective2` is 1 / f^2 (0 orthographic).
inline float splatDistance2(const DrawRecord& r, float da, float db, float rowDenominator, float sx,
                            float perspective2) {
    const float cross = da * r.tanY - db * r.tanX;
    return r.scale * (da * da + db * db + cross * cross) /
           (rowDenominator + perspective2 * sx * sx);
}

/// Pixel rectangle `r` clipped to the columns of `region` and rows [y0, y1] (of the region)
/// into `clip`; false when nothing is left.
template <class T>
bool clipRect(const T r[4], const PixelRect& region, std::uint32_t y0, std::uint32_t y1,
              std::uint32_t clip[4]) {
    clip[0] = std::max<std::uint32_t>(r[0], region.x);
    clip[1] = std::max<std::uint32_t>(r[1], y0);
    clip[2] = std::min<std::uint32_t>(r[2], region.x + region.width - 1);
    clip[3] = std::min<std::uint32_t>(r[3], y1);
    return clip[0] <= clip[2] && clip[1] <= clip[3];
}

/// Pixel rectangle `r` clipped to `region` into `clip`; false when nothing is left.
template <class T> bool clipToRegion(const T r[4], const PixelRect& region, std::uint32_t clip[4]) {
    return clipRect(r, region, region.y, region.y + region.height - 1, clip);
}

/// True when every pixel of the region's rows [y0, y1] that the brick can touch is opaque.
bool occludedIn(const Canvas& canvas, const BrickReach& reach, std::uint32_t y0, std::uint32_t y1) {
    if (reach.kind != BrickReach::Kind::Rect) return reach.kind == BrickReach::Kind::Nowhere;
    std::uint32_t c[4];
    return !clipRect(reach.rect, canvas.region(), y0, y1, c) ||
           canvas.occluded(c[0], c[1], c[2], c[3]);
}

/// The pixel rectangle of the bounding box of a sphere's screen ellipse (projectSphere's),
/// without hypot and atan2 (a third of a record's cost). Precondition: the sphere lies in
/// front of the eye plane (classifyDraw's Splat). False when the box misses the image or the
/// ellipse is not finite. The box may differ by an ulp, which moves at most a pixel centre on
/// the rim, where the footprint is 0.
bool splatRect(const SplatView& view, const glm::dvec3& centre, double radius, std::uint32_t w,
               std::uint32_t h, std::uint32_t rect[4]) {
    const glm::dvec3 rel = centre - view.eye;
    const glm::dvec3 c(glm::dot(rel, view.right), glm::dot(rel, view.up),
                       glm::dot(rel, view.forward));
    glm::dvec2 mid, half;
    if (view.orthographic) {
        mid = view.orthoScale * glm::dvec2(c.x, c.y);
        half = glm::dvec2(view.orthoScale * radius);
    } else {
        // projectPerspective's ellipse: with q = c / |c|, s = r / |c|, g = q.z^2 - s^2 and
        // e1 = q.xy / |q.xy|, centre f q.z / g q.xy and semi-axes f s cos(alpha) / g e1 and
        // f s / sqrt(g) e1 turned by 90 deg; the box's half size follows per axis.
        const double dist2 = glm::dot(c, c), s2 = radius * radius / dist2;
        const double g = (c.z * c.z - radius * radius) / dist2,
                     rho2 = (c.x * c.x + c.y * c.y) / dist2;
        if (!(g > 0.0)) return false;
        const double e1x2 = rho2 > 0.0 ? c.x * c.x / dist2 / rho2 : 1.0, e1y2 = 1.0 - e1x2;
        const double f = view.focalLength, k = f * std::sqrt(s2) / g, cz = c.z / std::sqrt(dist2);
        mid = (f * cz / g / std::sqrt(dist2)) * glm::dvec2(c.x, c.y);
        half = k * glm::dvec2(std::sqrt((1.0 - s2) * e1x2 + g * e1y2),
                              std::sqrt((1.0 - s2) * e1y2 + g * e1x2));
    }
    if (!(std::isfinite(mid.x) && std::isfinite(mid.y) && std::isfinite(half.x) &&
          std::isfinite(half.y)))
        return false;
    return detail::pixelRect(mid - half, mid + half, w, h, rect);
}

/// Rows [y0, y1] of the region (whole tile rows from its top) and what one worker draws there:
/// the records whose rectangles meet them within the region, in the serial order, so each pixel
/// sees the serial operations.
struct Band {
    std::uint32_t y0 = 0, y1 = 0;
    std::vector<std::uint32_t> records;    ///< indices of the chunk's records
    std::vector<std::uint32_t> brickFirst; ///< brick j: entries [brickFirst[j], brickFirst[j + 1])
    std::vector<std::uint8_t> drawn;       ///< per entry: drawn here (not culled)
    std::vector<std::uint8_t> occluded;    ///< per brick: skipped, its reach in the band opaque
    std::vector<std::uint32_t> dirty;      ///< the band's slab pixels holding coverage
};

/// Draws the prepared bricks of each chunk in plan order, in horizontal bands on every core.
/// Per voxel, in parallel: its record. Serially: where the slabs are cut (voxel order and depth
/// alone, as if nothing were culled) and which bands each voxel meets. Per band, in parallel:
/// brick and voxel culling against the band's tiles and drawing its rows. A voxel (brick)
/// counts as culled when every band it meets culled it: exactly when a serial draw would.
/// Records and slab cuts use whole-image coordinates; bands cover the canvas's region only.
class ChunkDrawer {
  public:
    /// Draws into `canvas` (its region of the `width` x `height` image).
    ChunkDrawer(const Frame& f, const SplatFootprint& fp, const HybridSplatterConfig& config,
                std::uint32_t width, std::uint32_t height, Canvas& canvas, HybridSplatStats& n);

    /// Marks chunk[j] culled when the tiles under bricks[j] are all opaque already.
    void cullBricks(const PlannedBrick* bricks, std::vector<PreparedBrick>& chunk);
    /// Draws the prepared chunk of the last cullBricks().
    void draw(const std::vector<PreparedBrick>& chunk);

  private:
    void makeRecords(const std::vector<PreparedBrick>& chunk);
    DrawRecord record(const Visible& v) const;
    void pointRecord(const VoxelDraw& d, DrawRecord& r) const;
    void splatRecord(const glm::dvec3& centre, double lnT, DrawRecord& r) const;
    void cutSlabs(const std::vector<PreparedBrick>& chunk);
    void drawBand(Band& band, const std::vector<PreparedBrick>& chunk);
    // Each draws record r over the pixels `clip` (its rectangle within the band).
    void drawPoint(Band& band, const DrawRecord& r, const std::uint32_t clip[4]);
    void drawSplat(const DrawRecord& r, const std::uint32_t clip[4]);
    void drawSplatByIndex(const DrawRecord& r, const std::uint32_t clip[4]);
    void count(const std::vector<PreparedBrick>& chunk);

    const Frame& mF;
    const SplatFootprint& mFp;
    Canvas& mCanvas;
    HybridSplatStats& mN;
    const bool mExact;
    const std::uint32_t mW, mH; ///< the whole image's
    const PixelRect mRegion;    ///< the pixels drawn
    const float mInvFilter2;    ///< 1 / pointFilter^2
    const float mPerspective2;  ///< 1 / focalLength^2, 0 orthographic
    std::uint32_t mBandRows = 1;
    std::vector<Band> mBands;
    std::vector<BrickReach> mReach;
    std::vector<DrawRecord> mRecords;
    std::vector<std::uint32_t> mBrickFirst; ///< brick j's records: [mBrickFirst[j], [j + 1])
    std::vector<std::uint32_t> mBrickSlab;  ///< slab cuts before brick j
    std::vector<std::uint32_t> mBrickSlabs; ///< slabs composited in brick j
    std::vector<std::uint8_t> mDrawn;       ///< per record: drawn in some band
};

ChunkDrawer::ChunkDrawer(const Frame& f, const SplatFootprint& fp,
                         const HybridSplatterConfig& config, std::uint32_t width,
                         std::uint32_t height, Canvas& canvas, HybridSplatStats& n)
    : mF(f), mFp(fp), mCanvas(canvas), mN(n), mExact(config.exactDistanceFootprint), mW(width),
      mH(height), mRegion(canvas.region()),
      mInvFilter2(float(1.0 / (f.pointFilter * f.pointFilter))),
      mPerspective2(f.view.orthographic ? 0.0f
                                        : float(1.0 / (f.view.focalLength * f.view.focalLength))) {
    // A few bands per worker: the bands of a view differ in work, TBB balances them.
    const std::uint32_t tile = canvas.tile(), tileRows = (mRegion.height + tile - 1) / tile;
    const std::uint32_t want =
        config.parallelDraw ? 4 * std::uint32_t(tbb::this_task_arena::max_concurrency()) : 1;
    const std::uint32_t bands = std::clamp(want, 1u, tileRows);
    mBandRows = tile * ((tileRows + bands - 1) / bands);
    for (std::uint32_t y = 0; y < mRegion.height; y += mBandRows) {
        mBands.emplace_back();
        mBands.back().y0 = mRegion.y + y;
        mBands.back().y1 = mRegion.y + std::min(y + mBandRows, mRegion.height) - 1;
    }
}

void ChunkDrawer::cullBricks(const PlannedBrick* bricks, std::vector<PreparedBrick>& chunk) {
    mReach.resize(chunk.size());
    for (std::size_t j = 0; j < chunk.size(); ++j) {
        mReach[j] = brickReach(mF, bricks[j], mW, mH);
        chunk[j].culled =
            mF.cull && occludedIn(mCanvas, mReach[j], mRegion.y, mRegion.y + mRegion.height - 1);
    }
}

void ChunkDrawer::draw(const std::vector<PreparedBrick>& chunk) {
    makeRecords(chunk);
    cutSlabs(chunk);
    tbb::parallel_for(std::size_t(0), mBands.size(),
                      [&](std::size_t b) { drawBand(mBands[b], chunk); });
    count(chunk);
}

void ChunkDrawer::makeRecords(const std::vector<PreparedBrick>& chunk) {
    mBrickFirst.assign(chunk.size() + 1, 0);
    for (std::size_t j = 0; j < chunk.size(); ++j)
        mBrickFirst[j + 1] =
            mBrickFirst[j] + std::uint32_t(chunk[j].culled ? 0 : chunk[j].voxels.size());
    mRecords.resize(mBrickFirst.back());
    tbb::parallel_for(tbb::blocked_range<std::uint32_t>(0, mBrickFirst.back(), 1024),
                      [&](const tbb::blocked_range<std::uint32_t>& range) {
                          std::size_t j =
                              std::size_t(std::upper_bound(mBrickFirst.begin(), mBrickFirst.end(),
                                                           range.begin()) -
                                          mBrickFirst.begin()) -
                              1;
                          for (std::uint32_t i = range.begin(); i != range.end(); ++i) {
                              while (i >= mBrickFirst[j + 1])
                                  ++j;
                              mRecords[i] = record(chunk[j].voxels[i - mBrickFirst[j]]);
                          }
                      });
}

DrawRecord ChunkDrawer::record(const Visible& v) const {
    DrawRecord r;
    r.voxel = &v;
    const VoxelDraw d = detail::classifyDraw(mF, v.centre, v.rgba[3]);
    if (d.kind == VoxelDraw::Kind::Point)
        pointRecord(d, r);
    else if (d.kind == VoxelDraw::Kind::Splat)
        splatRecord(v.centre, d.lnT, r);
    return r;
}

void ChunkDrawer::pointRecord(const VoxelDraw& d, DrawRecord& r) const {
    // A point covers its voxel's projected area (pixels^2) with the voxel's opacity over one
    // voxel of path; that coverage is spread by the footprint at each pixel centre,
    // normalised over the unclipped lattice, so no point is lost between pixel centres.
    const double R = mF.pointFilter;
    std::uint32_t rect[4];
    if (!detail::pixelRect(d.image - R, d.image + R, mW, mH, rect)) return;
    const double fx = d.image.x + 0.5 * mW - 0.5, fy = 0.5 * mH - 0.5 - d.image.y;
    r.dx = float(rect[0] - fx);
    r.dy = float(rect[1] - fy);
    const int i0 = int(std::ceil(fx - R)) - int(rect[0]),
              i1 = int(std::floor(fx + R)) - int(rect[0]);
    const int j0 = int(std::ceil(fy - R)) - int(rect[1]),
              j1 = int(std::floor(fy + R)) - int(rect[1]);
    float sum = 0.0f;
    for (int j = j0; j <= j1; ++j)
        for (int i = i0; i <= i1; ++i)
            sum += mFp.bySquaredDistance(pointDistance2(r, i, j, mInvFilter2));
    const double total =
        (1.0 - std::exp(-d.lnT * mF.voxelSteps)) * mF.voxelAreaMm2 * d.scale * d.scale;
    if (sum > 0.0f) {
        r.scale = float(total / sum);
    } else { // the whole coverage to the nearest pixel
        r.nearest = true;
        r.scale = float(total);
        const long nx = std::lround(fx), ny = std::lround(fy);
        if (nx >= 0 && ny >= 0 && nx < long(mW) && ny < long(mH)) {
            r.nearX = std::int32_t(nx);
            r.nearY = std::int32_t(ny);
        }
    }
    r.kind = DrawRecord::Kind::Point;
    std::copy(rect, rect + 4, r.rect);
}

void ChunkDrawer::splatRecord(const glm::dvec3& centre, double lnT, DrawRecord& r) const {
    std::uint32_t rect[4];
    if (!splatRect(mF.view, centre, mF.radiusMm, mW, mH, rect)) return;
    const glm::dvec3 rel = centre - mF.view.eye;
    const glm::dvec3 c(glm::dot(rel, mF.view.right), glm::dot(rel, mF.view.up),
                       glm::dot(rel, mF.view.forward));
    const glm::dvec2 p0 = SplatView::pixelCentre(rect[0], rect[1], mW, mH);
    if (mF.view.orthographic) {
        const double s = mF.view.orthoScale;
        r.dx = float(p0.x - s * c.x);
        r.dy = float(p0.y - s * c.y);
        r.scale = float(1.0 / (s * mF.radiusMm * s * mF.radiusMm));
    } else {
        const double fl = mF.view.focalLength, q = c.z / (fl * mF.radiusMm);
        r.tanX = float(c.x / c.z);
        r.tanY = float(c.y / c.z);
        r.dx = float(p0.x - fl * c.x / c.z);
        r.dy = float(p0.y - fl * c.y / c.z);
        r.scale = float(q * q);
    }
    r.opticalDepth = float(lnT * mF.depthScale);
    r.kind = DrawRecord::Kind::Splat;
    std::copy(rect, rect + 4, r.rect);
}

void ChunkDrawer::cutSlabs(const std::vector<PreparedBrick>& chunk) {
    for (Band& band : mBands) {
        band.records.clear();
        band.brickFirst.clear();
    }
    mBrickSlab.assign(chunk.size(), 0);
    mBrickSlabs.assign(chunk.size(), 0);
    std::uint32_t cuts = 0;
    for (std::size_t j = 0; j < chunk.size(); ++j) {
        for (Band& band : mBands)
            band.brickFirst.push_back(std::uint32_t(band.records.size()));
        mBrickSlab[j] = cuts;
        const std::uint32_t before = cuts;
        bool open = false;
        double end = 0.0;
        for (std::uint32_t i = mBrickFirst[j]; i < mBrickFirst[j + 1]; ++i) {
            DrawRecord& r = mRecords[i];
            if (r.kind == DrawRecord::Kind::None) continue;
            const double depth = r.voxel->depth;
            if (open && (r.kind == DrawRecord::Kind::Splat || depth > end)) {
                ++cuts; // points in front go first, culled or not
                open = false;
            }
            if (!open && r.kind == DrawRecord::Kind::Point) {
                open = true;
                end = depth + mF.slabMm;
            }
            r.slab = cuts;
            std::uint32_t clip[4];
            if (!clipToRegion(r.rect, mRegion, clip)) continue; // drawn by other slices
            for (std::uint32_t b = (clip[1] - mRegion.y) / mBandRows;
                 b <= (clip[3] - mRegion.y) / mBandRows; ++b)
                mBands[b].records.push_back(i);
        }
        cuts += open; // the next brick may lie in front of this slab
        mBrickSlabs[j] = cuts - before;
    }
    for (Band& band : mBands)
        band.brickFirst.push_back(std::uint32_t(band.records.size()));
}

void ChunkDrawer::drawBand(Band& band, const std::vector<PreparedBrick>& chunk) {
    band.drawn.assign(band.records.size(), 0);
    band.occluded.assign(chunk.size(), 0);
    for (std::size_t j = 0; j < chunk.size(); ++j) {
        if (chunk[j].culled) continue;
        // Bricks drawn earlier in the chunk may have covered this one since.
        if (mF.cull && occludedIn(mCanvas, mReach[j], band.y0, band.y1)) {
            band.occluded[j] = 1;
            continue;
        }
        std::uint32_t slab = mBrickSlab[j];
        for (std::uint32_t e = band.brickFirst[j]; e < band.brickFirst[j + 1]; ++e) {
            const DrawRecord& r = mRecords[band.records[e]];
            if (r.slab != slab) { // cut since this band's last voxel: composite its part
                mCanvas.flushSlab(band.dirty);
                slab = r.slab;
            }
            std::uint32_t clip[4];
            clipRect(r.rect, mRegion, band.y0, band.y1, clip); // not empty: r meets the band
            if (mF.cull && mCanvas.occluded(clip[0], clip[1], clip[2], clip[3])) continue;
            band.drawn[e] = 1;
            if (r.kind == DrawRecord::Kind::Point)
                drawPoint(band, r, clip);
            else if (mExact)
                drawSplat(r, clip);
            else
                drawSplatByIndex(r, clip);
        }
        mCanvas.flushSlab(band.dirty);
    }
}

void ChunkDrawer::drawPoint(Band& band, const DrawRecord& r, const std::uint32_t clip[4]) {
    // The slab adds coverages: an area average, as a box filter of the pixel would.
    const float* c = r.voxel->rgba.data();
    if (r.nearest) {
        const auto x = std::uint32_t(r.nearX), y = std::uint32_t(r.nearY);
        if (r.nearX >= 0 && x >= mRegion.x && x - mRegion.x < mRegion.width && y >= band.y0 &&
            y <= band.y1)
            mCanvas.deposit(x, y, r.scale, c, band.dirty);
        return;
    }
    for (std::uint32_t y = clip[1]; y <= clip[3]; ++y)
        for (std::uint32_t x = clip[0]; x <= clip[2]; ++x) {
            const float w = mFp.bySquaredDistance(
                pointDistance2(r, int(x - r.rect[0]), int(y - r.rect[1]), mInvFilter2));
            if (w > 0.0f) mCanvas.deposit(x, y, r.scale * w, c, band.dirty);
        }
}

void ChunkDrawer::drawSplat(const DrawRecord& r, const std::uint32_t clip[4]) {
    // The exact ray-centre distance: the same footprint as correctedDistance(coneIndex, alpha)
    // without the 2D table's interpolation error.
    const float* c = r.voxel->rgba.data();
    const float halfW = 0.5f * float(mW), halfH = 0.5f * float(mH), g = mPerspective2;
    for (std::uint32_t y = clip[1]; y <= clip[3]; ++y) {
        const float db = r.dy - float(y - r.rect[1]), sy = halfH - float(y) - 0.5f;
        const float rowDenominator = 1.0f + g * sy * sy;
        for (std::uint32_t x = clip[0]; x <= clip[2]; ++x) {
            const float da = r.dx + float(x - r.rect[0]), sx = float(x) + 0.5f - halfW;
            const float u = splatDistance2(r, da, db, rowDenominator, sx, g);
            if (!(u < 1.0f)) continue;
            const float fp = mFp.bySquaredDistance(u);
            if (fp > 0.0f) mCanvas.over(x, y, 1.0f - std::exp(-r.opticalDepth * fp), c);
        }
    }
}

void ChunkDrawer::drawSplatByIndex(const DrawRecord& r, const std::uint32_t clip[4]) {
    // The paper's path: the exact index, then the 2D (index, half angle) table.
    const Visible& v = *r.voxel;
    const double k = detail::classifyDraw(mF, v.centre, v.rgba[3]).lnT * mF.depthScale;
    const double alpha = projectSphere(mF.view, v.centre, mF.radiusMm).ellipse.halfAngleRad;
    for (std::uint32_t y = clip[1]; y <= clip[3]; ++y)
        for (std::uint32_t x = clip[0]; x <= clip[2]; ++x) {
            const double i =
                coneIndex(mF.view, v.centre, mF.radiusMm, SplatView::pixelCentre(x, y, mW, mH));
            if (!(i < 1.0)) continue;
            const double fp = mFp.lookup(i, alpha);
            if (fp > 0.0) mCanvas.over(x, y, float(1.0 - std::exp(-k * fp)), v.rgba.data());
        }
}

void ChunkDrawer::count(const std::vector<PreparedBrick>& chunk) {
    mDrawn.assign(mRecords.size(), 0);
    for (const Band& band : mBands)
        for (std::size_t e = 0; e < band.records.size(); ++e)
            if (band.drawn[e]) mDrawn[band.records[e]] = 1;
    for (std::size_t j = 0; j < chunk.size(); ++j) {
        bool culled = chunk[j].culled;
        if (!culled && mF.cull)
            culled = std::all_of(mBands.begin(), mBands.end(),
                                 [&](const Band& band) { return band.occluded[j] != 0; });
        if (culled) {
            ++mN.bricksCulled;
            continue;
        }
        mN.leavesSkipped += chunk[j].leavesSkipped;
        mN.slabs += mBrickSlabs[j];
        for (std::uint32_t i = mBrickFirst[j]; i < mBrickFirst[j + 1]; ++i) {
            const DrawRecord& r = mRecords[i];
            std::uint32_t clip[4];
            if (r.kind == DrawRecord::Kind::None || !clipToRegion(r.rect, mRegion, clip)) continue;
            if (!mDrawn[i])
                ++mN.culled;
            else if (r.kind == DrawRecord::Kind::Point)
                ++mN.points;
            else
                ++mN.splats;
        }
    }
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

Image HybridSplatter::render(const Scene& scene, const View& view, const RenderOptions& options,
                             FrameStats& stats) {
    const auto frameStart = Clock::now();
    stats = FrameStats{};
    mLast = HybridSplatStats{};
    // Opacity per unit step: the footprint supplies each voxel's own path length.
    const SplatScene splat = detail::sceneOf(scene, view, options, stats);
    const brickstore::BrickStore& store = scene.store;
    brickstore::BrickCache& cache = scene.cache;
    const std::uint32_t level = splat.level;
    const LevelGeometry& g = splat.g;
    const ViewBasis& basis = view.basis;
    const TransferFunctionTable& table = splat.table();
    const OccupancyTrees* occupancy = splat.occupancy();
    const Frame f = detail::frameOf(mConfig, g, basis, options, table);
    // The whole view's plan, less the bricks that cannot reach the region: its own frustum
    // (planBricks for a region) would lose splats that reach into it from outside.
    BrickPlan plan = planBricks(store, g, table, basis, options.skip, occupancy);
    detail::cullOutsideRegion(f, options.region, options.width, options.height, plan);
    recordPlan(plan, level, stats);
    stats.batches = 1;

    Canvas canvas(options.drawn(), mConfig.tilePixels,
                  options.earlyTermination ? options.ertThreshold : 2.0);
    ChunkDrawer drawer(f, mFootprint, mConfig, options.width, options.height, canvas, mLast);
    const auto type = store.info().volume.type;
    const std::uint64_t brickBytes = store.brickBytes(), budget = cache.stats().budgetBytes;
    for (std::size_t first = 0, end; first < plan.drawn.size(); first = end) {
        end = detail::chunkEnd(plan, first, brickBytes, budget);
        std::vector<PreparedBrick> chunk(end - first);
        drawer.cullBricks(plan.drawn.data() + first, chunk);
        const auto prepareStart = Clock::now();
        detail::prepareChunk(f, plan, first, cache, type, occupancy, chunk);
        stats.uploadMs += msSince(prepareStart);
        drawer.draw(chunk);
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

} // namespace bc::render
