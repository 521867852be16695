// The CPU raycaster's brick march vectorised across consecutive samples of one ray
// (render/detail/CpuMarchSimd.h), compiled once per instruction set by Highway's
// foreach_target and dispatched at run time to the best one the host has.
//
// Why across samples and not across rays: the brick DDA, the octree leaps and early
// termination stay the scalar code's, per ray, unchanged; only the per-sample work (8 to 32
// voxel loads, trilinear weights, the TF lookup, the gradient and the shading) runs a vector
// of samples at a time, and the samples of one ray in one brick share the brick's voxels.
//
// Same image as the scalar march, bit for bit: every lane does the scalar code's float
// operations in the scalar code's order, and this file is compiled without contraction into
// fused multiply-adds (render/CMakeLists.txt), so a sample's colour does not depend on the
// lane it ran in, on the vector width, or on whether it ran here at all. Compositing stays
// sequential, lane by lane, so early termination stops at the same sample.
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
HWY_INLINE PairF pairAt(const float* v, VI o) {
    const DF df;
    return {hn::GatherIndex(df, v, o), hn::GatherIndex(df, v, hn::Add(o, hn::Set(DI(), 1)))};
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
HWY_INLINE QuadF quadAt(const float* v, VI o) {
    return {pairAt(v, o), outerAt(v, o)};
}

HWY_INLINE VF lerpV(VF a, VF b, VF t) {
    const VF one = hn::Set(DF(), 1.0f);
    return hn::Add(hn::Mul(a, hn::Sub(one, t)), hn::Mul(b, t));
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

/// The rows at o, o + sy, o + sz, o + sy + sz; with their x neighbours when `withOuter` and
/// the voxels are narrow enough to read all four in one gather lane.
template <class T>
HWY_INLINE void cellRows(const T* v, VI o, VI sy, VI sz, bool withOuter, CellRows& c) {
    const VI o10 = hn::Add(o, sy), o01 = hn::Add(o, sz), o11 = hn::Add(o10, sz);
    if (sizeof(T) <= 2 && withOuter) {
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

/// shade() of CpuRay.h per lane (r, g, b in place; lanes with a zero gradient keep theirs).
HWY_INLINE void shadeV(const Frame& f, glm::vec3 dir, VF gx, VF gy, VF gz, VF& r, VF& g, VF& b) {
    const DF df;
    gx = hn::Mul(gx, hn::Set(df, f.gradScale.x));
    gy = hn::Mul(gy, hn::Set(df, f.gradScale.y));
    gz = hn::Mul(gz, hn::Set(df, f.gradScale.z));
    const VF len = hn::Sqrt(hn::Add(hn::Add(hn::Mul(gx, gx), hn::Mul(gy, gy)), hn::Mul(gz, gz)));
    const auto lit = hn::Gt(len, hn::Zero(df));
    const VF nx = hn::Div(gx, len), ny = hn::Div(gy, len), nz = hn::Div(gz, len);
    const VF diff =
        hn::Abs(hn::Add(hn::Add(hn::Mul(nx, hn::Set(df, dir.x)), hn::Mul(ny, hn::Set(df, dir.y))),
                        hn::Mul(nz, hn::Set(df, dir.z))));
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

/// Samples [k, k + count) of one brick, count <= Lanes(DF()); false once the ray is opaque.
///
/// Voxel reads, with the lane's position q clamped into the fused range [1, edge - 2) (lanes
/// outside it are redone by the scalar code): the cell is x0..x0+1, y0..y0+1, z0..z0+1 with
/// 1 <= x0, y0, z0 <= edge - 3, the gradient reads one voxel beyond on each axis (0 .. edge -
/// 1), so no read leaves the brick; the 4-byte gathers of 8-bit voxels read up to 2 bytes past
/// the voxel they need, which stays inside since the last row of the last slice (z = y =
/// edge - 1) is never a row read here (z = edge - 1 is read only for rows y0 and y0 + 1).
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
    const VF qx = hn::Add(hn::Set(df, rel.x), hn::Mul(hn::Set(df, dv.x), t));
    const VF qy = hn::Add(hn::Set(df, rel.y), hn::Mul(hn::Set(df, dv.y), t));
    const VF qz = hn::Add(hn::Set(df, rel.z), hn::Mul(hn::Set(df, dv.z), t));
    const VF one = hn::Set(df, 1.0f), hi = hn::Set(df, float(f.edge - 2));
    const auto fused = hn::And(
        hn::And(hn::And(hn::Ge(qx, one), hn::Lt(qx, hi)), hn::And(hn::Ge(qy, one), hn::Lt(qy, hi))),
        hn::And(hn::Ge(qz, one), hn::Lt(qz, hi)));
    const bool allFused = hn::AllTrue(df, fused);
    // Addresses from positions clamped into the fused range, which leaves a fused lane's own
    // (Max first: it returns 1 for a NaN position).
    const VF top = hn::Set(df, std::nextafter(float(f.edge - 2), 0.0f));
    auto inside = [&](VF q) { return hn::Min(hn::Max(q, one), top); };
    const VF cx = allFused ? qx : inside(qx), cy = allFused ? qy : inside(qy),
             cz = allFused ? qz : inside(qz);
    const VI x0 = hn::ConvertTo(di, cx), y0 = hn::ConvertTo(di, cy), z0 = hn::ConvertTo(di, cz);
    const VF fx = hn::Sub(cx, hn::ConvertTo(df, x0)), fy = hn::Sub(cy, hn::ConvertTo(df, y0)),
             fz = hn::Sub(cz, hn::ConvertTo(df, z0));
    const VI sy = hn::Set(di, f.edge), sz = hn::Set(di, f.edge * f.edge);
    const VI o = hn::Add(hn::Add(hn::Mul(z0, sz), hn::Mul(y0, sy)), x0);
    CellRows c;
    cellRows(v, o, sy, sz, f.shading, c);
    const VF value =
        lerpV(lerpV(lerpV(c.r00.lo, c.r00.hi, fx), lerpV(c.r10.lo, c.r10.hi, fx), fy),
              lerpV(lerpV(c.r01.lo, c.r01.hi, fx), lerpV(c.r11.lo, c.r11.hi, fx), fy), fz);
    // classify() per lane.
    const VF u =
        hn::Min(hn::Max(hn::Add(hn::Mul(value, hn::Set(df, f.tfScale)), hn::Set(df, f.tfOffset)),
                        hn::Zero(df)),
                hn::Set(df, float(f.entries - 1)));
    const VI entry = hn::Min(hn::ConvertTo(di, u), hn::Set(di, f.entries - 2));
    const VF w = hn::Sub(u, hn::ConvertTo(df, entry));
    const VI e = hn::ShiftLeft<2>(entry);
    auto channel = [&](int ch) {
        return lerpV(hn::GatherIndex(df, f.tf, hn::Add(e, hn::Set(di, ch))),
                     hn::GatherIndex(df, f.tf, hn::Add(e, hn::Set(di, ch + 4))), w);
    };
    const VF a = channel(3);
    if (allFused && hn::AllFalse(df, hn::Gt(a, hn::Zero(df)))) {
        n.samples += std::uint64_t(count);
        return true;
    }
    VF r = channel(0), g = channel(1), b = channel(2);
    if (f.shading) {
        VF gx, gy, gz;
        gradientOf(v, o, sy, sz, c, fx, fy, fz, gx, gy, gz);
        shadeV(f, dir, gx, gy, gz, r, g, b);
    }
    HWY_ALIGN float rs[kMax], gs[kMax], bs[kMax], as[kMax], ts[kMax];
    hn::Store(r, df, rs);
    hn::Store(g, df, gs);
    hn::Store(b, df, bs);
    hn::Store(a, df, as);
    std::uint8_t fusedBits[(kMax + 7) / 8 + 8] = {};
    if (!allFused) {
        hn::StoreMaskBits(df, fused, fusedBits);
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
HWY_EXPORT(Target);
HWY_EXPORT(LaneCount);

bool marchBrickSimd(brickstore::VoxelType type, const Frame& f, const void* voxels,
                    const std::uint32_t* words, glm::vec3 local, glm::vec3 dv, glm::vec3 dir,
                    float t0, int& k, int kEnd, Accum& acc, RayCount& n) {
    return HWY_DYNAMIC_DISPATCH(MarchBrick)(type, f, voxels, words, local, dv, dir, t0, k, kEnd,
                                            acc, n);
}

std::string simdTargetName() {
    return hwy::TargetName(HWY_DYNAMIC_DISPATCH(Target)());
}

int simdLanes() {
    return HWY_DYNAMIC_DISPATCH(LaneCount)();
}

} // namespace bc::render::detail
#endif
