// The brick march of the CPU raycaster's SIMD march (render/detail/CpuMarchSimd.cpp): one ray
// through one brick a vector of its samples at a time (marchBrickSimd), and the empty space a
// packet's lanes skip in their bricks, each lane at its own sample (leaf tests, octree and
// distance-map leaps).
//
// Per-target code in Highway's -inl.h form: include it only from render/detail/CpuMarchSimd.cpp,
// which foreach_target re-includes once per target (hence the toggle guard below, not
// #pragma once), and which alone defines its non-inline functions. That file is compiled with
// -ffp-contract=off (render/CMakeLists.txt) and this header's code inherits it only by being
// included there: a lane's float operations must stay the scalar code's, unfused.
#include "render/detail/CpuMarchSimd.h"

#include <algorithm>
#include <bit>
#include <cmath>
#include <cstdint>

// Per-target include guard: flipped with HWY_TARGET_TOGGLE for each target.
#if defined(BRICKCAST_RENDER_DETAIL_CPUMARCHBRICK_INL_H_) == defined(HWY_TARGET_TOGGLE)
#ifdef BRICKCAST_RENDER_DETAIL_CPUMARCHBRICK_INL_H_
#undef BRICKCAST_RENDER_DETAIL_CPUMARCHBRICK_INL_H_
#else
#define BRICKCAST_RENDER_DETAIL_CPUMARCHBRICK_INL_H_
#endif

#include "render/detail/CpuMarchGathers-inl.h"
#include "render/detail/CpuMarchShading-inl.h"

#include <hwy/highway.h>

HWY_BEFORE_NAMESPACE();
namespace bc::render::detail {
namespace HWY_NAMESPACE {

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

/// The rays of a packet's lanes in their bricks, as vectors (loaded for a round of steps).
struct LaneRays {
    VF t0;
    VF lx, ly, lz;         ///< the ray's start in the brick (RayWalk::local())
    VF dx, dy, dz;         ///< its step in voxels per unit t
    VF ix, iy, iz;         ///< 1 / (dx, dy, dz)
    VF rx, ry, rz;         ///< (lx, ly, lz) relative to the stored brick's first voxel
    VF wx, wy, wz;         ///< the ray's world direction (shading)
    VI base;               ///< the brick's first voxel, in voxels from the packet's
    VI wordBase, fineBase; ///< the brick's first octree word in f.occ, its map in f.fine (0: none)
    VI leafBase;           ///< the brick's first leaf in f.leafBound (a running skip)
};

/// Where each lane's sample at t lies: its leaf (ax, ay, az) and whether that is sampled; for a
/// lane whose brick has a distance map (mapped), the map's cell (cx, cy, cz) and the distance d
/// there instead (sampled where d is 0).
struct SampleCells {
    hn::Mask<DI> sampled, mapped;
    VI ax, ay, az;
    VI cx, cy, cz, d;
};

/// The octree leaf test of the lanes' samples at t (f.occ set); with distance maps (f.fine), a
/// lane whose brick has one tests its map's cell instead, the others walk the octree.
HWY_INLINE SampleCells sampleCells(const Frame& f, const LaneRays& r, VF t) {
    const DI di;
    const VI ax = leafOf(f, r.lx, r.dx, t), ay = leafOf(f, r.ly, r.dy, t),
             az = leafOf(f, r.lz, r.dz, t);
    const hn::Mask<DI> leaf = nodeSampled(f, f.occ, r.wordBase, ax, ay, az, f.octDepth);
    const VI zero = hn::Zero(di);
    SampleCells c{leaf, hn::FirstN(di, 0), ax, ay, az, zero, zero, zero, zero};
    if (f.fine == nullptr) return c;
    c.mapped = hn::Ne(r.fineBase, hn::Zero(di));
    if (hn::AllFalse(di, c.mapped)) return c;
    const VI axis = hn::Set(di, f.cellAxis);
    c.cx = mapCellOf(f, r.lx, r.dx, t);
    c.cy = mapCellOf(f, r.ly, r.dy, t);
    c.cz = mapCellOf(f, r.lz, r.dz, t);
    const VI cell = hn::Add(hn::Mul(hn::Add(hn::Mul(c.cz, axis), c.cy), axis), c.cx);
    const VI word = hn::GatherIndex(di, reinterpret_cast<const std::int32_t*>(f.fine),
                                    hn::Add(hn::ShiftRight<2>(cell), r.fineBase));
    c.d = hn::And(hn::Shr(word, hn::ShiftLeft<3>(hn::And(cell, hn::Set(di, 3)))), hn::Set(di, 255));
    c.sampled =
        hn::Or(hn::And(c.mapped, hn::Eq(c.d, hn::Zero(di))), hn::AndNot(c.mapped, c.sampled));
    return c;
}

/// BrickRay::exitOf() on one axis per lane, for a cube at lo of edge size.
HWY_INLINE VF exitOn(VF lo, VF size, VF local, VF dir, VF inv) {
    const DF df;
    const VF far = hn::Set(df, 3.0e38f);
    const VF face = hn::Add(lo, hn::IfThenElseZero(hn::Gt(dir, hn::Zero(df)), size));
    return hn::IfThenElse(hn::Eq(dir, hn::Zero(df)), far, hn::Mul(hn::Sub(face, local), inv));
}

/// BrickRay::exitOf() per lane: where the ray leaves the cube of edge size at node (nx, ny, nz).
HWY_INLINE VF exitOfCube(const LaneRays& r, VI nx, VI ny, VI nz, VF size) {
    const DF df;
    const VF far = hn::Set(df, 3.0e38f);
    return hn::Min(
        hn::Min(hn::Min(far, exitOn(hn::Mul(hn::ConvertTo(df, nx), size), size, r.lx, r.dx, r.ix)),
                exitOn(hn::Mul(hn::ConvertTo(df, ny), size), size, r.ly, r.dy, r.iy)),
        exitOn(hn::Mul(hn::ConvertTo(df, nz), size), size, r.lz, r.dz, r.iz));
}

/// Lanes `tree` (octree, their leaves empty): where each leaves the coarsest empty node that
/// holds its leaf, the level walked up from the leaf (coarsestEmpty()).
HWY_INLINE VF exitOfEmptyNode(const Frame& f, const LaneRays& r, const SampleCells& c,
                              hn::Mask<DI> tree) {
    const DF df;
    const DI di;
    VI level = hn::Set(di, 1);
    hn::Mask<DI> found = hn::Not(tree);
    for (int l = f.octDepth - 1; l >= 1 && !hn::AllTrue(di, found); --l) {
        const hn::Mask<DI> set =
            hn::AndNot(found, nodeSampled(f, f.occ, r.wordBase, c.ax, c.ay, c.az, l));
        level = hn::IfThenElse(set, hn::Set(di, l + 1), level);
        found = hn::Or(found, set);
    }
    const VI shift = hn::Sub(hn::Set(di, f.octDepth), level);
    const VF size = hn::Mul(hn::Set(df, f.leaf), hn::ConvertTo(df, hn::Shl(hn::Set(di, 1), shift)));
    return exitOfCube(r, hn::Shr(c.ax, shift), hn::Shr(c.ay, shift), hn::Shr(c.az, shift), size);
}

/// Lanes with a distance map, their cell's distance d > 0: where each leaves the cube of cells
/// within d - 1 of the sample's, all empty (sampleAfterCube()): its corner at (c - d) cell +
/// 1/2, its edge 2d - 1 cells.
HWY_INLINE VF exitOfEmptyCells(const Frame& f, const LaneRays& r, const SampleCells& c) {
    const DF df;
    const DI di;
    const VF cellSize = hn::Set(df, f.cell), half = hn::Set(df, 0.5f);
    const VI one = hn::Set(di, 1);
    const VI back = hn::Sub(c.d, one);
    const VF size = hn::Mul(hn::ConvertTo(df, hn::Add(hn::Add(back, back), one)), cellSize);
    auto lo = [&](VI cell, VF local, VF dir, VF inv) {
        return exitOn(hn::Add(hn::Mul(hn::ConvertTo(df, hn::Sub(cell, c.d)), cellSize), half), size,
                      local, dir, inv);
    };
    return hn::Min(hn::Min(hn::Min(hn::Set(df, 3.0e38f), lo(c.cx, r.lx, r.dx, r.ix)),
                           lo(c.cy, r.ly, r.dy, r.iy)),
                   lo(c.cz, r.lz, r.dz, r.iz));
}

/// Per lane, the first sample at or after parameter tExit (BrickRay::sampleAt()), at least
/// one past k and at most `end`.
HWY_INLINE VI sampleAfterExit(const Frame& f, const LaneRays& r, VF tExit, VI k, VI end) {
    const DF df;
    const DI di;
    const VF after = hn::Ceil(
        hn::Sub(hn::Mul(hn::Sub(tExit, r.t0), hn::Set(df, 1.0f / f.stepMm)), hn::Set(df, 0.5f)));
    const VF to = hn::Max(hn::Min(after, hn::ConvertTo(df, end)),
                          hn::ConvertTo(df, hn::Add(k, hn::Set(di, 1))));
    return hn::ConvertTo(di, to);
}

/// The samples k of the lanes `empty` (their samples in empty space) moved on to their first
/// sample past the empty node or cube that holds it (the scalar walk's sampleAfterNode() and
/// sampleAfterCube(), to within an ulp at the exit, render/OCCUPANCY.md), at least one on and
/// at most to `end`; the other lanes' k as they are.
HWY_INLINE VI leapEmpty(const Frame& f, const LaneRays& r, const SampleCells& c, hn::Mask<DI> empty,
                        VI k, VI end) {
    const DF df;
    const DI di;
    VF tExit = hn::Set(df, 3.0e38f);
    const hn::Mask<DI> tree = hn::AndNot(c.mapped, empty);
    if (!hn::AllFalse(di, tree)) tExit = exitOfEmptyNode(f, r, c, tree);
    const hn::Mask<DI> cube = hn::And(c.mapped, empty);
    if (!hn::AllFalse(di, cube))
        tExit = hn::IfThenElse(hn::RebindMask(df, cube), exitOfEmptyCells(f, r, c), tExit);
    return hn::IfThenElse(empty, sampleAfterExit(f, r, tExit, k, end), k);
}

} // namespace HWY_NAMESPACE
} // namespace bc::render::detail
HWY_AFTER_NAMESPACE();

#endif // BRICKCAST_RENDER_DETAIL_CPUMARCHBRICK_INL_H_
