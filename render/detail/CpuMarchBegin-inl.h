// Ray set-up of the CPU raycaster's SIMD march (render/detail/CpuMarchSimd.cpp): the walks of
// a vector of fresh rays through the brick grid, set up at once (RayWalk::begin() per lane).
//
// Per-target code in Highway's -inl.h form: include it only from render/detail/CpuMarchSimd.cpp,
// which foreach_target re-includes once per target (hence the toggle guard below, not
// #pragma once), and which alone defines its non-inline functions. That file is compiled with
// -ffp-contract=off (render/CMakeLists.txt) and this header's code inherits it only by being
// included there: a lane's float operations must stay the scalar code's, unfused.
#include "render/detail/CpuMarchSimd.h"

#include <cstddef>
#include <cstdint>

// Per-target include guard: flipped with HWY_TARGET_TOGGLE for each target.
#if defined(BRICKCAST_RENDER_DETAIL_CPUMARCHBEGIN_INL_H_) == defined(HWY_TARGET_TOGGLE)
#ifdef BRICKCAST_RENDER_DETAIL_CPUMARCHBEGIN_INL_H_
#undef BRICKCAST_RENDER_DETAIL_CPUMARCHBEGIN_INL_H_
#else
#define BRICKCAST_RENDER_DETAIL_CPUMARCHBEGIN_INL_H_
#endif

#include "render/detail/CpuMarchGathers-inl.h"

#include <hwy/highway.h>

HWY_BEFORE_NAMESPACE();
namespace bc::render::detail {
namespace HWY_NAMESPACE {

/// The rays' origins o and directions d per lane for image-plane positions (SX, SY), as
/// RayWalk::begin() sets them up (glm::normalize is v * (1 / sqrt(dot(v, v)))).
HWY_INLINE void rayBasis(const Frame& f, VF SX, VF SY, VF* o, VF* d) {
    const DF df;
    auto along = [&](float base, float right, float up) { // base + sx right + sy up
        return hn::Add(hn::Add(hn::Set(df, base), hn::Mul(SX, hn::Set(df, right))),
                       hn::Mul(SY, hn::Set(df, up)));
    };
    for (int a = 0; a < 3; ++a) {
        o[a] = f.ortho ? along(f.eye[a], f.right[a], f.up[a]) : hn::Set(df, f.eye[a]);
        d[a] = f.ortho ? hn::Set(df, f.forward[a]) : along(f.forward[a], f.right[a], f.up[a]);
    }
    if (f.ortho) return;
    const VF inv = hn::Div(
        hn::Set(df, 1.0f),
        hn::Sqrt(hn::Add(hn::Add(hn::Mul(d[0], d[0]), hn::Mul(d[1], d[1])), hn::Mul(d[2], d[2]))));
    for (int a = 0; a < 3; ++a)
        d[a] = hn::Mul(d[a], inv);
}

/// The rays in voxels (origins ov, directions dv, inv = 1 / dv) and where they enter (t0) and
/// leave (t1) the volume's box (std::min and std::max by their own comparisons); returns the
/// lanes that miss it, and those past `count`.
HWY_INLINE hn::Mask<DF> clipToVolume(const Frame& f, const VF* o, const VF* d, std::size_t count,
                                     VF* ov, VF* dv, VF* inv, VF& t0, VF& t1) {
    const DF df;
    const VF zero = hn::Zero(df);
    auto minOf = [](VF a, VF b) { return hn::IfThenElse(hn::Lt(b, a), b, a); }; // std::min
    auto maxOf = [](VF a, VF b) { return hn::IfThenElse(hn::Lt(a, b), b, a); }; // std::max
    t0 = zero;
    t1 = hn::Set(df, 3.0e38f);
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
    return miss;
}

/// beginFresh()'s walks per lane, stored from its vectors for each ray's RayWalk.
struct FreshLanes {
    static constexpr std::size_t kMax = hn::MaxLanes(DF());
    HWY_ALIGN float d[3][kMax], ov[3][kMax], dv[3][kMax], invDv[3][kMax], tDelta[3][kMax];
    HWY_ALIGN float tMax[kMax]; ///< one axis at a time
    HWY_ALIGN std::int32_t cell[3][kMax];
    HWY_ALIGN float t0[kMax];
    HWY_ALIGN std::int32_t total[kMax];
    std::uint8_t missBits[(kMax + 7) / 8 + 8] = {};
};

/// The rays' cells of the brick grid at t0 and their DDA steps (tDelta, and tMax straight into
/// walks[0, count)), stored per axis into `out` with the rays' d, ov, dv and inv.
HWY_INLINE void storeAxes(const Frame& f, const VF* d, const VF* ov, const VF* dv, const VF* inv,
                          VF t0, std::size_t count, FreshLanes& out, RayWalk* walks) {
    const DF df;
    const DI di;
    const VF zero = hn::Zero(df);
    const float brick = float(f.brick);
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
        hn::Store(cell, di, out.cell[a]);
        hn::Store(d[a], df, out.d[a]);
        hn::Store(ov[a], df, out.ov[a]);
        hn::Store(dv[a], df, out.dv[a]);
        hn::Store(inv[a], df, out.invDv[a]);
        hn::Store(hn::IfThenElse(still, far, hn::Mul(hn::Set(df, brick), hn::Abs(inv[a]))), df,
                  out.tDelta[a]);
        // tMax, kept where the cell is known: out.tMax holds one axis at a time.
        hn::Store(hn::IfThenElse(still, far, hn::Mul(hn::Sub(plane, ov[a]), inv[a])), df, out.tMax);
        for (std::size_t i = 0; i < count; ++i)
            walks[i].tMax[a] = out.tMax[i];
    }
}

/// Each ray's walk and ok[i] from the lanes, as begin() leaves them; the rays marked Done.
HWY_INLINE void unpackWalks(const Frame& f, const PacketRay* rays, std::size_t count, float invStep,
                            const FreshLanes& out, RayWalk* walks, bool* ok) {
    for (std::size_t i = 0; i < count; ++i) {
        RayWalk& w = walks[i];
        ok[i] = ((out.missBits[i >> 3] >> (i & 7)) & 1) == 0;
        if (rays[i].state) rays[i].state->phase = RayPhase::Done;
        if (!ok[i]) continue;
        for (int a = 0; a < 3; ++a) {
            w.d[a] = out.d[a][i];
            w.ov[a] = out.ov[a][i];
            w.dv[a] = out.dv[a][i];
            w.invDv[a] = out.invDv[a][i];
            w.tDelta[a] = out.tDelta[a][i];
            w.cell[a] = out.cell[a][i];
            w.stepDir[a] = w.dv[a] > 0.0f ? 1 : w.dv[a] < 0.0f ? -1 : 0;
        }
        w.t0 = out.t0[i];
        w.invStep = invStep;
        w.total = out.total[i];
        w.k = w.kEnd = w.index = w.first = 0;
        w.entered = false;
        if (f.clip.any) { // as begin() narrows it, from the same origin and direction
            const glm::vec3 o = f.ortho ? f.eye + rays[i].sx * f.right + rays[i].sy * f.up : f.eye;
            ok[i] = w.clipSamples(f, o);
            w.k = w.first;
        }
    }
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
    VF o[3], d[3];
    rayBasis(f, hn::Load(df, sx), hn::Load(df, sy), o, d);
    VF ov[3], dv[3], inv[3], t0, t1;
    auto miss = clipToVolume(f, o, d, count, ov, dv, inv, t0, t1);
    const float invStep = 1.0f / f.stepMm;
    t0 = hn::Add(t0, hn::Mul(hn::Load(df, shift), hn::Set(df, f.stepMm)));
    const VF totalF =
        hn::Ceil(hn::Sub(hn::Mul(hn::Sub(t1, t0), hn::Set(df, invStep)), hn::Set(df, 0.5f)));
    // Where the count does not fit an int the ray is refused (begin() would misbehave).
    miss = hn::Or(miss, hn::Not(hn::Lt(totalF, hn::Set(df, 2.0e9f))));
    miss = hn::Or(miss, hn::Not(hn::Gt(totalF, hn::Zero(df))));
    FreshLanes out;
    storeAxes(f, d, ov, dv, inv, t0, count, out, walks);
    hn::Store(t0, df, out.t0);
    hn::Store(hn::ConvertTo(di, hn::IfThenElseZero(hn::Not(miss), totalF)), di, out.total);
    hn::StoreMaskBits(df, miss, out.missBits);
    unpackWalks(f, rays, count, invStep, out, walks, ok);
}

/// A vector of rays set up as RayWalk::begin() does, up to the count of their lattice.
struct RaySetUp {
    VF o[3], d[3];           ///< origin and direction, world
    VF ov[3], dv[3], inv[3]; ///< in voxels, and 1 / dv
    VF t0, t1;               ///< where they enter and leave the volume's box
    VF lattice;              ///< t0 + shift step: sample k at lattice + (k + 1/2) step
    VF total;                ///< samples of the lattice in the box (as a float)
};

/// Sets up the rays `rays[0, n)` (n at most a vector) in `r`; returns the lanes that miss the
/// box, have no sample of their lattice in it, or lie past n.
HWY_INLINE hn::Mask<DF> setUpRays(const Frame& f, const PacketRay* rays, std::size_t n,
                                  RaySetUp& r) {
    const DF df;
    constexpr std::size_t kMax = hn::MaxLanes(DF());
    HWY_ALIGN float sx[kMax] = {}, sy[kMax] = {}, shift[kMax] = {};
    for (std::size_t i = 0; i < n; ++i) {
        sx[i] = rays[i].sx;
        sy[i] = rays[i].sy;
        shift[i] = rays[i].shift;
    }
    rayBasis(f, hn::Load(df, sx), hn::Load(df, sy), r.o, r.d);
    auto miss = clipToVolume(f, r.o, r.d, n, r.ov, r.dv, r.inv, r.t0, r.t1);
    r.lattice = hn::Add(r.t0, hn::Mul(hn::Load(df, shift), hn::Set(df, f.stepMm)));
    r.total = hn::Ceil(hn::Sub(hn::Mul(hn::Sub(r.t1, r.lattice), hn::Set(df, 1.0f / f.stepMm)),
                               hn::Set(df, 0.5f)));
    return hn::Or(miss, hn::Not(hn::Gt(r.total, hn::Zero(df))));
}

/// segmentEnds() for rays [0, count) of `rays`, a vector at a time: ok[i] says whether ray i
/// has ends, in[i] and out[i] are them. A crop or clip goes to segmentEnds() ray by ray.
void segmentEndsOf(const Frame& f, const PacketRay* rays, std::size_t count, glm::vec3* in,
                   glm::vec3* out, bool* ok) {
    if (f.clip.any) {
        for (std::size_t i = 0; i < count; ++i)
            ok[i] = segmentEnds(f, rays[i].sx, rays[i].sy, rays[i].shift, in[i], out[i]);
        return;
    }
    const DF df;
    constexpr std::size_t kMax = hn::MaxLanes(DF());
    const std::size_t lanes = hn::Lanes(df);
    for (std::size_t base = 0; base < count; base += lanes) {
        const std::size_t n = std::min(lanes, count - base);
        RaySetUp r;
        const auto miss = setUpRays(f, rays + base, n, r);
        HWY_ALIGN float a[3][kMax], b[3][kMax];
        for (int axis = 0; axis < 3; ++axis) {
            hn::Store(hn::Add(r.ov[axis], hn::Mul(r.dv[axis], r.t0)), df, a[axis]);
            hn::Store(hn::Add(r.ov[axis], hn::Mul(r.dv[axis], r.t1)), df, b[axis]);
        }
        std::uint8_t missBits[(kMax + 7) / 8 + 8] = {};
        hn::StoreMaskBits(df, miss, missBits);
        for (std::size_t i = 0; i < n; ++i) {
            ok[base + i] = ((missBits[i >> 3] >> (i & 7)) & 1) == 0;
            in[base + i] = {a[0][i], a[1][i], a[2][i]};
            out[base + i] = {b[0][i], b[1][i], b[2][i]};
        }
    }
}

/// cutEntriesSimd() for rays [0, count) of `rays`, a vector at a time: the volume's box as
/// RayWalk::begin() finds it, then the crop box's and the planes' kept interval with
/// ClipF::interval()'s operations, tracking which face raises its start, and the lattice's
/// samples kept as clipLattice() counts them.
void cutEntriesOf(const Frame& f, const PacketRay* rays, std::size_t count, CutEntry* entries,
                  bool* cut) {
    const DF df;
    const DI di;
    constexpr std::size_t kMax = hn::MaxLanes(DF());
    const std::size_t lanes = hn::Lanes(df);
    const VF zero = hn::Zero(df), half = hn::Set(df, 0.5f), invStep = hn::Set(df, 1.0f / f.stepMm);
    const ClipF& c = f.clip;
    for (std::size_t base = 0; base < count; base += lanes) {
        const std::size_t n = std::min(lanes, count - base);
        RaySetUp r;
        auto miss = setUpRays(f, rays + base, n, r);
        const VF* o = r.o;
        const VF* d = r.d;
        const VF lattice = r.lattice, t0 = r.t0;
        VF total = r.total;
        // The interval kept and the face raising its start: 2a (+ 1 for the high one) for a
        // crop face on axis a, 6 + i for plane i, -1 for none.
        VF ta = hn::Set(df, -3.0e38f), tb = hn::Set(df, 3.0e38f);
        VI face = hn::Set(di, -1);
        if (c.cropped)
            for (int a = 0; a < 3; ++a) {
                const VF lo = hn::Set(df, c.cropMin[a]), hi = hn::Set(df, c.cropMax[a]);
                const auto still = hn::Eq(d[a], zero);
                miss = hn::Or(miss, hn::And(still, hn::Or(hn::Lt(o[a], lo), hn::Gt(o[a], hi))));
                const VF invD = hn::Div(hn::Set(df, 1.0f), d[a]);
                const VF u0 = hn::Mul(hn::Sub(lo, o[a]), invD),
                         u1 = hn::Mul(hn::Sub(hi, o[a]), invD);
                const auto forward = hn::Lt(u0, u1);
                const VF enter = hn::IfThenElse(forward, u0, u1),
                         leave = hn::IfThenElse(forward, u1, u0);
                const auto raises = hn::AndNot(still, hn::Gt(enter, ta));
                face = hn::IfThenElse(hn::RebindMask(di, raises),
                                      hn::IfThenElse(hn::RebindMask(di, forward),
                                                     hn::Set(di, 2 * a), hn::Set(di, 2 * a + 1)),
                                      face);
                ta = hn::IfThenElse(raises, enter, ta);
                tb = hn::IfThenElse(hn::AndNot(still, hn::Lt(leave, tb)), leave, tb);
            }
        for (int i = 0; i < c.planeCount; ++i) {
            const glm::vec3& nv = c.normals[std::size_t(i)];
            const VF nx = hn::Set(df, nv.x), ny = hn::Set(df, nv.y), nz = hn::Set(df, nv.z);
            const VF nd = hn::Add(hn::Add(hn::Mul(nx, d[0]), hn::Mul(ny, d[1])), hn::Mul(nz, d[2]));
            const VF no =
                hn::Add(hn::Add(hn::Add(hn::Mul(nx, o[0]), hn::Mul(ny, o[1])), hn::Mul(nz, o[2])),
                        hn::Set(df, c.offsets[std::size_t(i)]));
            const auto still = hn::Eq(nd, zero);
            miss = hn::Or(miss, hn::And(still, hn::Lt(no, zero)));
            const VF t = hn::Div(hn::Neg(no), nd);
            const auto raises = hn::And(hn::Gt(nd, zero), hn::Gt(t, ta));
            face = hn::IfThenElse(hn::RebindMask(di, raises), hn::Set(di, 6 + i), face);
            ta = hn::IfThenElse(raises, t, ta);
            tb = hn::IfThenElse(hn::And(hn::Lt(nd, zero), hn::Lt(t, tb)), t, tb);
        }
        // The lattice's samples kept, [first, total) (clipLattice()).
        miss = hn::Or(miss, hn::Not(hn::Le(ta, tb)));
        const VF kb = hn::Ceil(hn::Sub(hn::Mul(hn::Sub(tb, lattice), invStep), half));
        total = hn::IfThenElse(hn::Lt(kb, total), hn::Max(kb, zero), total);
        const VF ka = hn::Ceil(hn::Sub(hn::Mul(hn::Sub(ta, lattice), invStep), half));
        const VF first = hn::IfThenElseZero(hn::Gt(ka, zero), hn::Min(ka, total));
        miss = hn::Or(miss, hn::Not(hn::Lt(first, total)));
        // Through a cut: the start lies past the box's entry (not on its face).
        const auto through = hn::AndNot(miss, hn::Gt(ta, t0));
        HWY_ALIGN float p[3][kMax], dir[3][kMax];
        HWY_ALIGN std::int32_t faces[kMax];
        for (int a = 0; a < 3; ++a) {
            hn::Store(hn::Add(r.ov[a], hn::Mul(r.dv[a], ta)), df, p[a]);
            hn::Store(d[a], df, dir[a]);
        }
        hn::Store(face, di, faces);
        std::uint8_t bits[(kMax + 7) / 8 + 8] = {};
        hn::StoreMaskBits(df, through, bits);
        for (std::size_t i = 0; i < n; ++i) {
            cut[base + i] = ((bits[i >> 3] >> (i & 7)) & 1) != 0;
            if (!cut[base + i]) continue;
            CutEntry& e = entries[base + i];
            e.p = {p[0][i], p[1][i], p[2][i]};
            e.d = {dir[0][i], dir[1][i], dir[2][i]};
            const int k = faces[i];
            if (k >= 6) {
                e.normal = c.normals[std::size_t(k - 6)];
            } else {
                e.normal = glm::vec3(0.0f);
                e.normal[k / 2] = k % 2 == 0 ? 1.0f : -1.0f;
            }
        }
    }
}

} // namespace HWY_NAMESPACE
} // namespace bc::render::detail
HWY_AFTER_NAMESPACE();

#endif // BRICKCAST_RENDER_DETAIL_CPUMARCHBEGIN_INL_H_
