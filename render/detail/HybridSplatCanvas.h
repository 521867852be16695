#pragma once
// The hybrid splatter's compositing (render/HybridSplatter.cpp): the region's pixels, their
// opaque tiles for occlusion culling, and the slab that points add into before it is
// composited 'over'.
#include "render/Image.h"
#include "render/RenderTypes.h"

#include <algorithm>
#include <cstddef>
#include <cstdint>
#include <vector>

namespace bc::render::detail {

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

} // namespace bc::render::detail
