#pragma once
// The hybrid splatter's drawing (render/HybridSplatter.cpp): the prepared bricks of a chunk
// become records, the slabs are cut, and horizontal bands of the canvas draw them on every
// core, each pixel seeing the operations of a serial draw.
#include "render/SplatConfig.h"
#include "render/SplatFootprint.h"
#include "render/detail/HybridSplatCanvas.h"
#include "render/detail/HybridSplatRecords.h"
#include "render/detail/SplatPrep.h"

#include <cstdint>
#include <vector>

namespace bc::render::detail {

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
    const std::uint32_t mW, mH;  ///< the whole image's
    const PixelRect mRegion;     ///< the pixels drawn
    const float mInvFilter2;     ///< 1 / pointFilter^2
    const float mPerspective2;   ///< 1 / focalLength^2, 0 orthographic
    const RecordMaker mRecordOf; ///< the voxels' records, with the constants above
    std::uint32_t mBandRows = 1;
    std::vector<Band> mBands;
    std::vector<BrickReach> mReach;
    std::vector<DrawRecord> mRecords;
    std::vector<std::uint32_t> mBrickFirst; ///< brick j's records: [mBrickFirst[j], [j + 1])
    std::vector<std::uint32_t> mBrickSlab;  ///< slab cuts before brick j
    std::vector<std::uint32_t> mBrickSlabs; ///< slabs composited in brick j
    std::vector<std::uint8_t> mDrawn;       ///< per record: drawn in some band
};

} // namespace bc::render::detail
