#pragma once
// The hybrid splatter's per-voxel records (render/HybridSplatter.cpp): what a visible voxel
// draws, as a point or a perspective splat, prepared on every core before the bands draw it,
// and the footprint arguments that the records and the drawing share.
#include "render/SplatFootprint.h"
#include "render/detail/SplatPrep.h"

#include <cstdint>

#include <glm/vec3.hpp>

namespace bc::render::detail {

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

/// Makes the records of a frame's voxels in the `width` x `height` image. Thread-safe: it
/// only reads.
class RecordMaker {
  public:
    /// `invFilter2` is 1 / f.pointFilter^2, as pointDistance2() takes it.
    RecordMaker(const Frame& f, const SplatFootprint& fp, std::uint32_t width, std::uint32_t height,
                float invFilter2)
        : mF(f), mFp(fp), mW(width), mH(height), mInvFilter2(invFilter2) {}

    /// The record of visible voxel `v`: a point or a splat as classifyDraw() decides, None
    /// when it draws nothing.
    DrawRecord operator()(const Visible& v) const;

  private:
    void pointRecord(const VoxelDraw& d, DrawRecord& r) const;
    void splatRecord(const glm::dvec3& centre, double lnT, DrawRecord& r) const;

    const Frame& mF;
    const SplatFootprint& mFp;
    const std::uint32_t mW, mH; ///< the whole image's
    const float mInvFilter2;
};

} // namespace bc::render::detail
