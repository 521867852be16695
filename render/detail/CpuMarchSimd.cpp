// The CPU raycaster's march vectorised (render/detail/CpuMarchSimd.h), compiled once per
// instruction set by Highway's foreach_target and dispatched at run time to the best one the
// host has. Two layouts:
//
// - Across rays (marchPacketSimd, the default): each lane is one ray of a list of neighbouring
//   pixels, and a step takes one sample of every lane. A ray is a chain of dependent steps
//   (DDA, leaf test, leap, sample, composite); sixteen independent chains side by side keep
//   the core busy where one ray's chain leaves it waiting. Lanes walk the brick grid each on
//   its own and sample their own bricks (32-bit gather offsets from one base); a lane out of
//   samples takes its next brick, or the next ray of the list, once a quarter of the lanes
//   are. Visible samples wait in a queue for their colour (TF colour, gradient, shading),
//   taken a full vector at a time: a step only classifies, so the gradient's 24 voxel loads
//   are paid per visible sample, not per lane of every step with one visible sample. A queued
//   sample names its ray, not its lane, and adds to the ray's state: a lane that takes another
//   brick or ray leaves the queue as it is (only a ray that composites outside the queue, a
//   brick of one value or the scalar loop, has it emptied first).
//
// Gathers are the floor under a step's time (bench/GatherProbe.cpp: a 16-lane gather costs
// about what 16 scalar loads do on the dev VM), so each reads as few elements as it can: a
// 16-bit voxel pair is one 32-bit lane, a 32-bit voxel pair or a TF channel's two ends
// (tfPairTable()) one 64-bit lane, and a cell row with its x neighbours one 64-bit lane for
// 16-bit voxels.
// - Across one ray's consecutive samples in one brick (marchBrickSimd): the brick DDA, the
//   octree leaps and early termination stay the scalar code's, per ray; the per-sample work
//   runs a vector of samples at a time. Pre-integration's scalar march aside, this is what
//   RenderOptions::packets = false selects.
//
// Same image as the scalar march, bit for bit: every lane does the scalar code's float
// operations in the scalar code's order, and this file is compiled without contraction into
// fused multiply-adds (render/CMakeLists.txt), so a sample's colour does not depend on the
// lane it ran in, on the vector width, or on whether it ran here at all. Compositing keeps
// each ray's order: across samples it goes lane by lane; across rays a lane's transmittance
// is updated at its step (so early termination stops at the same sample) and the queued
// colours are added to its sums in the order its samples were taken.
#undef HWY_TARGET_INCLUDE
#define HWY_TARGET_INCLUDE "render/detail/CpuMarchSimd.cpp"
#include <hwy/foreach_target.h> // IWYU pragma: keep

#include <hwy/highway.h>

#include "render/detail/CpuMarchSimd.h"

#include <bit>
#include <cmath>
#include <cstring>
#include <type_traits>

HWY_BEFORE_NAMESPACE();
namespace bc::render::detail {
namespace HWY_NAMESPACE {
namespace hn = hwy::HWY_NAMESPACE;

using DF = hn::ScalableTag<float>;
using DI = hn::RebindToSigned<DF>;
using VF = hn::Vec<DF>;
using VI = hn::Vec<DI>;

/// Two neighbours along x per lane, v[o] and v[o + 1], as floats.
struct PairF {
    VF lo, hi;
};

/// 8- and 16-bit voxels: one 32-bit gather per pair. For 8 bits it reads v[o .. o + 3]; every
/// offset the march uses has o + 3 inside the stored brick (the last row of the last slice is
/// never read: see marchChunk).
HWY_INLINE PairF pairAt(const std::uint8_t* v, VI o) {
    const DF df;
    const DI di;
    const VI w = hn::GatherOffset(di, reinterpret_cast<const std::int32_t*>(v), o);
    const VI byte = hn::Set(di, 0xFF);
    return {hn::ConvertTo(df, hn::And(w, byte)),
            hn::ConvertTo(df, hn::And(hn::ShiftRight<8>(w), byte))};
}
/// The two 16-bit voxels packed in each 32-bit lane of w (little-endian: the first in the low
/// half), as floats, sign-extended for int16.
template <class T> HWY_INLINE PairF unpack16(VI w) {
    const DF df;
    const DI di;
    if constexpr (std::is_signed_v<T>)
        return {hn::ConvertTo(df, hn::ShiftRight<16>(hn::ShiftLeft<16>(w))),
                hn::ConvertTo(df, hn::ShiftRight<16>(w))};
    const VI half = hn::Set(di, 0xFFFF);
    return {hn::ConvertTo(df, hn::And(w, half)),
            hn::ConvertTo(df, hn::And(hn::ShiftRight<16>(w), half))};
}
template <class T> HWY_INLINE PairF pair16(const T* v, VI o) {
    return unpack16<T>(
        hn::GatherOffset(DI(), reinterpret_cast<const std::int32_t*>(v), hn::ShiftLeft<1>(o)));
}
HWY_INLINE PairF pairAt(const std::uint16_t* v, VI o) {
    return pair16(v, o);
}
HWY_INLINE PairF pairAt(const std::int16_t* v, VI o) {
    return pair16(v, o);
}
/// Two 32-bit neighbours per lane from 64-bit gathers (half a vector of lanes per gather): the
/// element loads of one 32-bit gather for both, where two 32-bit gathers would load twice.
/// `o`: voxel offsets of the first of each pair.
HWY_INLINE PairF pair32(const float* v, VI o) {
#if HWY_TARGET == HWY_SCALAR
    const DF df;
    return {hn::GatherIndex(df, v, o), hn::GatherIndex(df, v, hn::Add(o, hn::Set(DI(), 1)))};
#else
    const DF df;
    const DI di;
    const hn::Repartition<std::int64_t, DF> d64;
    const hn::Half<DI> dh;
    const VI bytes = hn::ShiftLeft<2>(o);
    const auto* base = reinterpret_cast<const std::int64_t*>(v);
    const VI q0 =
        hn::BitCast(di, hn::GatherOffset(d64, base, hn::PromoteTo(d64, hn::LowerHalf(dh, bytes))));
    const VI q1 =
        hn::BitCast(di, hn::GatherOffset(d64, base, hn::PromoteTo(d64, hn::UpperHalf(dh, bytes))));
    // Lane i of q holds v[o] in its low 32 bits and v[o + 1] above (little-endian).
    return {hn::BitCast(df, hn::ConcatEven(di, q1, q0)),
            hn::BitCast(df, hn::ConcatOdd(di, q1, q0))};
#endif
}
HWY_INLINE PairF pairAt(const float* v, VI o) {
    return pair32(v, o);
}

/// v[o - 1] and v[o + 2]: the x neighbours of a cell row (one gather for 8 bits).
HWY_INLINE PairF outerAt(const std::uint8_t* v, VI o) {
    const DF df;
    const DI di;
    const VI w =
        hn::GatherOffset(di, reinterpret_cast<const std::int32_t*>(v), hn::Sub(o, hn::Set(di, 1)));
    const VI byte = hn::Set(di, 0xFF);
    return {hn::ConvertTo(df, hn::And(w, byte)),
            hn::ConvertTo(df, hn::And(hn::ShiftRight<24>(w), byte))};
}
template <class T> HWY_INLINE PairF outerAt(const T* v, VI o) {
    const DI di;
    return {pairAt(v, hn::Sub(o, hn::Set(di, 1))).lo, pairAt(v, hn::Add(o, hn::Set(di, 1))).hi};
}
/// 32-bit voxels: two gathers of the two voxels themselves (a pair each would load twice).
HWY_INLINE PairF outerAt(const float* v, VI o) {
    const DF df;
    const DI di;
    return {hn::GatherIndex(df, v, hn::Sub(o, hn::Set(di, 1))),
            hn::GatherIndex(df, v, hn::Add(o, hn::Set(di, 2)))};
}

/// A cell row with its x neighbours per lane: pair = (v[o], v[o + 1]), outer = (v[o - 1],
/// v[o + 2]); what the value and the x central differences read.
struct QuadF {
    PairF pair, outer;
};

HWY_INLINE QuadF quadAt(const std::uint8_t* v, VI o) {
    const DF df;
    const DI di;
    const VI w =
        hn::GatherOffset(di, reinterpret_cast<const std::int32_t*>(v), hn::Sub(o, hn::Set(di, 1)));
    const VI byte = hn::Set(di, 0xFF);
    auto at = [&](VI x) { return hn::ConvertTo(df, hn::And(x, byte)); };
    return {{at(hn::ShiftRight<8>(w)), at(hn::ShiftRight<16>(w))},
            {at(w), at(hn::ShiftRight<24>(w))}};
}

/// 16-bit voxels: one 64-bit gather per lane (half a vector of them per gather) reads the four.
template <class T> HWY_INLINE QuadF quad16(const T* v, VI o) {
#if HWY_TARGET == HWY_SCALAR
    return {pairAt(v, o), outerAt(v, o)};
#else
    const DI di;
    const hn::Repartition<std::int64_t, DF> d64;
    const hn::Half<DI> dh;
    const VI bytes = hn::ShiftLeft<1>(hn::Sub(o, hn::Set(di, 1)));
    const auto* base = reinterpret_cast<const std::int64_t*>(v);
    const auto q0 = hn::GatherOffset(d64, base, hn::PromoteTo(d64, hn::LowerHalf(dh, bytes)));
    const auto q1 = hn::GatherOffset(d64, base, hn::PromoteTo(d64, hn::UpperHalf(dh, bytes)));
    // Lane i of q holds v[o-1] | v[o] << 16 in its low 32 bits and v[o+1] | v[o+2] << 16 above.
    const VI w01 = hn::ConcatEven(di, hn::BitCast(di, q1), hn::BitCast(di, q0));
    const VI w23 = hn::ConcatOdd(di, hn::BitCast(di, q1), hn::BitCast(di, q0));
    const PairF p01 = unpack16<T>(w01), p23 = unpack16<T>(w23);
    return {{p01.hi, p23.lo}, {p01.lo, p23.hi}};
#endif
}
HWY_INLINE QuadF quadAt(const std::uint16_t* v, VI o) {
    return quad16(v, o);
}
HWY_INLINE QuadF quadAt(const std::int16_t* v, VI o) {
    return quad16(v, o);
}
/// 32-bit voxels: the pairs at o - 1 and o + 1 (pair32()), four 64-bit gathers in all.
HWY_INLINE QuadF quadAt(const float* v, VI o) {
    const DI di;
    const PairF a = pair32(v, hn::Sub(o, hn::Set(di, 1))),
                b = pair32(v, hn::Add(o, hn::Set(di, 1)));
    return {{a.hi, b.lo}, {a.lo, b.hi}};
}

/// The lanes of v under m, packed, stored at p: a whole vector is written (the lanes past the
/// packed ones are garbage). Compress into a register, then a plain store: AVX-512's
/// compress-to-memory form is microcoded on AMD Zen 4 at about a hundred cycles a store, and
/// Highway 1.0 has no Zen 4 target that avoids it (CompressStore would emit it).
template <class D, class V, class M>
HWY_INLINE void appendTo(V v, M m, D d, hn::TFromD<D>* HWY_RESTRICT p) {
    hn::StoreU(hn::Compress(v, m), d, p);
}

HWY_INLINE VF lerpV(VF a, VF b, VF t) {
    const VF one = hn::Set(DF(), 1.0f);
    return hn::Add(hn::Mul(a, hn::Sub(one, t)), hn::Mul(b, t));
}

/// classify()'s channel ch (0 r, 1 g, 2 b, 3 a) per lane: table entries e / 4 and e / 4 + 1
/// (e: 4 * the entry) mixed by w.
HWY_INLINE VF tfChannel(const Frame& f, VI e, VF w, int ch) {
    const DF df;
    const DI di;
    if (f.tfPairs) {
        const PairF p = pair32(f.tfPairs, hn::Add(hn::Add(e, e), hn::Set(di, 2 * ch)));
        return lerpV(p.lo, p.hi, w);
    }
    return lerpV(hn::GatherIndex(df, f.tf, hn::Add(e, hn::Set(di, ch))),
                 hn::GatherIndex(df, f.tf, hn::Add(e, hn::Set(di, ch + 4))), w);
}

/// Trilinear in fetch()'s order (x, then y, then z) of eight corner values dXYZ.
HWY_INLINE VF tri(VF d000, VF d100, VF d010, VF d110, VF d001, VF d101, VF d011, VF d111, VF fx,
                  VF fy, VF fz) {
    return lerpV(lerpV(lerpV(d000, d100, fx), lerpV(d010, d110, fx), fy),
                 lerpV(lerpV(d001, d101, fx), lerpV(d011, d111, fx), fy), fz);
}

/// The four cell rows of each lane's sample: pairs at o, o + sy, o + sz, o + sy + sz.
struct CellRows {
    PairF r00, r10, r01, r11; ///< rJK: row y0 + J of slice z0 + K
    PairF x00, x10, x01, x11; ///< their x neighbours (outerAt), once `outer` is set
    bool outer = false;
};

/// The rows at o, o + sy, o + sz, o + sy + sz; with their x neighbours when `withOuter`
/// (quadAt(): for voxels of 16 bits or fewer at the cost of the rows alone).
template <class T>
HWY_INLINE void cellRows(const T* v, VI o, VI sy, VI sz, bool withOuter, CellRows& c) {
    const VI o10 = hn::Add(o, sy), o01 = hn::Add(o, sz), o11 = hn::Add(o10, sz);
    if (withOuter) {
        const QuadF q00 = quadAt(v, o), q10 = quadAt(v, o10), q01 = quadAt(v, o01),
                    q11 = quadAt(v, o11);
        c.r00 = q00.pair;
        c.r10 = q10.pair;
        c.r01 = q01.pair;
        c.r11 = q11.pair;
        c.x00 = q00.outer;
        c.x10 = q10.outer;
        c.x01 = q01.outer;
        c.x11 = q11.outer;
        c.outer = true;
        return;
    }
    c.r00 = pairAt(v, o);
    c.r10 = pairAt(v, o10);
    c.r01 = pairAt(v, o01);
    c.r11 = pairAt(v, o11);
}

/// cellGradient() of CpuSampling.h per lane: the central differences at the 8 corners,
/// interpolated with the value's weights.
template <class T>
HWY_INLINE void gradientOf(const T* v, VI o, VI sy, VI sz, const CellRows& c, VF fx, VF fy, VF fz,
                           VF& gx, VF& gy, VF& gz) {
    const bool have = c.outer;
    const PairF x00 = have ? c.x00 : outerAt(v, o), x10 = have ? c.x10 : outerAt(v, hn::Add(o, sy));
    const PairF x01 = have ? c.x01 : outerAt(v, hn::Add(o, sz)),
                x11 = have ? c.x11 : outerAt(v, hn::Add(hn::Add(o, sy), sz));
    gx = tri(hn::Sub(c.r00.hi, x00.lo), hn::Sub(x00.hi, c.r00.lo), hn::Sub(c.r10.hi, x10.lo),
             hn::Sub(x10.hi, c.r10.lo), hn::Sub(c.r01.hi, x01.lo), hn::Sub(x01.hi, c.r01.lo),
             hn::Sub(c.r11.hi, x11.lo), hn::Sub(x11.hi, c.r11.lo), fx, fy, fz);
    const VI sy2 = hn::Add(sy, sy), sz2 = hn::Add(sz, sz);
    const PairF ym0 = pairAt(v, hn::Sub(o, sy)), yp0 = pairAt(v, hn::Add(o, sy2));
    const PairF ym1 = pairAt(v, hn::Sub(hn::Add(o, sz), sy)),
                yp1 = pairAt(v, hn::Add(hn::Add(o, sz), sy2));
    gy = tri(hn::Sub(c.r10.lo, ym0.lo), hn::Sub(c.r10.hi, ym0.hi), hn::Sub(yp0.lo, c.r00.lo),
             hn::Sub(yp0.hi, c.r00.hi), hn::Sub(c.r11.lo, ym1.lo), hn::Sub(c.r11.hi, ym1.hi),
             hn::Sub(yp1.lo, c.r01.lo), hn::Sub(yp1.hi, c.r01.hi), fx, fy, fz);
    const PairF zm0 = pairAt(v, hn::Sub(o, sz)), zp0 = pairAt(v, hn::Add(o, sz2));
    const PairF zm1 = pairAt(v, hn::Sub(hn::Add(o, sy), sz)),
                zp1 = pairAt(v, hn::Add(hn::Add(o, sy), sz2));
    gz = tri(hn::Sub(c.r01.lo, zm0.lo), hn::Sub(c.r01.hi, zm0.hi), hn::Sub(c.r11.lo, zm1.lo),
             hn::Sub(c.r11.hi, zm1.hi), hn::Sub(zp0.lo, c.r00.lo), hn::Sub(zp0.hi, c.r00.hi),
             hn::Sub(zp1.lo, c.r10.lo), hn::Sub(zp1.hi, c.r10.hi), fx, fy, fz);
}

HWY_INLINE VF pow24(VF x) {
    const VF x3 = hn::Mul(hn::Mul(x, x), x), x6 = hn::Mul(x3, x3), x12 = hn::Mul(x6, x6);
    return hn::Mul(x12, x12);
}

/// shade() of CpuRay.h per lane, for ray directions (dx, dy, dz) (r, g, b in place; lanes with a
/// zero gradient keep theirs).
HWY_INLINE void shadeV(const Frame& f, VF dx, VF dy, VF dz, VF gx, VF gy, VF gz, VF& r, VF& g,
                       VF& b) {
    const DF df;
    gx = hn::Mul(gx, hn::Set(df, f.gradScale.x));
    gy = hn::Mul(gy, hn::Set(df, f.gradScale.y));
    gz = hn::Mul(gz, hn::Set(df, f.gradScale.z));
    const VF len = hn::Sqrt(hn::Add(hn::Add(hn::Mul(gx, gx), hn::Mul(gy, gy)), hn::Mul(gz, gz)));
    const auto lit = hn::Gt(len, hn::Zero(df));
    const VF nx = hn::Div(gx, len), ny = hn::Div(gy, len), nz = hn::Div(gz, len);
    const VF diff = hn::Abs(hn::Add(hn::Add(hn::Mul(nx, dx), hn::Mul(ny, dy)), hn::Mul(nz, dz)));
    const VF spec = hn::Mul(hn::Set(df, float(ShadingModel::kSpecular)), pow24(diff));
    const VF k = hn::Add(hn::Set(df, float(ShadingModel::kAmbient)),
                         hn::Mul(hn::Set(df, float(ShadingModel::kDiffuse)), diff));
    const VF w = hn::Min(
        hn::Max(hn::Div(len, hn::Set(df, float(ShadingModel::kGradientFade))), hn::Zero(df)),
        hn::Set(df, 1.0f));
    auto apply = [&](VF x) {
        return hn::IfThenElse(lit, hn::Add(x, hn::Mul(hn::Sub(hn::Add(hn::Mul(x, k), spec), x), w)),
                              x);
    };
    r = apply(r);
    g = apply(g);
    b = apply(b);
}

/// A vector of samples of one brick at positions q (voxels, relative to the stored brick's
/// first voxel, as Sample<T> takes them): their opacity at once, their colour on demand.
///
/// Voxel reads, with the lane's position q clamped into the fused range [1, edge - 2) (lanes
/// outside it are for the scalar code, Sample<T>): the cell is x0..x0+1, y0..y0+1, z0..z0+1
/// with 1 <= x0, y0, z0 <= edge - 3, the gradient reads one voxel beyond on each axis (0 ..
/// edge - 1), so no read leaves the brick; the 4-byte gathers of 8-bit voxels read up to 2
/// bytes past the voxel they need, which stays inside since the last row of the last slice (z
/// = y = edge - 1) is never a row read here (z = edge - 1 is read only for rows y0 and y0 + 1).
template <class T> struct SamplesV {
    const Frame& f;
    const T* v;
    hn::Mask<DF> fused; ///< lanes in the fused range: the others' results are not theirs
    bool allFused;
    VI o, sy, sz, e;
    VF fx, fy, fz, w;
    CellRows c;
    VF a; ///< classify()'s alpha per lane

    /// `base`: per lane, where its brick's voxels start, in voxels from `voxels` (0 when
    /// every lane samples the brick at `voxels`).
    /// `quads`: read the cell rows' x neighbours too (what the gradient needs) where one
    /// gather reads them with the rows.
    SamplesV(const Frame& frame, const T* voxels, VF qx, VF qy, VF qz, VI base, bool quads)
        : f(frame), v(voxels) {
        const DF df;
        const DI di;
        const VF one = hn::Set(df, 1.0f), hi = hn::Set(df, float(f.edge - 2));
        fused = hn::And(hn::And(hn::And(hn::Ge(qx, one), hn::Lt(qx, hi)),
                                hn::And(hn::Ge(qy, one), hn::Lt(qy, hi))),
                        hn::And(hn::Ge(qz, one), hn::Lt(qz, hi)));
        allFused = hn::AllTrue(df, fused);
        // Addresses from positions clamped into the fused range, which leaves a fused lane's
        // own (Max first: it returns 1 for a NaN position).
        const VF top = hn::Set(df, std::nextafter(float(f.edge - 2), 0.0f));
        auto inside = [&](VF q) { return hn::Min(hn::Max(q, one), top); };
        const VF cx = allFused ? qx : inside(qx), cy = allFused ? qy : inside(qy),
                 cz = allFused ? qz : inside(qz);
        const VI x0 = hn::ConvertTo(di, cx), y0 = hn::ConvertTo(di, cy), z0 = hn::ConvertTo(di, cz);
        fx = hn::Sub(cx, hn::ConvertTo(df, x0));
        fy = hn::Sub(cy, hn::ConvertTo(df, y0));
        fz = hn::Sub(cz, hn::ConvertTo(df, z0));
        sy = hn::Set(di, f.edge);
        sz = hn::Set(di, f.edge * f.edge);
        o = hn::Add(hn::Add(hn::Add(hn::Mul(z0, sz), hn::Mul(y0, sy)), x0), base);
        cellRows(v, o, sy, sz, quads && sizeof(T) <= 2, c);
        const VF value =
            lerpV(lerpV(lerpV(c.r00.lo, c.r00.hi, fx), lerpV(c.r10.lo, c.r10.hi, fx), fy),
                  lerpV(lerpV(c.r01.lo, c.r01.hi, fx), lerpV(c.r11.lo, c.r11.hi, fx), fy), fz);
        // classify() per lane.
        const VF u = hn::Min(
            hn::Max(hn::Add(hn::Mul(value, hn::Set(df, f.tfScale)), hn::Set(df, f.tfOffset)),
                    hn::Zero(df)),
            hn::Set(df, float(f.entries - 1)));
        const VI entry = hn::Min(hn::ConvertTo(di, u), hn::Set(di, f.entries - 2));
        w = hn::Sub(u, hn::ConvertTo(df, entry));
        e = hn::ShiftLeft<2>(entry);
        a = channel(3);
    }
    VF channel(int ch) const { return tfChannel(f, e, w, ch); }
    /// classify()'s colour, shaded for ray directions (dx, dy, dz) where f.shading.
    void colour(VF dx, VF dy, VF dz, VF& r, VF& g, VF& b) const {
        r = channel(0);
        g = channel(1);
        b = channel(2);
        if (!f.shading) return;
        VF gx, gy, gz;
        gradientOf(v, o, sy, sz, c, fx, fy, fz, gx, gy, gz);
        shadeV(f, dx, dy, dz, gx, gy, gz, r, g, b);
    }
};

/// Samples [k, k + count) of one brick, count <= Lanes(DF()); false once the ray is opaque.
template <class T>
bool marchChunk(const Frame& f, const T* v, glm::vec3 rel, glm::vec3 dv, glm::vec3 dir, float t0,
                int k, int count, Accum& acc, RayCount& n) {
    const DF df;
    const DI di;
    constexpr std::size_t kMax = hn::MaxLanes(DF());
    const VI index = hn::Min(hn::Add(hn::Set(di, k), hn::Iota(di, 0)), hn::Set(di, k + count - 1));
    const VF t =
        hn::Add(hn::Set(df, t0), hn::Mul(hn::Add(hn::ConvertTo(df, index), hn::Set(df, 0.5f)),
                                         hn::Set(df, f.stepMm)));
    const SamplesV<T> samples(f, v, hn::Add(hn::Set(df, rel.x), hn::Mul(hn::Set(df, dv.x), t)),
                              hn::Add(hn::Set(df, rel.y), hn::Mul(hn::Set(df, dv.y), t)),
                              hn::Add(hn::Set(df, rel.z), hn::Mul(hn::Set(df, dv.z), t)),
                              hn::Zero(di), f.shading);
    const bool allFused = samples.allFused;
    const VF a = samples.a;
    if (allFused && hn::AllFalse(df, hn::Gt(a, hn::Zero(df)))) {
        n.samples += std::uint64_t(count);
        return true;
    }
    VF r, g, b;
    samples.colour(hn::Set(df, dir.x), hn::Set(df, dir.y), hn::Set(df, dir.z), r, g, b);
    HWY_ALIGN float rs[kMax], gs[kMax], bs[kMax], as[kMax], ts[kMax];
    hn::Store(r, df, rs);
    hn::Store(g, df, gs);
    hn::Store(b, df, bs);
    hn::Store(a, df, as);
    std::uint8_t fusedBits[(kMax + 7) / 8 + 8] = {};
    if (!allFused) {
        hn::StoreMaskBits(df, samples.fused, fusedBits);
        hn::Store(t, df, ts);
    }
    // Lane by lane, without a branch on visibility: a transparent lane (alpha 0; the TF has
    // no negative alpha) adds exactly +0 to each sum and multiplies t by exactly 1, which
    // leaves the sums bit for bit as skipping the lane would. The sum is a local: through the
    // reference every lane would store it.
    Accum sum = acc;
    for (int j = 0; j < count; ++j) {
        Rgba s{rs[j], gs[j], bs[j], as[j]};
        if (!allFused && ((fusedBits[j >> 3] >> (j & 7)) & 1) == 0) {
            s = colourOf(f, Sample<T>(v, f.edge, rel + dv * ts[j]), dir); // the scalar code
            if (s.a <= 0.0f) continue;
        }
        composite(sum, s); // the chain from lane to lane is its one multiply of t
        if (sum.t <= f.ertT) {
            acc = sum;
            n.samples += std::uint64_t(j + 1);
            return false;
        }
    }
    acc = sum;
    n.samples += std::uint64_t(count);
    return true;
}

/// One ray in one brick, with the reciprocals a leap multiplies by (divisions are most of a
/// leap's latency).
struct BrickRay {
    glm::vec3 local, dv, invDv; ///< invDv: 0 on an axis the ray does not move along
    glm::ivec3 step;
    float t0, invStep;

    BrickRay(const Frame& f, glm::vec3 localIn, glm::vec3 dvIn, float t0In)
        : local(localIn), dv(dvIn), t0(t0In), invStep(1.0f / f.stepMm) {
        for (int a = 0; a < 3; ++a) {
            step[a] = dv[a] > 0.0f ? 1 : dv[a] < 0.0f ? -1 : 0;
            invDv[a] = step[a] == 0 ? 0.0f : 1.0f / dv[a];
        }
    }
    /// The first sample index at or after parameter t (the scalar walk's rounding, to within
    /// an ulp of the node exit: a sample that close to a face is transparent if either leaf is,
    /// render/OCCUPANCY.md).
    int sampleAt(float t) const { return int(std::ceil((t - t0) * invStep - 0.5f)); }
    /// Where the ray leaves the axis-aligned cube [lo, lo + size] (exitParameter()).
    float exitOf(glm::vec3 lo, float size) const {
        float t = 3.0e38f;
        for (int a = 0; a < 3; ++a)
            if (step[a] != 0)
                t = std::min(t, (lo[a] + (step[a] > 0 ? size : 0.0f) - local[a]) * invDv[a]);
        return t;
    }
};

/// emptyLevel() for a leaf whose own bit is clear, walked up from the leaf: the level below
/// its deepest sampled ancestor, usually found at the first step. (A node is sampled when it
/// holds a non-empty leaf or its parent is drawn whole, so a node that is not sampled has no
/// sampled child, and this is the coarsest empty level.)
int coarsestEmpty(const Frame& f, const std::uint32_t* words, glm::ivec3 leaf) {
    for (int l = f.octDepth - 1; l >= 1; --l) {
        const glm::ivec3 node = leaf >> (f.octDepth - l);
        const int s = 1 << l;
        const int bit = ((1 << (3 * l)) - 8) / 7 + (node.z * s + node.y) * s + node.x;
        if (((words[bit >> 5] >> (bit & 31)) & 1u) != 0u) return l + 1;
    }
    return 1;
}

/// The first of samples [k, k + count) whose own leaf is sampled, or -1: the scalar walk's
/// per-sample leaf test for a vector of samples at once (positions, leaves and the bits of
/// their leaves by the scalar formulas), so a run of transparent leaves costs no chain of
/// dependent scalar steps.
int firstSampled(const Frame& f, const std::uint32_t* words, glm::vec3 local, glm::vec3 dv,
                 float t0, int k, int count) {
    const DF df;
    const DI di;
    const VI index = hn::Min(hn::Add(hn::Set(di, k), hn::Iota(di, 0)), hn::Set(di, k + count - 1));
    const VF t =
        hn::Add(hn::Set(df, t0), hn::Mul(hn::Add(hn::ConvertTo(df, index), hn::Set(df, 0.5f)),
                                         hn::Set(df, f.stepMm)));
    const VI top = hn::Set(di, f.leafAxis - 1);
    // p / leaf as the scalar walk divides; a power-of-two leaf (the default 8) multiplies by
    // its exact reciprocal instead, the same float and a fraction of a vector division's cost.
    const bool pow2 = f.leaf >= 1.0f && std::has_single_bit(unsigned(f.leaf)) &&
                      float(unsigned(f.leaf)) == f.leaf;
    const VF leaf = hn::Set(df, f.leaf), invLeaf = hn::Set(df, 1.0f / f.leaf);
    auto leafOf = [&](float l0, float d) {
        const VF p = hn::Add(hn::Set(df, l0), hn::Mul(hn::Set(df, d), t));
        const VF q = pow2 ? hn::Mul(p, invLeaf) : hn::Div(p, leaf);
        return hn::Min(hn::Max(hn::ConvertTo(di, hn::Floor(q)), hn::Zero(di)), top);
    };
    const VI lx = leafOf(local.x, dv.x), ly = leafOf(local.y, dv.y), lz = leafOf(local.z, dv.z);
    const int s = 1 << f.octDepth;
    const VI sv = hn::Set(di, s);
    const VI bit = hn::Add(hn::Set(di, ((1 << (3 * f.octDepth)) - 8) / 7),
                           hn::Add(hn::Mul(hn::Add(hn::Mul(lz, sv), ly), sv), lx));
    const VI word =
        hn::GatherIndex(di, reinterpret_cast<const std::int32_t*>(words), hn::ShiftRight<5>(bit));
    const VI one = hn::Set(di, 1);
    const auto sampled =
        hn::Ne(hn::And(hn::Shr(word, hn::And(bit, hn::Set(di, 31))), one), hn::Zero(di));
    return int(hn::FindFirstTrue(di, hn::And(sampled, hn::FirstN(di, std::size_t(count)))));
}

/// marchBrick() of CpuRay.h with the same octree, a vector of samples at a time: samples in
/// leaves whose bit is clear are skipped (each tested at its own position, as the scalar walk
/// does), a vector wholly in such leaves leaps on over the empty node its last sample lies in,
/// and a vector is taken from its first sample in a sampled leaf. Samples of the vector that
/// lie in empty leaves after that are taken too: they are transparent (render/OCCUPANCY.md),
/// so the image is the scalar one.
template <class T>
bool marchBrickT(const Frame& f, const T* v, const std::uint32_t* words, glm::vec3 local,
                 glm::vec3 dv, glm::vec3 dir, float t0, int& k, int kEnd, Accum& acc, RayCount& n) {
    const int lanes = int(hn::Lanes(DF()));
    const glm::vec3 rel = local + (float(f.apron) - 0.5f);
    const BrickRay ray(f, local, dv, t0);
    while (k < kEnd) {
        int count = std::min(lanes, kEnd - k);
        if (words) {
            const int first = firstSampled(f, words, local, dv, t0, k, count);
            if (first < 0) { // all empty: leap over the node of the last one
                const int last = k + count - 1;
                const float t = t0 + (float(last) + 0.5f) * f.stepMm;
                const glm::ivec3 leaf =
                    glm::clamp(glm::ivec3(glm::floor((local + dv * t) / f.leaf)), glm::ivec3(0),
                               glm::ivec3(f.leafAxis - 1));
                const int l = coarsestEmpty(f, words, leaf);
                const float size = f.leaf * float(1 << (f.octDepth - l));
                const glm::vec3 lo = glm::vec3(leaf >> (f.octDepth - l)) * size;
                ++n.leaps;
                k = std::max(last + 1, std::min(ray.sampleAt(ray.exitOf(lo, size)), kEnd));
                continue;
            }
            k += first;
            count = std::min(lanes, kEnd - k);
        }
        if (!marchChunk(f, v, rel, dv, dir, t0, k, count, acc, n)) return false;
        k += count;
    }
    return true;
}

bool MarchBrick(brickstore::VoxelType type, const Frame& f, const void* voxels,
                const std::uint32_t* words, glm::vec3 local, glm::vec3 dv, glm::vec3 dir, float t0,
                int& k, int kEnd, Accum& acc, RayCount& n) {
    switch (type) {
    case brickstore::VoxelType::U8:
        return marchBrickT(f, static_cast<const std::uint8_t*>(voxels), words, local, dv, dir, t0,
                           k, kEnd, acc, n);
    case brickstore::VoxelType::U16:
        return marchBrickT(f, static_cast<const std::uint16_t*>(voxels), words, local, dv, dir, t0,
                           k, kEnd, acc, n);
    case brickstore::VoxelType::I16:
        return marchBrickT(f, static_cast<const std::int16_t*>(voxels), words, local, dv, dir, t0,
                           k, kEnd, acc, n);
    case brickstore::VoxelType::F32:
        return marchBrickT(f, static_cast<const float*>(voxels), words, local, dv, dir, t0, k, kEnd,
                           acc, n);
    }
    return true;
}

/// Leaves (lx, ly, lz) of the rays' positions p = local + dv t per lane, clamped into the
/// brick: the scalar walk's floor(p / leaf) (a power-of-two leaf, the default 8, multiplies by
/// its exact reciprocal instead: the same float).
HWY_INLINE VI leafOf(const Frame& f, VF local, VF dv, VF t) {
    const DF df;
    const DI di;
    const bool pow2 = f.leaf >= 1.0f && std::has_single_bit(unsigned(f.leaf)) &&
                      float(unsigned(f.leaf)) == f.leaf;
    const VF p = hn::Add(local, hn::Mul(dv, t));
    const VF q = pow2 ? hn::Mul(p, hn::Set(df, 1.0f / f.leaf)) : hn::Div(p, hn::Set(df, f.leaf));
    return hn::Min(hn::Max(hn::ConvertTo(di, hn::Floor(q)), hn::Zero(di)),
                   hn::Set(di, f.leafAxis - 1));
}

/// Per lane: is the octree node of level l (1: the root's children ... f.octDepth: the leaves)
/// that holds leaf (lx, ly, lz) sampled? `wordBase`: where the lane's brick's words start.
HWY_INLINE hn::Mask<DI> nodeSampled(const Frame& f, const std::uint32_t* words, VI wordBase, VI lx,
                                    VI ly, VI lz, int l) {
    const DI di;
    const int shift = f.octDepth - l;
    const VI s = hn::Set(di, 1 << l);
    const VI nx = hn::ShiftRightSame(lx, shift), ny = hn::ShiftRightSame(ly, shift),
             nz = hn::ShiftRightSame(lz, shift);
    const VI bit = hn::Add(hn::Set(di, ((1 << (3 * l)) - 8) / 7),
                           hn::Add(hn::Mul(hn::Add(hn::Mul(nz, s), ny), s), nx));
    const VI word = hn::GatherIndex(di, reinterpret_cast<const std::int32_t*>(words),
                                    hn::Add(hn::ShiftRight<5>(bit), wordBase));
    return hn::Ne(hn::And(hn::Shr(word, hn::And(bit, hn::Set(di, 31))), hn::Set(di, 1)),
                  hn::Zero(di));
}

/// Cells of the distance maps (cellOf() of CpuRay.h) of the rays' positions per lane: f.cell is
/// a power of two, so multiplying by its reciprocal is the scalar division's float.
HWY_INLINE VI mapCellOf(const Frame& f, VF local, VF dv, VF t) {
    const DF df;
    const DI di;
    const VF p = hn::Add(hn::Add(local, hn::Mul(dv, t)), hn::Set(df, f.cell - 0.5f));
    return hn::Min(
        hn::Max(hn::ConvertTo(di, hn::Floor(hn::Mul(p, hn::Set(df, 1.0f / f.cell)))), hn::Zero(di)),
        hn::Set(di, f.cellAxis - 1));
}

/// RayWalk::begin() for rays [0, count) of `rays` at once, all Fresh: ok[i] says whether ray
/// i has anything to draw, walks[i] is its walk. The scalar code's float operations in its
/// order (glm::normalize is v * (1 / sqrt(dot(v, v))); std::min and std::max by their own
/// comparisons), so each walk is bit for bit the one begin() sets up. Marks the rays Done,
/// as begin() does (a ray that stops to wait says so in RayWalk::next()).
void beginFresh(const Frame& f, const PacketRay* rays, std::size_t count, RayWalk* walks,
                bool* ok) {
    const DF df;
    const DI di;
    constexpr std::size_t kMax = hn::MaxLanes(DF());
    HWY_ALIGN float sx[kMax] = {}, sy[kMax] = {}, shift[kMax] = {};
    for (std::size_t i = 0; i < count; ++i) {
        sx[i] = rays[i].sx;
        sy[i] = rays[i].sy;
        shift[i] = rays[i].shift;
    }
    const VF SX = hn::Load(df, sx), SY = hn::Load(df, sy), zero = hn::Zero(df);
    auto minOf = [](VF a, VF b) { return hn::IfThenElse(hn::Lt(b, a), b, a); }; // std::min
    auto maxOf = [](VF a, VF b) { return hn::IfThenElse(hn::Lt(a, b), b, a); }; // std::max
    auto along = [&](float base, float right, float up) { // base + sx right + sy up
        return hn::Add(hn::Add(hn::Set(df, base), hn::Mul(SX, hn::Set(df, right))),
                       hn::Mul(SY, hn::Set(df, up)));
    };
    VF o[3], d[3];
    for (int a = 0; a < 3; ++a) {
        o[a] = f.ortho ? along(f.eye[a], f.right[a], f.up[a]) : hn::Set(df, f.eye[a]);
        d[a] = f.ortho ? hn::Set(df, f.forward[a]) : along(f.forward[a], f.right[a], f.up[a]);
    }
    if (!f.ortho) {
        const VF inv = hn::Div(hn::Set(df, 1.0f),
                               hn::Sqrt(hn::Add(hn::Add(hn::Mul(d[0], d[0]), hn::Mul(d[1], d[1])),
                                                hn::Mul(d[2], d[2]))));
        for (VF& x : d)
            x = hn::Mul(x, inv);
    }
    VF ov[3], dv[3], inv[3];
    VF t0 = zero, t1 = hn::Set(df, 3.0e38f);
    auto miss = hn::Not(hn::FirstN(df, count));
    for (int a = 0; a < 3; ++a) {
        ov[a] = hn::Mul(o[a], hn::Set(df, f.invSpacing[a]));
        dv[a] = hn::Mul(d[a], hn::Set(df, f.invSpacing[a]));
        inv[a] = hn::Div(hn::Set(df, 1.0f), dv[a]);
        const auto still = hn::Eq(dv[a], zero);
        miss = hn::Or(miss, hn::And(still, hn::Or(hn::Lt(ov[a], zero),
                                                  hn::Gt(ov[a], hn::Set(df, f.dims[a])))));
        const VF ta = hn::Mul(hn::Neg(ov[a]), inv[a]),
                 tb = hn::Mul(hn::Sub(hn::Set(df, f.dims[a]), ov[a]), inv[a]);
        t0 = hn::IfThenElse(still, t0, maxOf(t0, minOf(ta, tb)));
        t1 = hn::IfThenElse(still, t1, minOf(t1, maxOf(ta, tb)));
    }
    const float invStep = 1.0f / f.stepMm;
    t0 = hn::Add(t0, hn::Mul(hn::Load(df, shift), hn::Set(df, f.stepMm)));
    const VF totalF =
        hn::Ceil(hn::Sub(hn::Mul(hn::Sub(t1, t0), hn::Set(df, invStep)), hn::Set(df, 0.5f)));
    // Where the count does not fit an int the ray is refused (begin() would misbehave).
    miss = hn::Or(miss, hn::Not(hn::Lt(totalF, hn::Set(df, 2.0e9f))));
    miss = hn::Or(miss, hn::Not(hn::Gt(totalF, zero)));
    const float brick = float(f.brick);
    HWY_ALIGN float out[16][kMax];
    HWY_ALIGN std::int32_t cells[3][kMax];
    for (int a = 0; a < 3; ++a) {
        const VF pin = hn::Add(ov[a], hn::Mul(dv[a], t0));
        const VI cell = hn::Min(
            hn::Max(hn::ConvertTo(di, hn::Floor(hn::Div(pin, hn::Set(df, brick)))), hn::Zero(di)),
            hn::Set(di, f.grid[a] - 1));
        const auto still = hn::Eq(dv[a], zero), up = hn::Gt(dv[a], zero);
        const VF plane = hn::ConvertTo(
            df, hn::Mul(hn::Add(cell, hn::IfThenElseZero(hn::RebindMask(di, up), hn::Set(di, 1))),
                        hn::Set(di, f.brick)));
        const VF far = hn::Set(df, 3.0e38f);
        hn::Store(cell, di, cells[a]);
        hn::Store(d[a], df, out[a]);
        hn::Store(ov[a], df, out[3 + a]);
        hn::Store(dv[a], df, out[6 + a]);
        hn::Store(inv[a], df, out[9 + a]);
        hn::Store(hn::IfThenElse(still, far, hn::Mul(hn::Set(df, brick), hn::Abs(inv[a]))), df,
                  out[12 + a]);
        // tMax, kept where the cell is known: out[15] holds one axis at a time.
        hn::Store(hn::IfThenElse(still, far, hn::Mul(hn::Sub(plane, ov[a]), inv[a])), df, out[15]);
        for (std::size_t i = 0; i < count; ++i)
            walks[i].tMax[a] = out[15][i];
    }
    HWY_ALIGN float t0s[kMax];
    HWY_ALIGN std::int32_t totals[kMax];
    hn::Store(t0, df, t0s);
    hn::Store(hn::ConvertTo(di, hn::IfThenElseZero(hn::Not(miss), totalF)), di, totals);
    std::uint8_t missBits[(kMax + 7) / 8 + 8] = {};
    hn::StoreMaskBits(df, miss, missBits);
    for (std::size_t i = 0; i < count; ++i) {
        RayWalk& w = walks[i];
        ok[i] = ((missBits[i >> 3] >> (i & 7)) & 1) == 0;
        if (rays[i].state) rays[i].state->phase = RayPhase::Done;
        if (!ok[i]) continue;
        for (int a = 0; a < 3; ++a) {
            w.d[a] = out[a][i];
            w.ov[a] = out[3 + a][i];
            w.dv[a] = out[6 + a][i];
            w.invDv[a] = out[9 + a][i];
            w.tDelta[a] = out[12 + a][i];
            w.cell[a] = cells[a][i];
            w.stepDir[a] = w.dv[a] > 0.0f ? 1 : w.dv[a] < 0.0f ? -1 : 0;
        }
        w.t0 = t0s[i];
        w.invStep = invStep;
        w.total = totals[i];
        w.k = w.kEnd = w.index = 0;
        w.entered = false;
    }
}

/// The rays in a packet's lanes, one per lane (structure of arrays): where each is in its
/// brick, which ray it is, and its transmittance (its colour sums are its RayState's). A lane
/// without samples to take has k = end.
struct Lanes {
    static constexpr std::size_t kMax = hn::MaxLanes(DF());
    HWY_ALIGN std::int32_t k[kMax], end[kMax];
    HWY_ALIGN std::int32_t base[kMax];  ///< the brick's first voxel, in voxels from the packet's
    HWY_ALIGN std::int32_t words[kMax]; ///< the brick's first octree word in f.occ
    HWY_ALIGN std::int32_t fine[kMax];  ///< the brick's distance map in f.fine (0: none)
    HWY_ALIGN float t0[kMax], lx[kMax], ly[kMax], lz[kMax], dx[kMax], dy[kMax], dz[kMax];
    HWY_ALIGN float ix[kMax], iy[kMax], iz[kMax]; ///< 1 / (dx, dy, dz)
    HWY_ALIGN float wx[kMax], wy[kMax], wz[kMax]; ///< the rays' world directions (shading)
    HWY_ALIGN std::int32_t ray[kMax]; ///< the lane's ray: its index in the packet's list
    HWY_ALIGN float t[kMax];
};

/// The march of marchPacketSimd() for voxels of type T: its lanes, each a ray of the queue
/// `rays` in turn, and the step that takes one sample of every lane.
template <class T> class Packet {
  public:
    static constexpr std::size_t kMax = Lanes::kMax;

    Packet(const Frame& f, const PacketRay* rays, std::size_t count, int lanes, RayCount& n)
        : f(f), mRays(rays), mCount(count), mLanes(lanes), mN(n) {}

    void run() {
        for (int j = 0; j < int(kMax); ++j)
            idle(j);
        for (int j = 0; j < mLanes; ++j)
            refill(j);
        march();
    }

  private:
    using MI = hn::Mask<DI>;

    /// Lane j without a ray: no samples, nothing to composite.
    void idle(int j) {
        mRay[j] = nullptr;
        L.k[j] = L.end[j] = 0;
        L.base[j] = L.words[j] = L.fine[j] = 0;
        L.t0[j] = L.lx[j] = L.ly[j] = L.lz[j] = L.dx[j] = L.dy[j] = L.dz[j] = 0.0f;
        L.ix[j] = L.iy[j] = L.iz[j] = L.wx[j] = L.wy[j] = L.wz[j] = 0.0f;
        L.ray[j] = 0;
        L.t[j] = 1.0f;
    }

    /// Lane j's ray on to its next sampled brick with samples to take (compositing the
    /// bricks of one value on the way, narrowing to the box of sampled leaves); false when the
    /// ray has no more in this pass.
    bool seek(int j) {
        RayWalk& w = mWalk[j];
        RayState& s = *mRay[j]->state;
        // The colour sums are the state's (flush() adds the queued samples to them); the
        // transmittance is the lane's.
        Accum acc{s.acc.r, s.acc.g, s.acc.b, L.t[j]};
        bool found = false;
        while (!found && w.next(f, s, *mRay[j]->resume)) {
            const BrickRef& b = f.bricks[w.index];
            if (b.slot == Slot::Constant) {
                settle(s, acc); // its queued samples first: each ray's sums in sample order
                if (!marchConstant(f, b.constant, w.k, w.kEnd, acc, mN)) break;
                continue;
            }
            int first = w.k, last = w.kEnd;
            if (f.occ && !clipToSampled(f, f.boxes[w.index], w.local(f), w.dv, w.invDv, w.invStep,
                                        w.t0, first, last))
                continue;
            const T* voxels = static_cast<const T*>(b.voxels);
            if (!mVoxels) mVoxels = voxels;
            // Gathers address a lane's voxels by 32-bit byte offsets from the packet's first
            // brick: a brick further away than that (never seen yet) is the scalar loop's
            // (pointers compared as integers: the bricks are separate allocations).
            const std::int64_t offset = (std::int64_t(reinterpret_cast<std::uintptr_t>(voxels)) -
                                         std::int64_t(reinterpret_cast<std::uintptr_t>(mVoxels))) /
                                        std::int64_t(sizeof(T));
            const std::int64_t span = std::int64_t(f.edge) * f.edge * f.edge;
            if ((std::abs(offset) + span) * std::int64_t(sizeof(T)) + 8 > f.gatherReach) {
                settle(s, acc);
                if (!marchAlone(voxels, w, first, last, acc)) break;
                continue;
            }
            const glm::vec3 local = w.local(f);
            mLaneVoxels[j] = voxels;
            L.k[j] = first;
            L.end[j] = last;
            L.base[j] = std::int32_t(offset);
            L.words[j] = w.index * f.occWords;
            L.fine[j] = std::int32_t(b.fine);
            L.t0[j] = w.t0;
            L.lx[j] = local.x;
            L.ly[j] = local.y;
            L.lz[j] = local.z;
            L.dx[j] = w.dv.x;
            L.dy[j] = w.dv.y;
            L.dz[j] = w.dv.z;
            L.ix[j] = w.invDv.x;
            L.iy[j] = w.invDv.y;
            L.iz[j] = w.invDv.z;
            L.wx[j] = w.d.x;
            L.wy[j] = w.d.y;
            L.wz[j] = w.d.z;
            found = true;
        }
        s.acc = acc;
        L.t[j] = acc.t;
        return found;
    }

    /// Before the ray of state s composites outside the queue: the queued samples added to
    /// its sums (and to every other ray's), so that acc holds them.
    void settle(const RayState& s, Accum& acc) {
        if (mQueue.count == 0) return;
        flush(true);
        acc.r = s.acc.r;
        acc.g = s.acc.g;
        acc.b = s.acc.b;
    }

    /// A brick too far from the packet's for its gathers: the scalar loop, samples [k, kEnd).
    bool marchAlone(const T* voxels, const RayWalk& w, int k, int kEnd, Accum& acc) {
        const std::uint32_t* words = f.occ ? f.occ + std::size_t(w.index) * f.occWords : nullptr;
        const std::uint32_t map = f.fine ? f.bricks[w.index].fine : 0;
        return marchBrick(f, voxels, words,
                          map ? reinterpret_cast<const std::uint8_t*>(f.fine + map) : nullptr,
                          w.local(f), w.dv, w.d, w.t0, k, kEnd, acc, mN);
    }

    /// Lane j, whose ray has no samples left to take (or that has no ray): its ray's next
    /// brick, or else the next ray of the queue that has one (finishing the rays it leaves).
    void refill(int j) {
        if (mRay[j] && !mStopped[j] && seek(j)) return;
        if (mRay[j]) mRay[j]->state->acc.t = L.t[j]; // its sums are the state's already
        mStopped[j] = false;
        while (mNext < mCount) {
            const std::size_t i = mNext++;
            const PacketRay& ray = mRays[i];
            if (!ray.state) continue;
            if (f.batch == 0) { // every ray is Fresh: set up a vector of them at once
                if (i >= mReadyFrom + mReadyCount) {
                    mReadyFrom = i;
                    mReadyCount = std::min(std::size_t(mLanes), mCount - i);
                    beginFresh(f, mRays + i, mReadyCount, mReady, mReadyOk);
                }
                if (!mReadyOk[i - mReadyFrom]) continue;
                mWalk[j] = mReady[i - mReadyFrom];
            } else if (!mWalk[j].begin(f, ray.sx, ray.sy, ray.shift, *ray.state, *ray.resume)) {
                continue;
            }
            mRay[j] = &ray;
            L.ray[j] = std::int32_t(i);
            L.t[j] = ray.state->acc.t;
            if (seek(j)) return;
            ray.state->acc.t = L.t[j];
        }
        idle(j);
    }

    /// Steps until every lane is out of samples and the queue out of rays: each step takes one
    /// sample of every lane in a sampled leaf and leaps the lanes in empty ones over the
    /// coarsest empty node that holds their sample (the scalar walk's emptyLevel() and
    /// sampleAfterNode(), to within an ulp at the node's exit, render/OCCUPANCY.md). Samples
    /// are taken as Sample<T> takes them (lanes outside the fused range by it) and composited
    /// lane by lane with the scalar composite(), so each ray's colour is the scalar march's.
    /// Lanes out of samples get their next brick or ray once a quarter of the lanes still
    /// with rays are.
    void march() {
        const DF df;
        const DI di;
        const VF step = hn::Set(df, f.stepMm), half = hn::Set(df, 0.5f), oneF = hn::Set(df, 1.0f);
        const VF invStep = hn::Set(df, 1.0f / f.stepMm), far = hn::Set(df, 3.0e38f);
        const VF apron = hn::Set(df, float(f.apron) - 0.5f), ertT = hn::Set(df, f.ertT);
        const VI one = hn::Set(di, 1);
        const auto* words = f.occ;
        // Distance maps (f.fine): a lane whose brick has one (L.fine != 0) leaps by it, the
        // others walk the octree.
        const bool maps = f.fine != nullptr;
        const VF cellSize = hn::Set(df, f.cell);
        const VI axis = hn::Set(di, f.cellAxis);
        for (;;) {
            const VF t0 = hn::Load(df, L.t0);
            const VF lx = hn::Load(df, L.lx), ly = hn::Load(df, L.ly), lz = hn::Load(df, L.lz);
            const VF dx = hn::Load(df, L.dx), dy = hn::Load(df, L.dy), dz = hn::Load(df, L.dz);
            const VF ix = hn::Load(df, L.ix), iy = hn::Load(df, L.iy), iz = hn::Load(df, L.iz);
            const VF wx = hn::Load(df, L.wx), wy = hn::Load(df, L.wy), wz = hn::Load(df, L.wz);
            const VF rx = hn::Add(lx, apron), ry = hn::Add(ly, apron), rz = hn::Add(lz, apron);
            const VI base = hn::Load(di, L.base), wordBase = hn::Load(di, L.words);
            const VI fineBase = hn::Load(di, L.fine);
            VI k = hn::Load(di, L.k), end = hn::Load(di, L.end);
            VF Tr = hn::Load(df, L.t);
            MI stopped = hn::FirstN(di, 0);
            MI active = hn::Lt(k, end);
            if (hn::AllFalse(di, active)) return flush(true);
            // Lanes out of rays for good, and how many more out of samples call for refills.
            std::size_t gone = 0;
            for (int j = 0; j < mLanes; ++j)
                gone += mRay[j] ? 0 : 1;
            const std::size_t refillAt = gone + std::max<std::size_t>(1, (mLanes - gone) / 4);
            // Unshaded, a sample's colour is two gathers a channel, as cheap in the step as in
            // the queue: the step composites it at once into the lanes' sums (R, G, B), which
            // go back to the rays' states before anything else composites into them.
            const bool direct = !f.shading;
            VF R = hn::Zero(df), G = hn::Zero(df), B = hn::Zero(df);
            if (direct) loadSums(R, G, B);
            while (hn::CountTrue(di, hn::Not(active)) < refillAt) {
                const VF t = hn::Add(t0, hn::Mul(hn::Add(hn::ConvertTo(df, k), half), step));
                MI take = active;
                if (words) {
                    const VI ax = leafOf(f, lx, dx, t), ay = leafOf(f, ly, dy, t),
                             az = leafOf(f, lz, dz, t);
                    MI sampled = nodeSampled(f, words, wordBase, ax, ay, az, f.octDepth);
                    // Lanes with a map: its distance d at the sample's cell (sample where 0).
                    MI mapped = hn::FirstN(di, 0);
                    VI cx = hn::Zero(di), cy = cx, cz = cx, d = cx;
                    if (maps) {
                        mapped = hn::Ne(fineBase, hn::Zero(di));
                        if (!hn::AllFalse(di, mapped)) {
                            cx = mapCellOf(f, lx, dx, t);
                            cy = mapCellOf(f, ly, dy, t);
                            cz = mapCellOf(f, lz, dz, t);
                            const VI cell =
                                hn::Add(hn::Mul(hn::Add(hn::Mul(cz, axis), cy), axis), cx);
                            const VI word =
                                hn::GatherIndex(di, reinterpret_cast<const std::int32_t*>(f.fine),
                                                hn::Add(hn::ShiftRight<2>(cell), fineBase));
                            d = hn::And(
                                hn::Shr(word, hn::ShiftLeft<3>(hn::And(cell, hn::Set(di, 3)))),
                                hn::Set(di, 255));
                            sampled = hn::Or(hn::And(mapped, hn::Eq(d, hn::Zero(di))),
                                             hn::AndNot(mapped, sampled));
                        }
                    }
                    const MI empty = hn::AndNot(sampled, active);
                    if (!hn::AllFalse(di, empty)) {
                        // BrickRay::exitOf() on one axis, for a cube at lo of edge size.
                        auto exitOn = [&](VF lo, VF size, VF local, VF dir, VF inv) {
                            const VF face =
                                hn::Add(lo, hn::IfThenElseZero(hn::Gt(dir, hn::Zero(df)), size));
                            return hn::IfThenElse(hn::Eq(dir, hn::Zero(df)), far,
                                                  hn::Mul(hn::Sub(face, local), inv));
                        };
                        auto exitOfCube = [&](VI nx, VI ny, VI nz, VF size) {
                            return hn::Min(
                                hn::Min(
                                    hn::Min(far, exitOn(hn::Mul(hn::ConvertTo(df, nx), size), size,
                                                        lx, dx, ix)),
                                    exitOn(hn::Mul(hn::ConvertTo(df, ny), size), size, ly, dy, iy)),
                                exitOn(hn::Mul(hn::ConvertTo(df, nz), size), size, lz, dz, iz));
                        };
                        VF tExit = far;
                        const MI tree = hn::AndNot(mapped, empty);
                        if (!hn::AllFalse(di, tree)) {
                            // The coarsest empty level per lane, walked up from the leaf
                            // (coarsestEmpty()).
                            VI level = hn::Set(di, 1);
                            MI found = hn::Not(tree);
                            for (int l = f.octDepth - 1; l >= 1 && !hn::AllTrue(di, found); --l) {
                                const MI set = hn::AndNot(
                                    found, nodeSampled(f, words, wordBase, ax, ay, az, l));
                                level = hn::IfThenElse(set, hn::Set(di, l + 1), level);
                                found = hn::Or(found, set);
                            }
                            const VI shift = hn::Sub(hn::Set(di, f.octDepth), level);
                            const VF size = hn::Mul(hn::Set(df, f.leaf),
                                                    hn::ConvertTo(df, hn::Shl(one, shift)));
                            tExit = exitOfCube(hn::Shr(ax, shift), hn::Shr(ay, shift),
                                               hn::Shr(az, shift), size);
                        }
                        const MI cube = hn::And(mapped, empty);
                        if (!hn::AllFalse(di, cube)) {
                            // sampleAfterCube(): the cells within d - 1 of the sample's are
                            // empty. Its corner at (c - d) cell + 1/2, its edge 2d - 1 cells.
                            const VI back = hn::Sub(d, one);
                            const VF size = hn::Mul(
                                hn::ConvertTo(df, hn::Add(hn::Add(back, back), one)), cellSize);
                            auto lo = [&](VI c, VF local, VF dir, VF inv) {
                                return exitOn(
                                    hn::Add(hn::Mul(hn::ConvertTo(df, hn::Sub(c, d)), cellSize),
                                            half),
                                    size, local, dir, inv);
                            };
                            const VF tCube = hn::Min(
                                hn::Min(hn::Min(far, lo(cx, lx, dx, ix)), lo(cy, ly, dy, iy)),
                                lo(cz, lz, dz, iz));
                            tExit = hn::IfThenElse(hn::RebindMask(df, cube), tCube, tExit);
                        }
                        const VF after =
                            hn::Ceil(hn::Sub(hn::Mul(hn::Sub(tExit, t0), invStep), half));
                        const VF to = hn::Max(hn::Min(after, hn::ConvertTo(df, end)),
                                              hn::ConvertTo(df, hn::Add(k, one)));
                        k = hn::IfThenElse(empty, hn::ConvertTo(di, to), k);
                        mN.leaps += hn::CountTrue(di, empty);
                        take = hn::And(active, sampled);
                        if (hn::AllFalse(di, take)) {
                            active = hn::AndNot(stopped, hn::Lt(k, end));
                            continue;
                        }
                    }
                }
                const SamplesV<T> samples(f, mVoxels, hn::Add(rx, hn::Mul(dx, t)),
                                          hn::Add(ry, hn::Mul(dy, t)), hn::Add(rz, hn::Mul(dz, t)),
                                          base, false);
                const auto takeF = hn::RebindMask(df, take);
                const auto odd = hn::AndNot(samples.fused, takeF); // for the scalar code
                if (!hn::AllFalse(df, odd)) {
                    if (direct) storeSums(R, G, B);
                    Tr = scalarLanes(odd, t, Tr);
                    if (direct) loadSums(R, G, B);
                    stopped = hn::Or(stopped, hn::RebindMask(di, hn::And(odd, hn::Le(Tr, ertT))));
                }
                mN.samples += hn::CountTrue(di, take);
                k = hn::IfThenElse(take, hn::Add(k, one), k);
                // composite()'s transmittance now, its colour sums once the colour is known.
                const VF a = samples.a;
                const auto vis = hn::And(hn::And(takeF, samples.fused), hn::Gt(a, hn::Zero(df)));
                if (!hn::AllFalse(df, vis)) {
                    const VF w = hn::Mul(Tr, a);
                    if (direct) { // composite()'s sums: acc.r += w * c.r, lane by lane
                        R = hn::IfThenElse(vis, hn::Add(R, hn::Mul(w, samples.channel(0))), R);
                        G = hn::IfThenElse(vis, hn::Add(G, hn::Mul(w, samples.channel(1))), G);
                        B = hn::IfThenElse(vis, hn::Add(B, hn::Mul(w, samples.channel(2))), B);
                    } else {
                        defer(samples, vis, w, wx, wy, wz);
                    }
                    Tr = hn::IfThenElse(vis, hn::Mul(Tr, hn::Sub(oneF, a)), Tr);
                    stopped = hn::Or(stopped, hn::RebindMask(di, hn::And(vis, hn::Le(Tr, ertT))));
                }
                active = hn::AndNot(stopped, hn::Lt(k, end));
            }
            // A quarter of the lanes (or all) are out of samples: their next bricks or rays.
            // The queued samples stay queued: they name their rays, not lanes.
            if (direct) storeSums(R, G, B);
            hn::Store(Tr, df, L.t);
            hn::Store(k, di, L.k);
            std::uint8_t doneBits[(kMax + 7) / 8 + 8] = {}, stopBits[(kMax + 7) / 8 + 8] = {};
            hn::StoreMaskBits(di, hn::Not(active), doneBits);
            hn::StoreMaskBits(di, stopped, stopBits);
            for (int j = 0; j < mLanes; ++j) {
                if (((doneBits[j >> 3] >> (j & 7)) & 1) == 0) continue;
                mStopped[j] = ((stopBits[j >> 3] >> (j & 7)) & 1) != 0;
                refill(j);
            }
        }
    }

    /// The colour sums of the lanes' rays, as vectors (0 in a lane without a ray).
    void loadSums(VF& R, VF& G, VF& B) const {
        const DF df;
        HWY_ALIGN float r[kMax] = {}, g[kMax] = {}, b[kMax] = {};
        for (int j = 0; j < mLanes; ++j) {
            if (!mRay[j]) continue;
            const Accum& acc = mRay[j]->state->acc;
            r[j] = acc.r;
            g[j] = acc.g;
            b[j] = acc.b;
        }
        R = hn::Load(df, r);
        G = hn::Load(df, g);
        B = hn::Load(df, b);
    }
    void storeSums(VF R, VF G, VF B) {
        const DF df;
        HWY_ALIGN float r[kMax], g[kMax], b[kMax];
        hn::Store(R, df, r);
        hn::Store(G, df, g);
        hn::Store(B, df, b);
        for (int j = 0; j < mLanes; ++j) {
            if (!mRay[j]) continue;
            Accum& acc = mRay[j]->state->acc;
            acc.r = r[j];
            acc.g = g[j];
            acc.b = b[j];
        }
    }

    /// The lanes of `odd` (outside the fused range) sampled by the scalar code, Sample<T>,
    /// and composited at once (after the colours deferred so far); returns the transmittance.
    VF scalarLanes(hn::Mask<DF> odd, VF t, VF tr) {
        const DF df;
        flush(true);
        HWY_ALIGN float ts[kMax];
        hn::Store(t, df, ts);
        hn::Store(tr, df, L.t);
        std::uint8_t bits[(kMax + 7) / 8 + 8] = {};
        hn::StoreMaskBits(df, odd, bits);
        for (std::size_t j = 0; j < kMax; ++j) {
            if (((bits[j >> 3] >> (j & 7)) & 1) == 0) continue;
            const glm::vec3 rel = glm::vec3(L.lx[j], L.ly[j], L.lz[j]) + (float(f.apron) - 0.5f);
            const glm::vec3 dv(L.dx[j], L.dy[j], L.dz[j]);
            const Rgba c = colourOf(f, Sample<T>(mLaneVoxels[j], f.edge, rel + dv * ts[j]),
                                    glm::vec3(L.wx[j], L.wy[j], L.wz[j]));
            if (c.a <= 0.0f) continue;
            Accum& sums = mRay[j]->state->acc;
            Accum acc{sums.r, sums.g, sums.b, L.t[j]};
            composite(acc, c);
            sums.r = acc.r;
            sums.g = acc.g;
            sums.b = acc.b;
            L.t[j] = acc.t;
        }
        return hn::Load(df, L.t);
    }

    /// Queues the visible lanes' samples for their colour (classify()'s colour, shaded), with
    /// their compositing weights w = t a: a lane's colour sums add w * colour in the order
    /// its samples were taken, as composite() does, when flush() has the colours.
    void defer(const SamplesV<T>& s, hn::Mask<DF> vis, VF w, VF wx, VF wy, VF wz) {
        const DF df;
        const DI di;
        const auto visI = hn::RebindMask(di, vis);
        Deferred& q = mQueue;
        const std::size_t at = q.count;
        appendTo(s.o, visI, di, q.o + at);
        appendTo(s.e, visI, di, q.e + at);
        appendTo(hn::Load(di, L.ray), visI, di, q.ray + at);
        appendTo(s.fx, vis, df, q.fx + at);
        appendTo(s.fy, vis, df, q.fy + at);
        appendTo(s.fz, vis, df, q.fz + at);
        appendTo(s.w, vis, df, q.tw + at);
        appendTo(w, vis, df, q.w + at);
        appendTo(wx, vis, df, q.dx + at);
        appendTo(wy, vis, df, q.dy + at);
        appendTo(wz, vis, df, q.dz + at);
        q.count += hn::CountTrue(df, vis);
        if (q.count >= std::size_t(mLanes)) flush(false);
    }

    /// The colours of the queued samples, a vector at a time, added to their lanes' sums in
    /// queue order; `all`: down to the last (else whole vectors only).
    void flush(bool all) {
        const DF df;
        const DI di;
        Deferred& q = mQueue;
        const std::size_t lanes = hn::Lanes(df);
        std::size_t done = 0;
        while (q.count - done >= lanes || (all && done < q.count)) {
            const std::size_t count = std::min(lanes, q.count - done);
            const auto valid = hn::FirstN(di, count);
            const auto validF = hn::RebindMask(df, valid);
            // Lanes past the queue read a cell inside the packet's first brick.
            const VI o = hn::IfThenElse(valid, hn::LoadU(di, q.o + done),
                                        hn::Set(di, 1 + f.edge + f.edge * f.edge));
            const VI e = hn::IfThenElseZero(valid, hn::LoadU(di, q.e + done));
            const VF tw = hn::IfThenElseZero(validF, hn::LoadU(df, q.tw + done));
            auto channel = [&](int ch) { return tfChannel(f, e, tw, ch); };
            VF r = channel(0), g = channel(1), b = channel(2);
            if (f.shading) {
                const VF fx = hn::LoadU(df, q.fx + done), fy = hn::LoadU(df, q.fy + done),
                         fz = hn::LoadU(df, q.fz + done);
                const VI sy = hn::Set(di, f.edge), sz = hn::Set(di, f.edge * f.edge);
                CellRows c;
                cellRows(mVoxels, o, sy, sz, true, c);
                VF gx, gy, gz;
                gradientOf(mVoxels, o, sy, sz, c, fx, fy, fz, gx, gy, gz);
                shadeV(f, hn::LoadU(df, q.dx + done), hn::LoadU(df, q.dy + done),
                       hn::LoadU(df, q.dz + done), gx, gy, gz, r, g, b);
            }
            const VF w = hn::LoadU(df, q.w + done);
            HWY_ALIGN float wr[kMax], wg[kMax], wb[kMax];
            hn::Store(hn::Mul(w, r), df, wr);
            hn::Store(hn::Mul(w, g), df, wg);
            hn::Store(hn::Mul(w, b), df, wb);
            for (std::size_t i = 0; i < count; ++i) {
                Accum& sums = mRays[q.ray[done + i]].state->acc;
                sums.r += wr[i];
                sums.g += wg[i];
                sums.b += wb[i];
            }
            done += count;
        }
        if (done == 0) return;
        q.count -= done;
        for (std::size_t i = 0; i < q.count; ++i) { // the rest to the front
            q.o[i] = q.o[done + i];
            q.e[i] = q.e[done + i];
            q.ray[i] = q.ray[done + i];
            q.fx[i] = q.fx[done + i];
            q.fy[i] = q.fy[done + i];
            q.fz[i] = q.fz[done + i];
            q.tw[i] = q.tw[done + i];
            q.w[i] = q.w[done + i];
            q.dx[i] = q.dx[done + i];
            q.dy[i] = q.dy[done + i];
            q.dz[i] = q.dz[done + i];
        }
    }

    /// Visible samples waiting for their colours (defer(), flush()): up to a vector's lanes
    /// less one, and a vector's more while one is queued (appendTo() writes whole vectors).
    struct Deferred {
        static constexpr std::size_t kSize = 2 * kMax + 8;
        HWY_ALIGN std::int32_t o[kSize], e[kSize], ray[kSize]; ///< ray: its index in mRays
        HWY_ALIGN float fx[kSize], fy[kSize], fz[kSize], tw[kSize], w[kSize];
        HWY_ALIGN float dx[kSize], dy[kSize], dz[kSize];
        std::size_t count = 0;
    };

    const Frame& f;
    const PacketRay* mRays;
    std::size_t mCount, mNext = 0;
    int mLanes;
    RayCount& mN;
    Lanes L;
    RayWalk mWalk[kMax];
    const PacketRay* mRay[kMax] = {}; ///< each lane's ray (null: none)
    bool mStopped[kMax] = {};         ///< its ray became opaque
    RayWalk mReady[kMax];             ///< walks of rays [mReadyFrom, + mReadyCount) (beginFresh)
    bool mReadyOk[kMax] = {};
    std::size_t mReadyFrom = 0, mReadyCount = 0;
    const T* mVoxels = nullptr;      ///< the first brick the packet sampled: the lanes' base
    const T* mLaneVoxels[kMax] = {}; ///< each lane's brick
    Deferred mQueue;
};

void MarchPacket(brickstore::VoxelType type, const Frame& f, const PacketRay* rays,
                 std::size_t count, RayCount& n) {
    const int lanes = int(hn::Lanes(DF()));
    switch (type) {
    case brickstore::VoxelType::U8:
        return Packet<std::uint8_t>(f, rays, count, lanes, n).run();
    case brickstore::VoxelType::U16:
        return Packet<std::uint16_t>(f, rays, count, lanes, n).run();
    case brickstore::VoxelType::I16:
        return Packet<std::int16_t>(f, rays, count, lanes, n).run();
    case brickstore::VoxelType::F32:
        return Packet<float>(f, rays, count, lanes, n).run();
    }
}

std::int64_t Target() {
    return HWY_TARGET;
}
int LaneCount() {
    return int(hn::Lanes(DF()));
}

} // namespace HWY_NAMESPACE
} // namespace bc::render::detail
HWY_AFTER_NAMESPACE();

#if HWY_ONCE
namespace bc::render::detail {

HWY_EXPORT(MarchBrick);
HWY_EXPORT(MarchPacket);
HWY_EXPORT(Target);
HWY_EXPORT(LaneCount);

bool marchBrickSimd(brickstore::VoxelType type, const Frame& f, const void* voxels,
                    const std::uint32_t* words, glm::vec3 local, glm::vec3 dv, glm::vec3 dir,
                    float t0, int& k, int kEnd, Accum& acc, RayCount& n) {
    return HWY_DYNAMIC_DISPATCH(MarchBrick)(type, f, voxels, words, local, dv, dir, t0, k, kEnd,
                                            acc, n);
}

void marchPacketSimd(brickstore::VoxelType type, const Frame& f, const PacketRay* rays,
                     std::size_t count, RayCount& n) {
    HWY_DYNAMIC_DISPATCH(MarchPacket)(type, f, rays, count, n);
}

std::string simdTargetName() {
    return hwy::TargetName(HWY_DYNAMIC_DISPATCH(Target)());
}

int simdLanes() {
    return HWY_DYNAMIC_DISPATCH(LaneCount)();
}

} // namespace bc::render::detail
#endif
