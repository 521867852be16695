// Shading of the CPU raycaster's SIMD march (render/detail/CpuMarchSimd.cpp): a vector of
// samples classified by the transfer function, lit (gradient, shade()), and the queue of a
// packet's visible samples whose colours are composited into their rays' sums a vector at a
// time.
//
// Per-target code in Highway's -inl.h form: include it only from render/detail/CpuMarchSimd.cpp,
// which foreach_target re-includes once per target (hence the toggle guard below, not
// #pragma once). That file is compiled with -ffp-contract=off (render/CMakeLists.txt) and this
// header's code inherits it only by being included there: a lane's float operations must stay
// the scalar code's, unfused.
#include "render/detail/CpuMarchSimd.h"

#include <algorithm>
#include <bit>
#include <cstddef>
#include <cstdint>

// Per-target include guard: flipped with HWY_TARGET_TOGGLE for each target.
#if defined(BRICKCAST_RENDER_DETAIL_CPUMARCHSHADING_INL_H_) == defined(HWY_TARGET_TOGGLE)
#ifdef BRICKCAST_RENDER_DETAIL_CPUMARCHSHADING_INL_H_
#undef BRICKCAST_RENDER_DETAIL_CPUMARCHSHADING_INL_H_
#else
#define BRICKCAST_RENDER_DETAIL_CPUMARCHSHADING_INL_H_
#endif

#include "render/detail/CpuMarchGathers-inl.h"

#include <hwy/highway.h>

HWY_BEFORE_NAMESPACE();
namespace bc::render::detail {
namespace HWY_NAMESPACE {

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

/// powShininess() of CpuRay.h per lane: x^24 by squaring.
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
    VF value; ///< the trilinear value per lane (detail::fetch's, in the fused lanes)
    VF a;     ///< classify()'s alpha per lane

    /// `base`: per lane, where its brick's voxels start, in voxels from `voxels` (0 when
    /// every lane samples the brick at `voxels`).
    /// `quads`: read the cell rows' x neighbours too (what the gradient needs) where one
    /// gather reads them with the rows.
    SamplesV(const Frame& frame, const T* voxels, VF qx, VF qy, VF qz, VI base, bool quads)
        : f(frame), v(voxels) {
        locate(qx, qy, qz, base);
        cellRows(v, o, sy, sz, quads && sizeof(T) <= 2, c);
        interpolate();
        classifyValue(value);
    }
    /// The values alone (the projections'): no classification, so no colour nor alpha.
    struct ValueOnly {};
    SamplesV(const Frame& frame, const T* voxels, VF qx, VF qy, VF qz, VI base, ValueOnly)
        : f(frame), v(voxels) {
        locate(qx, qy, qz, base);
        cellRows(v, o, sy, sz, false, c);
        interpolate();
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

  private:
    /// The fused lanes, and each lane's cell (o: its first voxel) with its weights (fx, fy, fz).
    HWY_INLINE void locate(VF qx, VF qy, VF qz, VI base) {
        const DF df;
        const DI di;
        const VF one = hn::Set(df, 1.0f), hi = hn::Set(df, float(f.edge - 2));
        fused = hn::And(hn::And(hn::And(hn::Ge(qx, one), hn::Lt(qx, hi)),
                                hn::And(hn::Ge(qy, one), hn::Lt(qy, hi))),
                        hn::And(hn::Ge(qz, one), hn::Lt(qz, hi)));
        allFused = hn::AllTrue(df, fused);
        // Addresses from positions clamped into the fused range, which leaves a fused lane's
        // own (Max first: it returns 1 for a NaN position).
        // The float below edge - 2 (std::nextafter towards 0, without its call each step: the
        // edge is positive, so one bit pattern less).
        const VF top =
            hn::Set(df, std::bit_cast<float>(std::bit_cast<std::uint32_t>(float(f.edge - 2)) - 1u));
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
    }
    /// The trilinear value of the cell rows, in fetch()'s order.
    HWY_INLINE void interpolate() {
        value = lerpV(lerpV(lerpV(c.r00.lo, c.r00.hi, fx), lerpV(c.r10.lo, c.r10.hi, fx), fy),
                      lerpV(lerpV(c.r01.lo, c.r01.hi, fx), lerpV(c.r11.lo, c.r11.hi, fx), fy), fz);
    }
    /// classify() per lane of the trilinear values: the entry (e), its weight (w), the alpha.
    HWY_INLINE void classifyValue(VF value) {
        const DF df;
        const DI di;
        const VF u = hn::Min(
            hn::Max(hn::Add(hn::Mul(value, hn::Set(df, f.tfScale)), hn::Set(df, f.tfOffset)),
                    hn::Zero(df)),
            hn::Set(df, float(f.entries - 1)));
        const VI entry = hn::Min(hn::ConvertTo(di, u), hn::Set(di, f.entries - 2));
        w = hn::Sub(u, hn::ConvertTo(df, entry));
        e = hn::ShiftLeft<2>(entry);
        a = channel(3);
    }
};

/// The lanes of v under m, packed, stored at p: a whole vector is written (the lanes past the
/// packed ones are garbage). Compress into a register, then a plain store: AVX-512's
/// compress-to-memory form is microcoded on AMD Zen 4 at about a hundred cycles a store, and
/// Highway 1.0 has no Zen 4 target that avoids it (CompressStore would emit it).
template <class D, class V, class M>
HWY_INLINE void appendTo(V v, M m, D d, hn::TFromD<D>* HWY_RESTRICT p) {
    hn::StoreU(hn::Compress(v, m), d, p);
}

/// A packet's visible samples waiting for their colour (classify()'s colour, shaded), with
/// their compositing weights w = t a: a ray's colour sums add w * colour in the order its
/// samples were taken, as composite() does, when flush() has the colours. A queued sample
/// names its ray, not its lane. Up to a vector's lanes less one wait, and a vector's more
/// while one is pushed (appendTo() writes whole vectors).
template <class T> struct ColourQueue {
    static constexpr std::size_t kMax = hn::MaxLanes(DF());
    static constexpr std::size_t kSize = 2 * kMax + 8;
    HWY_ALIGN std::int32_t o[kSize], e[kSize], ray[kSize]; ///< ray: its index in the list
    HWY_ALIGN float fx[kSize], fy[kSize], fz[kSize], tw[kSize], w[kSize];
    HWY_ALIGN float dx[kSize], dy[kSize], dz[kSize];
    std::size_t count = 0;

    /// Queues the samples of the lanes `vis` of s: `rayIndex` their rays (in the packet's
    /// list), `weight` their weights, (wx, wy, wz) their rays' world directions (shading).
    void push(const SamplesV<T>& s, hn::Mask<DF> vis, VI rayIndex, VF weight, VF wx, VF wy, VF wz) {
        const DF df;
        const DI di;
        const auto visI = hn::RebindMask(di, vis);
        const std::size_t at = count;
        appendTo(s.o, visI, di, o + at);
        appendTo(s.e, visI, di, e + at);
        appendTo(rayIndex, visI, di, ray + at);
        appendTo(s.fx, vis, df, fx + at);
        appendTo(s.fy, vis, df, fy + at);
        appendTo(s.fz, vis, df, fz + at);
        appendTo(s.w, vis, df, tw + at);
        appendTo(weight, vis, df, w + at);
        appendTo(wx, vis, df, dx + at);
        appendTo(wy, vis, df, dy + at);
        appendTo(wz, vis, df, dz + at);
        count += hn::CountTrue(df, vis);
    }

    /// The colours of the queued samples, a vector at a time, added to the sums of their rays
    /// (`rays`: the packet's list) in queue order; `voxels`: the brick the samples' offsets
    /// start from. `all`: down to the last (else whole vectors only).
    void flush(const Frame& f, const T* voxels, const PacketRay* rays, bool all) {
        const std::size_t lanes = hn::Lanes(DF());
        std::size_t done = 0;
        while (count - done >= lanes || (all && done < count)) {
            const std::size_t n = std::min(lanes, count - done);
            addColours(f, voxels, rays, done, n);
            done += n;
        }
        if (done == 0) return;
        dropFront(done);
    }

  private:
    /// Queued samples [from, from + n), n <= Lanes(DF()): their colours, added to their rays'
    /// sums in queue order.
    HWY_INLINE void addColours(const Frame& f, const T* voxels, const PacketRay* rays,
                               std::size_t from, std::size_t n) const {
        const DF df;
        const DI di;
        const auto valid = hn::FirstN(di, n);
        const auto validF = hn::RebindMask(df, valid);
        // Lanes past the queue read a cell inside the packet's first brick.
        const VI cell = hn::IfThenElse(valid, hn::LoadU(di, o + from),
                                       hn::Set(di, 1 + f.edge + f.edge * f.edge));
        const VI entry = hn::IfThenElseZero(valid, hn::LoadU(di, e + from));
        const VF mix = hn::IfThenElseZero(validF, hn::LoadU(df, tw + from));
        auto channel = [&](int ch) { return tfChannel(f, entry, mix, ch); };
        VF r = channel(0), g = channel(1), b = channel(2);
        if (f.shading) shade(f, voxels, cell, from, r, g, b);
        const VF weight = hn::LoadU(df, w + from);
        HWY_ALIGN float wr[kMax], wg[kMax], wb[kMax];
        hn::Store(hn::Mul(weight, r), df, wr);
        hn::Store(hn::Mul(weight, g), df, wg);
        hn::Store(hn::Mul(weight, b), df, wb);
        for (std::size_t i = 0; i < n; ++i) {
            Accum& sums = rays[ray[from + i]].state->acc;
            sums.r += wr[i];
            sums.g += wg[i];
            sums.b += wb[i];
        }
    }
    /// Colours (r, g, b) of queued samples from `from` on, in cells `cell`, shaded.
    HWY_INLINE void shade(const Frame& f, const T* voxels, VI cell, std::size_t from, VF& r, VF& g,
                          VF& b) const {
        const DF df;
        const DI di;
        const VF cx = hn::LoadU(df, fx + from), cy = hn::LoadU(df, fy + from),
                 cz = hn::LoadU(df, fz + from);
        const VI sy = hn::Set(di, f.edge), sz = hn::Set(di, f.edge * f.edge);
        CellRows c;
        cellRows(voxels, cell, sy, sz, true, c);
        VF gx, gy, gz;
        gradientOf(voxels, cell, sy, sz, c, cx, cy, cz, gx, gy, gz);
        shadeV(f, hn::LoadU(df, dx + from), hn::LoadU(df, dy + from), hn::LoadU(df, dz + from), gx,
               gy, gz, r, g, b);
    }
    /// The first n queued samples dropped, the rest moved to the front.
    void dropFront(std::size_t n) {
        count -= n;
        for (std::size_t i = 0; i < count; ++i) {
            o[i] = o[n + i];
            e[i] = e[n + i];
            ray[i] = ray[n + i];
            fx[i] = fx[n + i];
            fy[i] = fy[n + i];
            fz[i] = fz[n + i];
            tw[i] = tw[n + i];
            w[i] = w[n + i];
            dx[i] = dx[n + i];
            dy[i] = dy[n + i];
            dz[i] = dz[n + i];
        }
    }
};

} // namespace HWY_NAMESPACE
} // namespace bc::render::detail
HWY_AFTER_NAMESPACE();

#endif // BRICKCAST_RENDER_DETAIL_CPUMARCHSHADING_INL_H_
