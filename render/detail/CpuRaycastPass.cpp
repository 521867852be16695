#include "render/detail/CpuRaycastPass.h"

#include "render/detail/CpuMarchSimd.h"

#include <tbb/blocked_range.h>
#include <tbb/blocked_range2d.h>
#include <tbb/parallel_for.h>

#include <algorithm>
#include <atomic>
#include <limits>
#include <memory>
#include <optional>
#include <type_traits>

#include <glm/vec2.hpp>

namespace bc::render::detail {
namespace {

using Tile = tbb::blocked_range2d<std::uint32_t>;

template <class T> constexpr brickstore::VoxelType voxelTypeOf() {
    if constexpr (std::is_same_v<T, std::uint8_t>) return brickstore::VoxelType::U8;
    if constexpr (std::is_same_v<T, std::uint16_t>) return brickstore::VoxelType::U16;
    if constexpr (std::is_same_v<T, std::int16_t>) return brickstore::VoxelType::I16;
    return brickstore::VoxelType::F32;
}

/// The samples [w.k, w.kEnd) of the ray in sampled brick `b` (w.index): false when the ray
/// terminated early.
template <class T>
bool marchSampled(const Frame& f, RayWalk& w, const BrickRef& b, Accum& acc, Front* front,
                  RayCount& n) {
    int& k = w.k;
    const int kEnd = w.kEnd;
    const std::uint32_t* words = f.occ ? f.occ + std::size_t(w.index) * f.occWords : nullptr;
    const auto* map =
        f.fine && b.fine ? reinterpret_cast<const std::uint8_t*>(f.fine + b.fine) : nullptr;
    const glm::vec3 local = w.local(f);
    const T* voxels = static_cast<const T*>(b.voxels);
    // Pre-integration walks the whole range itself: a segment may begin at a sample
    // that a leap skipped. The others narrow it to the box of sampled leaves first.
    int kFirst = k, kLast = kEnd;
    bool more = true;
    if (f.pre)
        more = marchBrickPre(f, voxels, words, local, w.dv, w.d, w.t0, k, kEnd, acc, *front, n);
    else if (words && !clipToSampled(f, f.boxes[w.index], local, w.dv, w.invDv, w.invStep, w.t0,
                                     kFirst, kLast))
        more = true;
    else if (f.mode != BlendMode::Composite)
        more = marchBrickMode(f, voxels, words, map, local, w.dv, w.d, w.t0, w.first, kFirst, kLast,
                              acc, n);
    else
        more = f.simd ? marchBrickSimd(voxelTypeOf<T>(), f, b.voxels, words, local, w.dv, w.d, w.t0,
                                       kFirst, kLast, acc, n)
                      : marchBrick(f, voxels, words, map, local, w.dv, w.d, w.t0, kFirst, kLast,
                                   acc, n);
    return more;
}

/// The samples [k, kEnd) of the ray in constant brick `b` under pre-integration: false when
/// the ray terminated early.
inline bool marchConstantPre(const Frame& f, const BrickRef& b, int& k, int kEnd, Accum& acc,
                             Front& front, RayCount& n) {
    // One value throughout: the first segment runs from the last sample's value to it,
    // every later one is that value alone.
    const PreintegratedTable::End e = f.pre->end(double(b.constant));
    n.samples += std::uint64_t(kEnd - k);
    for (; k < kEnd; ++k) {
        const Rgba c = segmentColour(f, front, k, e);
        front = {e, k};
        if (c.a <= 0.0f) continue;
        composite(acc, c);
        if (acc.t <= f.ertT) return false;
    }
    return true;
}

/// One ray (the shader's main()) for the bricks of batch f.batch, one brick after the other
/// (RayWalk). `front`: the ray's link between samples under pre-integration (f.pre), else
/// null.
template <class T>
void marchRay(const Frame& f, float sx, float sy, float shift, RayState& s, RayResume& r,
              Front* front, RayCount& n) {
    RayWalk w;
    if (!w.begin(f, sx, sy, shift, s, r)) return;
    Accum& acc = s.acc;
    while (w.next(f, s, r)) {
        const BrickRef& b = f.bricks[w.index];
        if (f.running && !passes(f, b.bound, acc)) { // no sample of it can pass the ray's value
            ++n.leaps;
            continue;
        }
        if (b.slot == Slot::Sampled) {
            if (!marchSampled<T>(f, w, b, acc, front, n)) return;
        } else if (f.pre) {
            if (!marchConstantPre(f, b, w.k, w.kEnd, acc, *front, n)) return;
        } else if (f.mode != BlendMode::Composite) {
            if (!marchConstantMode(f, b.constant, w.k, w.kEnd, acc, n)) return;
        } else if (!marchConstant(f, b.constant, w.k, w.kEnd, acc, n)) {
            return;
        }
    }
}

/// The rays of a pass (marchPass), numbered as the region's: a ray's image-plane position,
/// sample shift and state, which batch 0 constructs (unless `constructs` is false: another
/// PassRays of the pass did already).
class PassRays {
  public:
    PassRays(const Frame& f, PixelLattice lattice, const PixelRect& region, RayStates& rays,
             bool constructs = true)
        : mF(f), mLattice(lattice), mX0(region.x), mY0(region.y), mW(region.width), mRays(rays),
          mConstructs(constructs && f.batch == 0) {}

    /// Ray (x, y)'s index in the region's rays.
    std::size_t index(std::uint32_t x, std::uint32_t y) const {
        return std::size_t(y - mY0) * mW + (x - mX0);
    }
    /// Ray (x, y), its state constructed when this is batch 0 (the first touch).
    PacketRay operator()(std::uint32_t x, std::uint32_t y) const {
        const PacketRay p = at(x, y);
        if (mConstructs) std::construct_at(p.state);
        return p;
    }
    /// Ray (x, y), its state as it is.
    PacketRay at(std::uint32_t x, std::uint32_t y) const {
        PacketRay p;
        const glm::vec2 plane = planeOf(mF, mLattice, x, y);
        p.sx = plane.x;
        p.sy = plane.y;
        p.shift = mF.jitter ? rayJitter(mLattice.pixel(x), mLattice.pixel(y)) - 0.5f : 0.0f;
        const std::size_t i = index(x, y);
        p.state = &mRays[i];
        p.resume = &mRays.resume(i);
        return p;
    }

  private:
    const Frame& mF;
    const PixelLattice mLattice;
    const std::uint32_t mX0, mY0, mW;
    RayStates& mRays;
    const bool mConstructs;
};

/// The rays of tile `r` in 4x4 blocks (partial at an edge): neighbouring pixels next to each
/// other, as marchPacketSimd() wants them. Constructs the states on batch 0 (`ray`).
void tileRays(const PassRays& ray, const Tile& r, std::vector<PacketRay>& list) {
    const auto ye = r.rows().end(), xe = r.cols().end();
    list.clear();
    list.reserve(r.rows().size() * r.cols().size());
    for (std::uint32_t by = r.rows().begin(); by < ye; by += 4)
        for (std::uint32_t bx = r.cols().begin(); bx < xe; bx += 4)
            for (std::uint32_t y = by; y < std::min(by + 4, ye); ++y)
                for (std::uint32_t x = bx; x < std::min(bx + 4, xe); ++x) {
                    list.push_back(ray(x, y));
                    // The states were written by the thread that
                    // made them: fetch them here, well before use.
                    __builtin_prefetch(list.back().state, 1);
                }
}

/// The rays of tile `r` one by one.
template <class T>
void marchTileRays(const Frame& f, const PassRays& ray, const Tile& r, std::vector<Front>& fronts,
                   RayCount& n) {
    for (std::uint32_t y = r.rows().begin(); y < r.rows().end(); ++y)
        for (std::uint32_t x = r.cols().begin(); x < r.cols().end(); ++x) {
            const PacketRay p = ray(x, y);
            const std::size_t i = ray.index(x, y);
            marchRay<T>(f, p.sx, p.sy, p.shift, *p.state, *p.resume,
                        fronts.empty() ? nullptr : &fronts[i], n);
        }
}

/// The segment ends of rays `rays[0, count)` whose bricks this pass draws (samplesEnds(),
/// takeEnd()), before their march, so that they seed its running skip; the same for every
/// march, so the scalar and SIMD ones stay equal.
template <class T>
void takeEnds(const Frame& f, const EndGrid& grid, const PacketRay* rays, std::size_t count,
              RayCount& n) {
    constexpr std::size_t kChunk = 64;
    glm::vec3 in[kChunk], out[kChunk];
    bool ok[kChunk];
    for (std::size_t base = 0; base < count; base += kChunk) {
        const std::size_t m = std::min(kChunk, count - base);
        segmentEndsSimd(f, rays + base, m, in, out, ok);
        for (std::size_t i = 0; i < m; ++i) {
            if (!ok[i]) continue;
            takeEnd<T>(f, grid, in[i], rays[base + i].state->acc, n);
            takeEnd<T>(f, grid, out[i], rays[base + i].state->acc, n);
        }
    }
}

/// The cut faces of rays `rays[0, count)` whose bricks this pass draws (Frame::capping,
/// takeCap()), before their march: a face lies in front of every sample of its ray. A ray
/// done with its march may still have one: its lattice may have no sample in the bricks this
/// frame draws (a part of a sort-last frame), or none after the face's batch.
template <class T>
void takeCaps(const Frame& f, const PacketRay* rays, std::size_t count, RayCount& n) {
    constexpr std::size_t kChunk = 64;
    CutEntry entries[kChunk];
    bool cut[kChunk];
    for (std::size_t base = 0; base < count; base += kChunk) {
        const std::size_t m = std::min(kChunk, count - base);
        cutEntriesSimd(f, rays + base, m, entries, cut);
        for (std::size_t i = 0; i < m; ++i)
            if (cut[i]) takeCap<T>(f, entries[i], *rays[base + i].state, n);
    }
}

/// marchPass() for voxels of type T, on every core (TBB over 8x8 tiles).
template <class T>
void marchPassOf(const Frame& f, PixelLattice lattice, const PixelRect& region,
                 const PixelRect& rect, RayStates& rays, std::vector<Front>& fronts,
                 RayCount& total) {
    std::atomic<std::uint64_t> samples{0}, leaps{0}, raises{0};
    const std::optional<EndGrid> ends =
        samplesEnds(f.mode) ? std::make_optional(EndGrid(f)) : std::nullopt;
    // A tile's ray list, where one is needed, is built once (constructing the states on batch
    // 0: `first`) and serves the ends, the faces and the packet march; the scalar march walks
    // the tile itself, after the list (`listed`) or constructing the states.
    const PassRays first(f, lattice, region, rays), listed(f, lattice, region, rays, false);
    const bool lists = f.packets || ends || f.capping;
    tbb::parallel_for(Tile(rect.y, rect.y + rect.height, 8, rect.x, rect.x + rect.width, 8),
                      [&](const Tile& r) {
                          RayCount n;
                          std::vector<PacketRay> list;
                          if (lists) tileRays(first, r, list);
                          if (ends) takeEnds<T>(f, *ends, list.data(), list.size(), n);
                          if (f.capping) takeCaps<T>(f, list.data(), list.size(), n);
                          if (f.packets)
                              marchPacketSimd(voxelTypeOf<T>(), f, list.data(), list.size(), n);
                          else
                              marchTileRays<T>(f, lists ? listed : first, r, fronts, n);
                          samples += n.samples;
                          leaps += n.leaps;
                          raises += n.raises;
                      });
    total.samples += samples;
    total.leaps += leaps;
    total.raises += raises;
}

} // namespace

void marchPass(brickstore::VoxelType type, const Frame& f, PixelLattice lattice,
               const PixelRect& region, const PixelRect& rect, RayStates& rays,
               std::vector<Front>& fronts, RayCount& total) {
    switch (type) {
    case brickstore::VoxelType::U8:
        return marchPassOf<std::uint8_t>(f, lattice, region, rect, rays, fronts, total);
    case brickstore::VoxelType::U16:
        return marchPassOf<std::uint16_t>(f, lattice, region, rect, rays, fronts, total);
    case brickstore::VoxelType::I16:
        return marchPassOf<std::int16_t>(f, lattice, region, rect, rays, fronts, total);
    case brickstore::VoxelType::F32:
        return marchPassOf<float>(f, lattice, region, rect, rays, fronts, total);
    }
}

Image imageOf(const RayStates& rays, std::uint32_t width, std::uint32_t height,
              const Footprint& marched, bool clamp, bool raw) {
    Image image(width, height); // transparent black
    if (!marched.visible) return image;
    const PixelRect& m = marched.rect;
    const float top = clamp ? 1.0f : std::numeric_limits<float>::max();
    tbb::parallel_for(tbb::blocked_range<std::uint32_t>(m.y, m.y + m.height, 16),
                      [&](const tbb::blocked_range<std::uint32_t>& r) {
                          for (std::uint32_t y = r.begin(); y < r.end(); ++y)
                              for (std::uint32_t x = m.x; x < m.x + m.width; ++x) {
                                  const Accum& c = rays[std::size_t(y) * width + x].acc;
                                  float* px = image.pixel(x, y);
                                  if (raw) {
                                      px[0] = c.v;
                                      px[1] = float(c.n);
                                      continue;
                                  }
                                  px[0] = std::clamp(c.r, 0.0f, top);
                                  px[1] = std::clamp(c.g, 0.0f, top);
                                  px[2] = std::clamp(c.b, 0.0f, top);
                                  px[3] = std::clamp(1.0f - c.t, 0.0f, 1.0f);
                              }
                      });
    return image;
}

} // namespace bc::render::detail
