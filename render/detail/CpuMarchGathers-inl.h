// Gathers of the CPU raycaster's SIMD march (render/detail/CpuMarchSimd.cpp): a vector of
// samples' voxels read from their bricks (pairs of x neighbours, cell rows and their x
// neighbours), and the trilinear weights and central differences made of them.
//
// Gathers are the floor under a step's time (bench/GatherProbe.cpp: a 16-lane gather costs
// about what 16 scalar loads do on the dev VM), so each reads as few elements as it can: a
// 16-bit voxel pair is one 32-bit lane, a 32-bit voxel pair or a TF channel's two ends
// (tfPairTable()) one 64-bit lane, and a cell row with its x neighbours one 64-bit lane for
// 16-bit voxels.
//
// Per-target code in Highway's -inl.h form: include it only from render/detail/CpuMarchSimd.cpp,
// which foreach_target re-includes once per target (hence the toggle guard below, not
// #pragma once). That file is compiled with -ffp-contract=off (render/CMakeLists.txt) and this
// header's code inherits it only by being included there: a lane's float operations must stay
// the scalar code's, unfused.

// Per-target include guard: flipped with HWY_TARGET_TOGGLE for each target.
#if defined(BRICKCAST_RENDER_DETAIL_CPUMARCHGATHERS_INL_H_) == defined(HWY_TARGET_TOGGLE)
#ifdef BRICKCAST_RENDER_DETAIL_CPUMARCHGATHERS_INL_H_
#undef BRICKCAST_RENDER_DETAIL_CPUMARCHGATHERS_INL_H_
#else
#define BRICKCAST_RENDER_DETAIL_CPUMARCHGATHERS_INL_H_
#endif

#include <hwy/highway.h>

#include <cstdint>
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

/// lerp1() of CpuSampling.h per lane: a + t (b - a).
HWY_INLINE VF lerpV(VF a, VF b, VF t) {
    return hn::Add(a, hn::Mul(t, hn::Sub(b, a)));
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

} // namespace HWY_NAMESPACE
} // namespace bc::render::detail
HWY_AFTER_NAMESPACE();

#endif // BRICKCAST_RENDER_DETAIL_CPUMARCHGATHERS_INL_H_
