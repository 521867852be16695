// The packet march of the CPU raycaster's SIMD march (render/detail/CpuMarchSimd.cpp,
// marchPacketSimd): lanes that each march a ray of a list of neighbouring pixels, a step
// taking one sample of every lane, and the refills that give a lane out of samples its ray's
// next brick or the next ray of the list.
//
// Per-target code in Highway's -inl.h form: include it only from render/detail/CpuMarchSimd.cpp,
// which foreach_target re-includes once per target (hence the toggle guard below, not
// #pragma once). That file is compiled with -ffp-contract=off (render/CMakeLists.txt) and this
// header's code inherits it only by being included there: a lane's float operations must stay
// the scalar code's, unfused.
#include "render/detail/CpuMarchSimd.h"

#include <algorithm>
#include <cstddef>
#include <cstdint>
#include <cstdlib>

// Per-target include guard: flipped with HWY_TARGET_TOGGLE for each target.
#if defined(BRICKCAST_RENDER_DETAIL_CPUMARCHPACKET_INL_H_) == defined(HWY_TARGET_TOGGLE)
#ifdef BRICKCAST_RENDER_DETAIL_CPUMARCHPACKET_INL_H_
#undef BRICKCAST_RENDER_DETAIL_CPUMARCHPACKET_INL_H_
#else
#define BRICKCAST_RENDER_DETAIL_CPUMARCHPACKET_INL_H_
#endif

#include "render/detail/CpuMarchBegin-inl.h"
#include "render/detail/CpuMarchBrick-inl.h"
#include "render/detail/CpuMarchGathers-inl.h"
#include "render/detail/CpuMarchShading-inl.h"

#include <hwy/highway.h>

HWY_BEFORE_NAMESPACE();
namespace bc::render::detail {
namespace HWY_NAMESPACE {

/// The rays in a packet's lanes, one per lane (structure of arrays): where each is in its
/// brick, which ray it is, its transmittance (its colour sums are its RayState's) and a
/// projection's value and count. A lane without samples to take has k = end.
struct Lanes {
    static constexpr std::size_t kMax = hn::MaxLanes(DF());
    HWY_ALIGN std::int32_t k[kMax], end[kMax];
    HWY_ALIGN std::int32_t base[kMax];   ///< the brick's first voxel, in voxels from the packet's
    HWY_ALIGN std::int32_t words[kMax];  ///< the brick's first octree word in f.occ
    HWY_ALIGN std::int32_t fine[kMax];   ///< the brick's distance map in f.fine (0: none)
    HWY_ALIGN std::int32_t leaves[kMax]; ///< the brick's first leaf in f.leafBound
    HWY_ALIGN float t0[kMax], lx[kMax], ly[kMax], lz[kMax], dx[kMax], dy[kMax], dz[kMax];
    HWY_ALIGN float ix[kMax], iy[kMax], iz[kMax]; ///< 1 / (dx, dy, dz)
    HWY_ALIGN float wx[kMax], wy[kMax], wz[kMax]; ///< the rays' world directions (shading)
    HWY_ALIGN std::int32_t ray[kMax]; ///< the lane's ray: its index in the packet's list
    HWY_ALIGN float t[kMax];
    HWY_ALIGN float v[kMax];        ///< Accum::v
    HWY_ALIGN std::int32_t n[kMax]; ///< Accum::n
};

/// The lanes of a packet for voxels of type T, each a ray of the list `rays` in turn: a lane
/// out of samples takes its ray's next brick, or else the next ray that has one (refill()).
template <class T> class PacketLanes {
  public:
    static constexpr std::size_t kMax = Lanes::kMax;

    PacketLanes(const Frame& f, const PacketRay* rays, std::size_t count, int lanes, RayCount& n)
        : f(f), mRays(rays), mCount(count), mLanes(lanes), mN(n) {}

  protected:
    /// Every lane idle, then the first mLanes given their rays: the packet ready to march.
    void start() {
        for (int j = 0; j < int(kMax); ++j)
            idle(j);
        for (int j = 0; j < mLanes; ++j)
            refill(j);
    }

    /// each(j) for every lane j set in mask `m` of d, in order.
    template <class D, class M, class Each> static void forLanes(D d, M m, const Each& each) {
        std::uint8_t bits[(kMax + 7) / 8 + 8] = {};
        hn::StoreMaskBits(d, m, bits);
        for (std::size_t j = 0; j < kMax; ++j)
            if (((bits[j >> 3] >> (j & 7)) & 1) != 0) each(int(j));
    }

    /// Lane j's ray's start relative to its stored brick's first voxel, its step in voxels, and
    /// its world direction (shading).
    glm::vec3 rel(int j) const {
        return glm::vec3(L.lx[j], L.ly[j], L.lz[j]) + (float(f.apron) - 0.5f);
    }
    glm::vec3 dir(int j) const { return glm::vec3(L.dx[j], L.dy[j], L.dz[j]); }
    glm::vec3 world(int j) const { return glm::vec3(L.wx[j], L.wy[j], L.wz[j]); }

    /// composite() of c into lane j's ray: its sums are its state's, its transmittance the lane's.
    void compositeLane(int j, const Rgba& c) {
        Accum& sums = mRay[j]->state->acc;
        Accum acc{sums.r, sums.g, sums.b, L.t[j]};
        composite(acc, c);
        sums.r = acc.r;
        sums.g = acc.g;
        sums.b = acc.b;
        L.t[j] = acc.t;
    }

    /// After a round of steps: the lanes of `done` (of the first mLanes) refilled, those also in
    /// `stopped` leaving their rays (opaque, or the mode ended them).
    void refillLanes(hn::Mask<DI> done, hn::Mask<DI> stopped) {
        const DI di;
        std::uint8_t doneBits[(kMax + 7) / 8 + 8] = {}, stopBits[(kMax + 7) / 8 + 8] = {};
        hn::StoreMaskBits(di, done, doneBits);
        hn::StoreMaskBits(di, stopped, stopBits);
        for (int j = 0; j < mLanes; ++j) {
            if (((doneBits[j >> 3] >> (j & 7)) & 1) == 0) continue;
            mStopped[j] = ((stopBits[j >> 3] >> (j & 7)) & 1) != 0;
            refill(j);
        }
    }

    /// Lane j without a ray: no samples, nothing to composite.
    void idle(int j) {
        mRay[j] = nullptr;
        L.k[j] = L.end[j] = 0;
        L.base[j] = L.words[j] = L.fine[j] = L.leaves[j] = 0;
        L.t0[j] = L.lx[j] = L.ly[j] = L.lz[j] = L.dx[j] = L.dy[j] = L.dz[j] = 0.0f;
        L.ix[j] = L.iy[j] = L.iz[j] = L.wx[j] = L.wy[j] = L.wz[j] = 0.0f;
        L.ray[j] = 0;
        L.t[j] = 1.0f;
        L.v[j] = 0.0f;
        L.n[j] = 0;
    }

    /// Lane j's ray on to its next sampled brick with samples to take (compositing the
    /// bricks of one value on the way, leaving out those a running skip passes over, narrowing
    /// to the box of sampled leaves); false when the ray has no more in this pass.
    bool seek(int j) {
        RayWalk& w = mWalk[j];
        RayState& s = *mRay[j]->state;
        // The colour sums are the state's (flush() adds the queued samples to them); the
        // transmittance and a projection's value are the lane's.
        Accum acc{s.acc.r, s.acc.g, s.acc.b, L.t[j], L.v[j], std::uint32_t(L.n[j])};
        const bool composite = f.mode == BlendMode::Composite;
        bool found = false;
        while (!found && w.next(f, s, *mRay[j]->resume)) {
            const BrickRef& b = f.bricks[w.index];
            if (f.running && !passes(f, b.bound, acc)) {
                ++mN.leaps;
                continue;
            }
            if (b.slot == Slot::Constant) {
                settle(s, acc); // its queued samples first: each ray's sums in sample order
                if (!(composite ? marchConstant(f, b.constant, w.k, w.kEnd, acc, mN)
                                : marchConstantMode(f, b.constant, w.k, w.kEnd, acc, mN)))
                    break;
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
            place(j, w, b, voxels, offset, first, last);
            found = true;
        }
        s.acc = acc;
        L.t[j] = acc.t;
        L.v[j] = acc.v;
        L.n[j] = std::int32_t(acc.n);
        return found;
    }

    /// Lane j to take samples [first, last) of brick b of its ray's walk w, whose voxels are
    /// `offset` voxels from the packet's first brick.
    void place(int j, const RayWalk& w, const BrickRef& b, const T* voxels, std::int64_t offset,
               int first, int last) {
        const glm::vec3 local = w.local(f);
        mLaneVoxels[j] = voxels;
        L.k[j] = first;
        L.end[j] = last;
        L.base[j] = std::int32_t(offset);
        L.words[j] = w.index * f.occWords;
        L.fine[j] = std::int32_t(b.fine);
        L.leaves[j] = w.index * f.leafCount;
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
        const auto* cells = map ? reinterpret_cast<const std::uint8_t*>(f.fine + map) : nullptr;
        if (f.mode != BlendMode::Composite)
            return marchBrickMode(f, voxels, words, cells, w.local(f), w.dv, w.d, w.t0, w.first, k,
                                  kEnd, acc, mN);
        return marchBrick(f, voxels, words, cells, w.local(f), w.dv, w.d, w.t0, k, kEnd, acc, mN);
    }

    /// Lane j, whose ray has no samples left to take (or that has no ray): its ray's next
    /// brick, or else the next ray of the queue that has one (finishing the rays it leaves).
    void refill(int j) {
        if (mRay[j] && !mStopped[j] && seek(j)) return;
        if (mRay[j]) { // its sums are the state's already
            Accum& acc = mRay[j]->state->acc;
            acc.t = L.t[j];
            acc.v = L.v[j];
            acc.n = std::uint32_t(L.n[j]);
        }
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
            L.v[j] = ray.state->acc.v;
            L.n[j] = std::int32_t(ray.state->acc.n);
            if (seek(j)) return;
            // seek() left the state's acc whole
        }
        idle(j);
    }

    /// The lanes' rays as vectors, for a round of steps.
    HWY_INLINE LaneRays loadRays() const {
        const DF df;
        const DI di;
        const VF apron = hn::Set(df, float(f.apron) - 0.5f);
        LaneRays r;
        r.t0 = hn::Load(df, L.t0);
        r.lx = hn::Load(df, L.lx);
        r.ly = hn::Load(df, L.ly);
        r.lz = hn::Load(df, L.lz);
        r.dx = hn::Load(df, L.dx);
        r.dy = hn::Load(df, L.dy);
        r.dz = hn::Load(df, L.dz);
        r.ix = hn::Load(df, L.ix);
        r.iy = hn::Load(df, L.iy);
        r.iz = hn::Load(df, L.iz);
        r.rx = hn::Add(r.lx, apron);
        r.ry = hn::Add(r.ly, apron);
        r.rz = hn::Add(r.lz, apron);
        r.wx = hn::Load(df, L.wx);
        r.wy = hn::Load(df, L.wy);
        r.wz = hn::Load(df, L.wz);
        r.base = hn::Load(di, L.base);
        r.wordBase = hn::Load(di, L.words);
        r.fineBase = hn::Load(di, L.fine);
        r.leafBase = hn::Load(di, L.leaves);
        return r;
    }

    /// How many lanes out of samples call for refills: those out of rays for good, and a
    /// quarter of the others (at least one).
    std::size_t refillThreshold() const {
        std::size_t gone = 0;
        for (int j = 0; j < mLanes; ++j)
            gone += mRay[j] ? 0 : 1;
        return gone + std::max<std::size_t>(1, (mLanes - gone) / 4);
    }

    /// The queued samples' colours added to their rays' sums (ColourQueue::flush()).
    void flush(bool all) { mQueue.flush(f, mVoxels, mRays, all); }

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
    ColourQueue<T> mQueue;
};

/// The march of marchPacketSimd() for voxels of type T: its lanes (PacketLanes), and the step
/// that takes one sample of every lane.
template <class T> class Packet : PacketLanes<T> {
  public:
    using PacketLanes<T>::PacketLanes;

    void run() {
        start();
        march();
    }

  private:
    using Base = PacketLanes<T>;
    using Base::f, Base::mLanes, Base::mN, Base::L, Base::mRay, Base::mStopped;
    using Base::flush, Base::kMax, Base::start, Base::loadRays, Base::refillThreshold;
    using Base::forLanes, Base::rel, Base::dir, Base::world, Base::compositeLane, Base::refillLanes;
    using Base::mRays, Base::mVoxels, Base::mLaneVoxels, Base::mQueue;
    using MI = hn::Mask<DI>;

    /// The lanes in a round of steps: their samples [k, end), their rays' transmittance,
    /// whether their rays stopped (opaque), and which lanes still have samples to take.
    struct Progress {
        VI k, end;
        VF tr;
        MI stopped, active;
    };

    /// Steps until every lane is out of samples and the queue out of rays: each step takes one
    /// sample of every lane in a sampled leaf and leaps the lanes in empty ones over the
    /// coarsest empty node that holds their sample (the scalar walk's emptyLevel() and
    /// sampleAfterNode(), to within an ulp at the node's exit, render/OCCUPANCY.md). Samples
    /// are taken as Sample<T> takes them (lanes outside the fused range by it) and composited
    /// lane by lane with the scalar composite(), so each ray's colour is the scalar march's.
    /// Lanes out of samples get their next brick or ray once a quarter of the lanes still
    /// with rays are.
    void march() {
        for (;;) {
            const LaneRays r = loadRays();
            Progress p = loadProgress();
            if (hn::AllFalse(DI(), p.active)) return flush(true);
            const std::size_t refillAt = refillThreshold();
            // Unshaded, a sample's colour is two gathers a channel, as cheap in the step as in
            // the queue: the step composites it at once into the lanes' sums (R, G, B), which
            // go back to the rays' states before anything else composites into them.
            const bool direct = !f.shading;
            VF R = hn::Zero(DF()), G = hn::Zero(DF()), B = hn::Zero(DF());
            if (direct) loadSums(R, G, B);
            while (hn::CountTrue(DI(), hn::Not(p.active)) < refillAt)
                step(r, p, direct, R, G, B);
            // A quarter of the lanes (or all) are out of samples: their next bricks or rays.
            // The queued samples stay queued: they name their rays, not lanes.
            if (direct) storeSums(R, G, B);
            refillDone(p);
        }
    }

    /// The lanes' progress as vectors, no ray stopped yet, for a round of steps.
    HWY_INLINE Progress loadProgress() const {
        const DI di;
        Progress p;
        p.k = hn::Load(di, L.k);
        p.end = hn::Load(di, L.end);
        p.tr = hn::Load(DF(), L.t);
        p.stopped = hn::FirstN(di, 0);
        p.active = hn::Lt(p.k, p.end);
        return p;
    }

    /// One step of the active lanes: those whose sample lies in empty space leap over it (the
    /// coarsest empty node or distance-map cube that holds it), the others take their sample.
    HWY_INLINE void step(const LaneRays& r, Progress& p, bool direct, VF& R, VF& G, VF& B) {
        const DF df;
        const DI di;
        const VF t = hn::Add(r.t0, hn::Mul(hn::Add(hn::ConvertTo(df, p.k), hn::Set(df, 0.5f)),
                                           hn::Set(df, f.stepMm)));
        MI take = p.active;
        if (f.occ) {
            const SampleCells c = sampleCells(f, r, t);
            const MI empty = hn::AndNot(c.sampled, p.active);
            if (!hn::AllFalse(di, empty)) {
                p.k = leapEmpty(f, r, c, empty, p.k, p.end);
                mN.leaps += hn::CountTrue(di, empty);
                take = hn::And(p.active, c.sampled);
                if (hn::AllFalse(di, take)) {
                    p.active = hn::AndNot(p.stopped, hn::Lt(p.k, p.end));
                    return;
                }
            }
        }
        takeSamples(r, t, take, p, direct, R, G, B);
        p.active = hn::AndNot(p.stopped, hn::Lt(p.k, p.end));
    }

    /// The samples at t of the lanes `take`, as Sample<T> takes them (lanes outside the fused
    /// range by it, scalarLanes()), composited.
    HWY_INLINE void takeSamples(const LaneRays& r, VF t, MI take, Progress& p, bool direct, VF& R,
                                VF& G, VF& B) {
        const DF df;
        const DI di;
        const SamplesV<T> samples(f, mVoxels, hn::Add(r.rx, hn::Mul(r.dx, t)),
                                  hn::Add(r.ry, hn::Mul(r.dy, t)), hn::Add(r.rz, hn::Mul(r.dz, t)),
                                  r.base, false);
        const auto takeF = hn::RebindMask(df, take);
        const auto odd = hn::AndNot(samples.fused, takeF); // for the scalar code
        if (!hn::AllFalse(df, odd)) {
            if (direct) storeSums(R, G, B);
            p.tr = scalarLanes(odd, t, p.tr);
            if (direct) loadSums(R, G, B);
            p.stopped = hn::Or(p.stopped,
                               hn::RebindMask(di, hn::And(odd, hn::Le(p.tr, hn::Set(df, f.ertT)))));
        }
        mN.samples += hn::CountTrue(di, take);
        p.k = hn::IfThenElse(take, hn::Add(p.k, hn::Set(di, 1)), p.k);
        compositeLanes(samples, r, hn::And(takeF, samples.fused), p, direct, R, G, B);
    }

    /// composite() for the lanes `taken` whose samples are visible: their transmittance now,
    /// their colour sums at once (direct: R, G, B) or once the queue has the colours.
    HWY_INLINE void compositeLanes(const SamplesV<T>& s, const LaneRays& r, hn::Mask<DF> taken,
                                   Progress& p, bool direct, VF& R, VF& G, VF& B) {
        const DF df;
        const DI di;
        const VF a = s.a;
        const auto vis = hn::And(taken, hn::Gt(a, hn::Zero(df)));
        if (hn::AllFalse(df, vis)) return;
        const VF w = hn::Mul(p.tr, a);
        if (direct) { // composite()'s sums: acc.r += w * c.r, lane by lane
            R = hn::IfThenElse(vis, hn::Add(R, hn::Mul(w, s.channel(0))), R);
            G = hn::IfThenElse(vis, hn::Add(G, hn::Mul(w, s.channel(1))), G);
            B = hn::IfThenElse(vis, hn::Add(B, hn::Mul(w, s.channel(2))), B);
        } else {
            defer(s, vis, w, r.wx, r.wy, r.wz);
        }
        p.tr = hn::IfThenElse(vis, hn::Mul(p.tr, hn::Sub(hn::Set(df, 1.0f), a)), p.tr);
        p.stopped =
            hn::Or(p.stopped, hn::RebindMask(di, hn::And(vis, hn::Le(p.tr, hn::Set(df, f.ertT)))));
    }

    /// The lanes' progress back to L, and the lanes out of samples refilled.
    HWY_INLINE void refillDone(const Progress& p) {
        const DI di;
        hn::Store(p.tr, DF(), L.t);
        hn::Store(p.k, di, L.k);
        refillLanes(hn::Not(p.active), p.stopped);
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
        forLanes(df, odd, [&](int j) {
            const Rgba c =
                colourOf(f, Sample<T>(mLaneVoxels[j], f.edge, rel(j) + dir(j) * ts[j]), world(j));
            if (!(c.a <= 0.0f)) compositeLane(j, c); // as composite() would, NaN too
        });
        return hn::Load(df, L.t);
    }

    /// Queues the visible lanes' samples for their colour, with their compositing weights
    /// w = t a (ColourQueue), a vector's colours taken once a vector is queued.
    void defer(const SamplesV<T>& s, hn::Mask<DF> vis, VF w, VF wx, VF wy, VF wz) {
        mQueue.push(s, vis, hn::Load(DI(), L.ray), w, wx, wy, wz);
        if (mQueue.count >= std::size_t(mLanes)) flush(false);
    }
};

} // namespace HWY_NAMESPACE
} // namespace bc::render::detail
HWY_AFTER_NAMESPACE();

#endif // BRICKCAST_RENDER_DETAIL_CPUMARCHPACKET_INL_H_
