// The packet march of the modes other than composite (render/MODES.md) in the CPU raycaster's
// SIMD march (render/detail/CpuMarchSimd.cpp, marchPacketSimd): the lanes and refills of
// CpuMarchPacket-inl.h, a step that takes each lane's sample value alone (no classification,
// no colour), and what each mode keeps of it: the largest, the smallest or the sum of the
// values, or the first at or above the iso value. A maximum or minimum also leaps over the
// octree leaves whose values cannot pass the ray's value so far (Frame::running).
//
// The image of the scalar march (marchBrickMode), bit for bit: a lane's value is fetch()'s
// float (the fused lanes' lerps in its order, the others by fetch() itself), taken in its ray's
// order; the isosurface's hit is refined and shaded by the scalar code.
//
// Per-target code in Highway's -inl.h form: include it only from render/detail/CpuMarchSimd.cpp,
// which foreach_target re-includes once per target (hence the toggle guard below, not
// #pragma once). That file is compiled with -ffp-contract=off (render/CMakeLists.txt) and this
// header's code inherits it only by being included there.
#include "render/detail/CpuMarchSimd.h"

#include <cstddef>
#include <cstdint>

// Per-target include guard: flipped with HWY_TARGET_TOGGLE for each target.
#if defined(BRICKCAST_RENDER_DETAIL_CPUMARCHMODES_INL_H_) == defined(HWY_TARGET_TOGGLE)
#ifdef BRICKCAST_RENDER_DETAIL_CPUMARCHMODES_INL_H_
#undef BRICKCAST_RENDER_DETAIL_CPUMARCHMODES_INL_H_
#else
#define BRICKCAST_RENDER_DETAIL_CPUMARCHMODES_INL_H_
#endif

#include "render/detail/CpuMarchPacket-inl.h"

#include <hwy/highway.h>

HWY_BEFORE_NAMESPACE();
namespace bc::render::detail {
namespace HWY_NAMESPACE {

/// marchPacketSimd() for the modes other than composite, voxels of type T.
template <class T> class ModePacket : PacketLanes<T> {
  public:
    using PacketLanes<T>::PacketLanes;

    void run() {
        start();
        march();
    }

  private:
    using Base = PacketLanes<T>;
    using Base::f, Base::mN, Base::L, Base::mWalk, Base::mVoxels, Base::mLaneVoxels;
    using Base::forLanes, Base::rel, Base::dir, Base::world, Base::compositeLane, Base::refillLanes;
    using Base::kMax, Base::start, Base::loadRays, Base::refillThreshold;
    using MI = hn::Mask<DI>;

    /// The lanes in a round of steps: their samples [k, end), their rays' value and count
    /// (Accum::v, Accum::n), whether their rays stopped, which lanes still have samples.
    struct Progress {
        VI k, end;
        VF v;
        VI n;
        MI stopped, active;
    };

    /// Steps until every lane is out of samples and the list out of rays (Packet::march()).
    void march() {
        for (;;) {
            const LaneRays r = loadRays();
            const DI di;
            Progress p{hn::Load(di, L.k), hn::Load(di, L.end), hn::Load(DF(), L.v),
                       hn::Load(di, L.n), hn::FirstN(di, 0),   hn::FirstN(di, 0)};
            p.active = hn::Lt(p.k, p.end);
            if (hn::AllFalse(di, p.active)) return;
            const std::size_t refillAt = refillThreshold();
            while (hn::CountTrue(di, hn::Not(p.active)) < refillAt)
                step(r, p);
            refillDone(p);
        }
    }

    /// One step of the active lanes: those in empty space, or under a running skip in a leaf
    /// that cannot pass their value, leap; the others take their sample.
    HWY_INLINE void step(const LaneRays& r, Progress& p) {
        const DF df;
        const DI di;
        const VF t = hn::Add(r.t0, hn::Mul(hn::Add(hn::ConvertTo(df, p.k), hn::Set(df, 0.5f)),
                                           hn::Set(df, f.stepMm)));
        MI take = p.active;
        VI ax, ay, az; // the samples' leaves, once known
        bool located = false;
        if (f.occ) {
            const SampleCells c = sampleCells(f, r, t);
            const MI empty = hn::AndNot(c.sampled, p.active);
            if (!hn::AllFalse(di, empty)) {
                p.k = leapEmpty(f, r, c, empty, p.k, p.end);
                mN.leaps += hn::CountTrue(di, empty);
                take = hn::And(p.active, c.sampled);
            }
            ax = c.ax;
            ay = c.ay;
            az = c.az;
            located = true;
        }
        if (f.leafBound && !hn::AllFalse(di, take)) {
            if (!located) {
                ax = leafOf(f, r.lx, r.dx, t);
                ay = leafOf(f, r.ly, r.dy, t);
                az = leafOf(f, r.lz, r.dz, t);
            }
            const MI stale = staleLeaves(r, ax, ay, az, take, p);
            if (!hn::AllFalse(di, stale)) {
                const VF exit = exitOfCube(r, ax, ay, az, hn::Set(df, f.leaf));
                p.k = hn::IfThenElse(stale, sampleAfterExit(f, r, exit, p.k, p.end), p.k);
                mN.leaps += hn::CountTrue(di, stale);
                take = hn::AndNot(stale, take);
            }
        }
        if (!hn::AllFalse(di, take)) takeValues(r, t, take, p);
        p.active = hn::AndNot(p.stopped, hn::Lt(p.k, p.end));
    }

    /// Lanes of `take` with a value whose sample's leaf (ax, ay, az) cannot pass it: its bound
    /// (f.leafBound) at or below a maximum, at or above a minimum (passes()).
    HWY_INLINE MI staleLeaves(const LaneRays& r, VI ax, VI ay, VI az, MI take,
                              const Progress& p) const {
        const DF df;
        const DI di;
        const VI axis = hn::Set(di, f.leafAxis);
        const VI leaf =
            hn::Add(r.leafBase, hn::Add(hn::Mul(hn::Add(hn::Mul(az, axis), ay), axis), ax));
        const VF bound = hn::GatherIndex(df, f.leafBound, leaf);
        const auto held = f.mode == BlendMode::Maximum ? hn::Le(bound, p.v) : hn::Ge(bound, p.v);
        return hn::And(hn::And(take, hn::Gt(p.n, hn::Zero(di))), hn::RebindMask(di, held));
    }

    /// The values at t of the lanes `take` (the lanes outside the fused range by fetch()), each
    /// kept by the mode.
    HWY_INLINE void takeValues(const LaneRays& r, VF t, MI take, Progress& p) {
        const DF df;
        const DI di;
        const SamplesV<T> s(f, mVoxels, hn::Add(r.rx, hn::Mul(r.dx, t)),
                            hn::Add(r.ry, hn::Mul(r.dy, t)), hn::Add(r.rz, hn::Mul(r.dz, t)),
                            r.base, typename SamplesV<T>::ValueOnly{});
        const auto takeF = hn::RebindMask(df, take);
        VF value = s.value;
        const auto odd = hn::AndNot(s.fused, takeF);
        if (!hn::AllFalse(df, odd)) value = scalarValues(odd, t, value);
        mN.samples += hn::CountTrue(di, take);
        const VI k = p.k;
        p.k = hn::IfThenElse(take, hn::Add(p.k, hn::Set(di, 1)), p.k);
        if (f.mode == BlendMode::Isosurface)
            return isoLanes(hn::And(takeF, hn::Ge(value, hn::Set(df, f.iso))), k, t, p);
        const auto first = hn::RebindMask(df, hn::Eq(p.n, hn::Zero(di)));
        p.n = hn::IfThenElse(take, hn::Add(p.n, hn::Set(di, 1)), p.n);
        if (f.mode == BlendMode::Average) {
            p.v = hn::IfThenElse(takeF, hn::Add(p.v, value), p.v);
            return;
        }
        const bool max = f.mode == BlendMode::Maximum;
        const auto raise =
            hn::And(takeF, hn::Or(first, max ? hn::Gt(value, p.v) : hn::Lt(value, p.v)));
        p.v = hn::IfThenElse(raise, value, p.v);
        mN.raises += hn::CountTrue(df, raise);
        if (f.ertT < 0.0f) return;
        // project()'s early termination: the value at or past the table's end on its side.
        const VF u = hn::Add(hn::Mul(p.v, hn::Set(df, f.tfScale)), hn::Set(df, f.tfOffset));
        const auto done =
            max ? hn::Ge(u, hn::Set(df, float(f.entries - 1))) : hn::Le(u, hn::Zero(df));
        p.stopped = hn::Or(p.stopped, hn::RebindMask(di, hn::And(takeF, done)));
    }

    /// The values of the lanes `odd` (outside the fused range) by fetch(), the others' as
    /// they are in `value`.
    VF scalarValues(hn::Mask<DF> odd, VF t, VF value) const {
        const DF df;
        HWY_ALIGN float ts[kMax], vs[kMax];
        hn::Store(t, df, ts);
        hn::Store(value, df, vs);
        forLanes(df, odd, [&](int j) {
            vs[j] = detail::fetch(mLaneVoxels[j], f.edge, rel(j) + dir(j) * ts[j]);
        });
        return hn::Load(df, vs);
    }

    /// The lanes `hit` (samples k at t at or above the iso value): each ray's surface refined
    /// and shaded by the scalar code (isoHit(), isoColour()), composited, and the ray stopped.
    void isoLanes(hn::Mask<DF> hit, VI k, VF t, Progress& p) {
        const DF df;
        const DI di;
        if (hn::AllFalse(df, hit)) return;
        HWY_ALIGN float ts[kMax];
        HWY_ALIGN std::int32_t ks[kMax];
        hn::Store(t, df, ts);
        hn::Store(k, di, ks);
        forLanes(df, hit, [&](int j) {
            const T* v = mLaneVoxels[j];
            const glm::vec3 from = rel(j), dv = dir(j);
            const float at = isoHit(f, L.t0[j], mWalk[j].first, ks[j], ts[j], [&](float u) {
                return detail::fetch(v, f.edge, from + dv * u);
            });
            compositeLane(j, isoColour(f, Sample<T>(v, f.edge, from + dv * at).diffs(), world(j)));
        });
        p.stopped = hn::Or(p.stopped, hn::RebindMask(di, hit));
    }

    /// The lanes' progress back to L, and the lanes out of samples refilled.
    HWY_INLINE void refillDone(const Progress& p) {
        const DI di;
        hn::Store(p.k, di, L.k);
        hn::Store(p.v, DF(), L.v);
        hn::Store(p.n, di, L.n);
        refillLanes(hn::Not(p.active), p.stopped);
    }
};

} // namespace HWY_NAMESPACE
} // namespace bc::render::detail
HWY_AFTER_NAMESPACE();

#endif // BRICKCAST_RENDER_DETAIL_CPUMARCHMODES_INL_H_
