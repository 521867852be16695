#include "render/detail/HybridSplatDrawer.h"

#include "render/SplatGeometry.h"

#include <tbb/blocked_range.h>
#include <tbb/parallel_for.h>
#include <tbb/task_arena.h>

#include <algorithm>
#include <cmath>

namespace bc::render::detail {
namespace {

/// True when every pixel of the region's rows [y0, y1] that the brick can touch is opaque.
bool occludedIn(const Canvas& canvas, const BrickReach& reach, std::uint32_t y0, std::uint32_t y1) {
    if (reach.kind != BrickReach::Kind::Rect) return reach.kind == BrickReach::Kind::Nowhere;
    std::uint32_t c[4];
    return !clipRect(reach.rect, canvas.region(), y0, y1, c) ||
           canvas.occluded(c[0], c[1], c[2], c[3]);
}

} // namespace

ChunkDrawer::ChunkDrawer(const Frame& f, const SplatFootprint& fp,
                         const HybridSplatterConfig& config, std::uint32_t width,
                         std::uint32_t height, Canvas& canvas, HybridSplatStats& n)
    : mF(f), mFp(fp), mCanvas(canvas), mN(n), mExact(config.exactDistanceFootprint), mW(width),
      mH(height), mRegion(canvas.region()),
      mInvFilter2(float(1.0 / (f.pointFilter * f.pointFilter))),
      mPerspective2(f.view.orthographic ? 0.0f
                                        : float(1.0 / (f.view.focalLength * f.view.focalLength))),
      mRecordOf(f, fp, width, height, mInvFilter2) {
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
                              mRecords[i] = mRecordOf(chunk[j].voxels[i - mBrickFirst[j]]);
                          }
                      });
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
    const double k = classifyDraw(mF, v.centre, v.rgba[3]).lnT * mF.depthScale;
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

} // namespace bc::render::detail
