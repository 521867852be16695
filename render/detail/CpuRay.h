#pragma once
// The CPU raycaster's ray model (render/CpuRaycaster.cpp): the frame's uniforms, the
// classification, shading and compositing of one sample, the octree walk and the scalar
// march through one brick. The vectorised march (render/detail/CpuMarchSimd.cpp) takes the
// same samples with the same formulas, many at once, and falls back to these per sample.
#include "render/Occupancy.h"
#include "render/RenderTypes.h"
#include "render/TransferFunction.h"
#include "render/detail/CpuSampling.h"

#include <algorithm>
#include <cmath>
#include <cstdint>
#include <limits>
#include <vector>

#include <glm/common.hpp>
#include <glm/geometric.hpp>
#include <glm/vec3.hpp>

namespace bc::render::detail {

enum class Slot : std::uint8_t { Absent, Sampled, Constant };

struct BrickRef {
    const void* voxels = nullptr; ///< while its batch is drawn
    float constant = 0.0f;
    std::uint32_t batch = 0; ///< the front-to-back batch that draws it
    Slot slot = Slot::Absent;
    /// Its distance map's first word in Frame::fine (FineOccupancy::offsetOf; 0: none).
    std::uint32_t fine = 0;
    /// Under Frame::running: a bound on every sample value in the brick, from above for a
    /// maximum, from below for a minimum (interpolatedUpper(), interpolatedLower()).
    float bound = 0.0f;
};

/// Everything a ray needs, in float, as the shader's uniforms.
struct Frame {
    glm::vec3 eye, forward, right, up;
    bool ortho = false;
    float width = 0, height = 0;
    glm::vec3 invSpacing, dims;
    float stepMm = 1;
    int brick = 64, apron = 2, edge = 68;
    glm::ivec3 grid{1};
    const float* tf = nullptr;
    int entries = 2;
    /// f.tf as pairs (tfPairTable()): the SIMD march reads both ends of a channel's lerp with
    /// one 64-bit gather lane; null: it gathers them from f.tf one by one.
    const float* tfPairs = nullptr;
    float tfScale = 1, tfOffset = 0; ///< native value -> table position
    float ertT = -1; ///< stop a ray once its transmittance is at most this (-1: never)
    bool shading = true;
    bool simd = true;    ///< march bricks with marchBrickSimd (CpuMarchSimd.h)
    bool packets = true; ///< with simd: march rays a vector at a time (marchPacketSimd)
    /// marchPacketSimd(): the bytes its 32-bit gather offsets reach from the packet's first
    /// brick; a lane's brick further away marches with the scalar loop (tests shrink it).
    std::int64_t gatherReach = std::numeric_limits<std::int32_t>::max();
    bool jitter = false; ///< RenderOptions::jitter
    /// RenderOptions::preintegrate: segments classify through this table (the scalar
    /// marchBrickPre), `segment` long in the opacity's units (the step in voxels).
    const PreintegratedTable* pre = nullptr;
    double segment = 1.0;
    glm::vec3 gradScale{1};
    const std::uint32_t* occ = nullptr;
    const SampledBox* boxes = nullptr; ///< per brick, with occ (OccupancyTrees::sampledBoxes)
    int octDepth = 0, occWords = 0, leafAxis = 1;
    float leaf = 1;
    /// With occ: per-brick distance maps over cells of `cell` voxels, `cellAxis` of them along
    /// a brick (FineOccupancy), a brick's at BrickRef::fine words into `fine` (0: it has
    /// none and walks the octree). Null: no maps.
    const std::uint32_t* fine = nullptr;
    int cellAxis = 1;
    float cell = 1;
    const BrickRef* bricks = nullptr;
    std::uint32_t batch = 0; ///< the batch being drawn
    /// RenderOptions::mode; the other modes than composite march with the scalar loop
    /// (marchBrickMode), through `tf` as authored (step 1).
    BlendMode mode = BlendMode::Composite;
    ClipF clip;    ///< RenderOptions::clip: samples outside are not taken
    float iso = 0; ///< RenderOptions::isoValue
    /// capsCuts(): a ray entering through a cut draws the face first (takeCap()); its opacity
    /// is the table's raised to `capPower` (1 / the step in voxels: the table's is the step's).
    bool capping = false;
    float capPower = 1.0f;
    /// A maximum or minimum under skipping: a ray leaves out the bricks, and with `leafBound`
    /// the octree leaves, whose samples cannot pass its value so far (passes()): BrickRef::bound,
    /// and per leaf OccupancyTrees::leafBounds() (brick i's leaves from
    /// i * leafCount, numbered as the octree's).
    bool running = false;
    const float* leafBound = nullptr;
    int leafCount = 0;
};

struct Rgba {
    float r = 0, g = 0, b = 0, a = 0;
};

inline Rgba classify(const Frame& f, float value) {
    const float u = std::clamp(value * f.tfScale + f.tfOffset, 0.0f, float(f.entries - 1));
    const int i = std::min(int(u), f.entries - 2);
    const float w = u - float(i);
    const float* e = f.tf + 4 * i;
    auto mix = [w](float a, float b) { return lerp1(a, b, w); };
    return {mix(e[0], e[4]), mix(e[1], e[5]), mix(e[2], e[6]), mix(e[3], e[7])};
}

/// For entries e < entries - 1 of the RGBA table tf: r_e, r_e+1, g_e, g_e+1, b_e, b_e+1, a_e,
/// a_e+1 (the same floats, so a lerp of a pair is bit for bit the lerp of tf's entries).
inline std::vector<float> tfPairTable(const float* tf, int entries) {
    std::vector<float> pairs(std::size_t(std::max(entries - 1, 1)) * 8, 0.0f);
    for (int e = 0; e + 1 < entries; ++e)
        for (int ch = 0; ch < 4; ++ch) {
            pairs[std::size_t(e) * 8 + 2 * ch] = tf[4 * e + ch];
            pairs[std::size_t(e) * 8 + 2 * ch + 1] = tf[4 * (e + 1) + ch];
        }
    return pairs;
}

/// diff^kShininess by squaring (the exponent is a whole number): std::pow costs more than
/// the rest of the shading.
inline float powShininess(float x) {
    static_assert(ShadingModel::kShininess == 24.0, "powShininess assumes 24");
    const float x3 = x * x * x, x6 = x3 * x3, x12 = x6 * x6;
    return x12 * x12;
}

/// Blinn-Phong under the headlight: `diff` = |cos| between the normal and the ray, the lit
/// colour weighted by w in [0, 1] against the unlit one.
inline Rgba light(Rgba c, float diff, float w) {
    const float spec = float(ShadingModel::kSpecular) * powShininess(diff);
    const float k = float(ShadingModel::kAmbient) + float(ShadingModel::kDiffuse) * diff;
    auto lit = [&](float x) { return x + ((x * k + spec) - x) * w; };
    return {lit(c.r), lit(c.g), lit(c.b), c.a};
}

/// `diffs`: v(q + e_a) - v(q - e_a), the central differences of the interpolated field.
inline Rgba shade(const Frame& f, Rgba c, glm::vec3 diffs, glm::vec3 dir) {
    const glm::vec3 g = diffs * f.gradScale;
    const float len = glm::length(g);
    if (len <= 0.0f) return c;
    return light(c, std::abs(glm::dot(g / len, dir)),
                 std::clamp(len / float(ShadingModel::kGradientFade), 0.0f, 1.0f));
}

/// A ray's colour so far (premultiplied) and its transmittance t = 1 - alpha. Compositing
/// front to back multiplies t by 1 - a per sample: one multiply is all that chains one sample
/// to the next (the SIMD march composites lane by lane along that chain).
struct Accum {
    float r = 0, g = 0, b = 0, t = 1;
    /// The projections (BlendMode Maximum, Minimum, Average): the largest, smallest or summed
    /// value of the samples so far, and how many there were; the frame's image carries them
    /// raw and render::resolveProjections turns them into colours.
    float v = 0;
    std::uint32_t n = 0;
};

/// Takes a sample's value into a projecting ray; false once nothing can change its colour
/// (under early termination: a maximum at or past the table's last entry, a minimum at or
/// before its first, where classify() clamps, so any further value gives the same colour).
inline bool project(const Frame& f, Accum& acc, float value, std::uint64_t& raises) {
    switch (f.mode) {
    case BlendMode::Maximum:
        if (acc.n == 0 || value > acc.v) {
            acc.v = value;
            ++raises;
        }
        ++acc.n;
        return !(f.ertT >= 0.0f && acc.v * f.tfScale + f.tfOffset >= float(f.entries - 1));
    case BlendMode::Minimum:
        if (acc.n == 0 || value < acc.v) {
            acc.v = value;
            ++raises;
        }
        ++acc.n;
        return !(f.ertT >= 0.0f && acc.v * f.tfScale + f.tfOffset <= 0.0f);
    default: // Average
        acc.v += value;
        ++acc.n;
        return true;
    }
}

/// Under Frame::running: whether samples whose values `bound` bounds (BrickRef::bound, a
/// leaf's) could pass the ray's maximum or minimum so far; where they cannot, leaving them out
/// changes neither the value nor whether the ray has one (it has).
inline bool passes(const Frame& f, float bound, const Accum& acc) {
    if (acc.n == 0) return true;
    return f.mode == BlendMode::Maximum ? bound > acc.v : bound < acc.v;
}

inline void composite(Accum& acc, const Rgba& c) {
    const float w = acc.t * c.a;
    acc.r += w * c.r;
    acc.g += w * c.g;
    acc.b += w * c.b;
    acc.t *= 1.0f - c.a;
}

/// The coarsest octree level whose node holding `leaf` is empty, or 0 (the shader's walk).
inline int emptyLevel(const Frame& f, const std::uint32_t* words, glm::ivec3 leaf) {
    int first = 0;
    for (int l = 1; l <= f.octDepth; ++l) {
        const glm::ivec3 n = leaf >> (f.octDepth - l);
        const int s = 1 << l;
        const int bit = first + (n.z * s + n.y) * s + n.x;
        if (((words[bit >> 5] >> (bit & 31)) & 1u) == 0u) return l;
        first += s * s * s;
    }
    return 0;
}

inline float exitParameter(glm::vec3 p0, glm::vec3 dv, glm::vec3 lo, float size) {
    float t = 3.0e38f;
    for (int a = 0; a < 3; ++a) {
        if (dv[a] > 0.0f)
            t = std::min(t, (lo[a] + size - p0[a]) / dv[a]);
        else if (dv[a] < 0.0f)
            t = std::min(t, (lo[a] - p0[a]) / dv[a]);
    }
    return t;
}

struct RayCount {
    std::uint64_t samples = 0, leaps = 0;
    std::uint64_t raises = 0; ///< projections: samples that raised a maximum or lowered a minimum
};

/// Narrows samples [k, kEnd) of a brick to those inside the box of its sampled leaves; false
/// when none is left. The samples left out lie in leaves whose bit is clear, which the octree
/// walk would skip one by one (to within an ulp of the box's faces, where a sample is
/// transparent if either leaf is: render/OCCUPANCY.md). A face on the brick's own boundary is
/// not a limit: a sample there may lie a rounding error outside and count as the edge leaf.
/// `invDv`: 1 / dv per axis (any value where dv is 0); `invStep`: 1 / f.stepMm.
[[gnu::always_inline]] inline bool clipToSampled(const Frame& f, const SampledBox& box,
                                                 glm::vec3 local, glm::vec3 dv, glm::vec3 invDv,
                                                 float invStep, float t0, int& k, int& kEnd) {
    if (box.none()) return false;
    constexpr float kInf = std::numeric_limits<float>::infinity();
    float ta = -kInf, tb = kInf;
    for (int a = 0; a < 3; ++a) {
        const float lo = box.lo[a] == 0 ? -kInf : float(box.lo[a]) * f.leaf;
        const float hi = int(box.hi[a]) >= f.leafAxis - 1 ? kInf : float(box.hi[a] + 1) * f.leaf;
        if (dv[a] == 0.0f) {
            if (local[a] < lo || local[a] >= hi) return false;
            continue;
        }
        const float u0 = (lo - local[a]) * invDv[a], u1 = (hi - local[a]) * invDv[a];
        ta = std::max(ta, std::min(u0, u1));
        tb = std::min(tb, std::max(u0, u1));
    }
    // Sample indices as floats first: the parameters may be infinite.
    const float ka = (ta - t0) * invStep - 0.5f, kb = (tb - t0) * invStep - 0.5f;
    if (!(ta < tb) || !(ka < float(kEnd)) || !(kb > float(k))) return false;
    if (ka > float(k)) k = int(std::ceil(ka));
    if (kb < float(kEnd)) kEnd = int(std::ceil(kb));
    return k < kEnd;
}

/// A sample's value at q and, where no fetch of the six-fetch gradient would be clamped
/// (every sample of the payload once the apron is 2 or more), the cell whose weights give the
/// gradient too: 8 loads for the value, 24 more only for a visible shaded sample.
template <class T> struct Sample {
    const T* v;
    int edge;
    glm::vec3 q;
    bool fused;
    detail::Cell<T> cell;
    float value;

    Sample(const T* voxels, int edgeVoxels, glm::vec3 at)
        : v(voxels), edge(edgeVoxels), q(at), fused(detail::fusedInRange(edge, q)) {
        if (fused) {
            cell = detail::cellAt(v, edge, q);
            value = detail::cellValue(cell); // bit for bit detail::fetch(v, edge, q)
        } else {
            value = detail::fetch(v, edge, q);
        }
    }
    /// v(q + e_a) - v(q - e_a).
    glm::vec3 diffs() const {
        return fused ? detail::cellGradient(cell) : detail::sixFetchGradient(v, edge, q);
    }
};

/// A sample's straight colour: classified, and shaded where it is visible.
template <class T> Rgba colourOf(const Frame& f, const Sample<T>& s, glm::vec3 dir) {
    Rgba c = classify(f, s.value);
    if (c.a > 0.0f && f.shading) c = shade(f, c, s.diffs(), dir);
    return c;
}

/// The first sample past the empty octree node of level l (emptyLevel()) that holds `leaf`.
inline int sampleAfterNode(const Frame& f, glm::vec3 local, glm::vec3 dv, float t0, glm::ivec3 leaf,
                           int l) {
    const int shift = f.octDepth - l;
    const float size = f.leaf * float(1 << shift);
    const glm::vec3 lo = glm::vec3(leaf >> shift) * size;
    const float tExit = exitParameter(local, dv, lo, size);
    return int(std::ceil((tExit - t0) / f.stepMm - 0.5f));
}

/// The cell of brick-local position p in a brick's distance map: f.cell voxels a cell, on the
/// sampler's voxel lattice (cell c holds p in [(c - 1) cell + 1/2, c cell + 1/2)), clamped
/// into the map. f.cell is a power of two: its reciprocal is exact.
inline glm::ivec3 cellOf(const Frame& f, glm::vec3 p) {
    return glm::clamp(glm::ivec3(glm::floor((p + (f.cell - 0.5f)) * (1.0f / f.cell))),
                      glm::ivec3(0), glm::ivec3(f.cellAxis - 1));
}

/// A cell's distance in a brick's map (FineOccupancy): 0 where samples are taken, else d: the
/// cells within d - 1 of it along every axis are empty.
inline int cellDistance(const Frame& f, const std::uint8_t* map, glm::ivec3 c) {
    return map[(std::size_t(c.z) * std::size_t(f.cellAxis) + std::size_t(c.y)) *
                   std::size_t(f.cellAxis) +
               std::size_t(c.x)];
}

/// The first sample past the empty cube of cells within d - 1 of cell c (cellDistance() d).
/// By reciprocals, as the march across rays computes it, so that both leap to the same sample.
inline int sampleAfterCube(const Frame& f, glm::vec3 local, glm::vec3 dv, float t0, glm::ivec3 c,
                           int d) {
    const glm::vec3 lo = glm::vec3(c - d) * f.cell + 0.5f;
    const float size = float(2 * d - 1) * f.cell;
    float tExit = 3.0e38f;
    for (int a = 0; a < 3; ++a) {
        if (dv[a] == 0.0f) continue;
        const float face = dv[a] > 0.0f ? lo[a] + size : lo[a];
        tExit = std::min(tExit, (face - local[a]) * (1.0f / dv[a]));
    }
    return int(std::ceil((tExit - t0) * (1.0f / f.stepMm) - 0.5f));
}

/// The samples [k, kEnd) of one sampled brick that the brick's distance map or octree does
/// not leap, each given to `take(k, t)` (sample k at ray parameter t), which returns false to
/// end the ray; false when it did. `map`: the brick's distance map (f.fine + its
/// BrickRef::fine, as bytes), which then decides in place of the octree; null to walk the
/// octree.
template <class Take>
[[gnu::always_inline]] inline bool
walkBrick(const Frame& f, const std::uint32_t* words, const std::uint8_t* map, glm::vec3 local,
          glm::vec3 dv, float t0, int& k, int kEnd, RayCount& n, const Take& take) {
    glm::ivec3 checked(-1);
    for (; k < kEnd; ++k) {
        const float t = t0 + (float(k) + 0.5f) * f.stepMm;
        if (map) {
            const glm::ivec3 cell = cellOf(f, local + dv * t);
            const int d = cellDistance(f, map, cell);
            if (d > 0) {
                ++n.leaps;
                k = std::max(k, std::min(sampleAfterCube(f, local, dv, t0, cell, d), kEnd) - 1);
                continue;
            }
        } else if (words) {
            const glm::ivec3 leaf = glm::clamp(glm::ivec3(glm::floor((local + dv * t) / f.leaf)),
                                               glm::ivec3(0), glm::ivec3(f.leafAxis - 1));
            if (leaf != checked) {
                const int l = emptyLevel(f, words, leaf);
                if (l > 0) {
                    ++n.leaps;
                    k = std::max(k, std::min(sampleAfterNode(f, local, dv, t0, leaf, l), kEnd) - 1);
                    continue;
                }
                checked = leaf;
            }
        }
        ++n.samples;
        if (!take(k, t)) return false;
    }
    return true;
}

/// Samples [k, kEnd) of one sampled brick; returns false once the ray is opaque (walkBrick()).
template <class T>
bool marchBrick(const Frame& f, const T* v, const std::uint32_t* words, const std::uint8_t* map,
                glm::vec3 local, glm::vec3 dv, glm::vec3 dir, float t0, int& k, int kEnd,
                Accum& acc, RayCount& n) {
    const glm::vec3 rel = local + (float(f.apron) - 0.5f);
    return walkBrick(f, words, map, local, dv, t0, k, kEnd, n, [&](int, float t) {
        const Rgba c = colourOf(f, Sample<T>(v, f.edge, rel + dv * t), dir);
        if (c.a <= 0.0f) return true;
        composite(acc, c);
        return acc.t > f.ertT;
    });
}

/// An isosurface's hit on the step from sample k - 1 (below f.iso) to sample k at parameter t
/// (at or above it), the field read by `at(u)`: IsoModel's bisections; sample k itself when
/// it is the ray's first kept sample, `first` (the volume's box or the clip cuts the surface).
template <class At>
float isoHit(const Frame& f, float t0, int first, int k, float t, const At& at) {
    if (k == first) return t;
    float lo = t0 + (float(k - 1) + 0.5f) * f.stepMm, hi = t;
    for (int i = 0; i < IsoModel::kBisections; ++i) {
        const float mid = 0.5f * (lo + hi);
        (at(mid) >= f.iso ? hi : lo) = mid;
    }
    return 0.5f * (lo + hi);
}

/// The isosurface's colour: the function's at the iso value, opaque; shaded by `diffs` (the
/// gradient's central differences at the hit).
inline Rgba isoColour(const Frame& f, glm::vec3 diffs, glm::vec3 dir) {
    Rgba c = classify(f, f.iso);
    c.a = 1.0f;
    return f.shading ? shade(f, c, diffs, dir) : c;
}

/// marchBrick for the other modes than composite: the projections take every sample's value
/// (project()), an isosurface ends the ray at its first sample at or above the iso value,
/// whose crossing it refines within this brick's voxels (isoHit). Leaps as walkBrick does,
/// under the mode's own octrees (SkipRule).
template <class T>
bool marchBrickMode(const Frame& f, const T* v, const std::uint32_t* words, const std::uint8_t* map,
                    glm::vec3 local, glm::vec3 dv, glm::vec3 dir, float t0, int first, int& k,
                    int kEnd, Accum& acc, RayCount& n) {
    const glm::vec3 rel = local + (float(f.apron) - 0.5f);
    return walkBrick(f, words, map, local, dv, t0, k, kEnd, n, [&](int j, float t) {
        const float value = detail::fetch(v, f.edge, rel + dv * t);
        if (f.mode != BlendMode::Isosurface) return project(f, acc, value, n.raises);
        if (value < f.iso) return true;
        const float hit = isoHit(f, t0, first, j, t,
                                 [&](float u) { return detail::fetch(v, f.edge, rel + dv * u); });
        composite(acc, isoColour(f, Sample<T>(v, f.edge, rel + dv * hit).diffs(), dir));
        return false;
    });
}

/// marchConstant for the other modes than composite (marchBrickMode).
inline bool marchConstantMode(const Frame& f, float value, int& k, int kEnd, Accum& acc,
                              RayCount& n) {
    if (f.mode == BlendMode::Isosurface) {
        if (value < f.iso) {
            n.samples += std::uint64_t(kEnd - k);
            k = kEnd;
            return true;
        }
        // The surface is at the brick's first sample or before it, where it meets the brick
        // of one value: no gradient there, the surface unshaded wherever it lies.
        ++n.samples;
        composite(acc, isoColour(f, glm::vec3(0.0f), glm::vec3(0.0f)));
        return false;
    }
    for (; k < kEnd; ++k) {
        ++n.samples;
        if (!project(f, acc, value, n.raises)) return false;
    }
    return true;
}

/// Samples [k, kEnd) of a brick of one value `value`; false once the ray is opaque.
inline bool marchConstant(const Frame& f, float value, int& k, int kEnd, Accum& acc, RayCount& n) {
    const Rgba c = classify(f, value);
    n.samples += std::uint64_t(kEnd - k);
    for (; c.a > 0.0f && k < kEnd; ++k) {
        composite(acc, c);
        if (acc.t <= f.ertT) return false;
    }
    return true;
}

/// Narrows a ray's samples [first, total) (sample k at t0 + (k + 1/2) step, `invStep` = 1 /
/// step) to those `clip` keeps along o + t d, and gives the parameters it keeps, [ta, tb];
/// false when no sample is left.
inline bool clipLattice(const ClipF& clip, glm::vec3 o, glm::vec3 d, float t0, float invStep,
                        int& first, int& total, float& ta, float& tb) {
    ta = -3.0e38f;
    tb = 3.0e38f;
    clip.interval(o, d, ta, tb);
    if (!(ta <= tb)) return false;
    const float kb = std::ceil((tb - t0) * invStep - 0.5f);
    if (kb < float(total)) total = kb > 0.0f ? int(kb) : 0;
    const float ka = std::ceil((ta - t0) * invStep - 0.5f);
    if (ka > 0.0f) first = ka < float(total) ? int(ka) : total;
    return first < total;
}

enum class RayPhase : std::uint8_t { Fresh, Waiting, Done };

/// A ray between batches: its colour so far and its phase. Every pass reads and writes it, so
/// it is small (a 512^2 frame's are 5 MB): the DDA state of a waiting ray is kept apart.
struct RayState {
    Accum acc;
    RayPhase phase = RayPhase::Fresh;
};

/// A ray waiting for a brick of a later batch: its DDA state at that brick, so the next pass
/// goes on with the same floats. Written only when the ray stops to wait (RayWalk::next), read
/// only when it is Waiting: a frame of one batch never touches it.
struct RayResume {
    glm::ivec3 cell{0};
    glm::vec3 tMax{0.0f};
    int k = 0;
    int brick = 0; ///< the brick it waits for
};

/// One ray's walk through the brick grid (the shader's main()) for the bricks of batch
/// f.batch: a 3D DDA over bricks that stops at each brick with samples of the ray to draw,
/// and, state saved, at the first such brick of a later batch. Samples are k = 0 .. total - 1
/// at t0 + (k + 1/2) step; those in the brick next() stopped at are [k, kEnd).
struct RayWalk {
    glm::vec3 d{0.0f}, ov{0.0f}, dv{0.0f}; ///< direction (world), origin and direction (voxels)
    glm::vec3 invDv{0.0f};                 ///< 1 / dv (inf on an axis it does not move along)
    float t0 = 0.0f, invStep = 1.0f;
    int total = 0, k = 0, kEnd = 0;
    int first = 0; ///< the first sample kept (0 unless a crop or clip cuts the ray's start)
    int index = 0; ///< the brick next() stopped at
    glm::ivec3 cell{0}, stepDir{0};
    glm::vec3 tDelta{0.0f}, tMax{0.0f};
    bool entered = false; ///< next() stopped at a brick, which the next call leaves

    /// Sets up the ray of image-plane position (sx, sy) for this pass; false when it has
    /// nothing to draw in it (done, waiting for a later batch, or missing the volume).
    /// `shift`: where its samples start, in steps, relative to the unjittered lattice
    /// (rayJitter() - 1/2 with RenderOptions::jitter, else 0).
    bool begin(const Frame& f, float sx, float sy, float shift, RayState& s, const RayResume& r) {
        if (s.phase == RayPhase::Done) return false;
        if (s.phase == RayPhase::Waiting && f.bricks[r.brick].batch != f.batch) return false;
        const RayPhase phase = s.phase;
        s.phase = RayPhase::Done; // unless it stops to wait in next()
        const glm::vec3 o = f.ortho ? f.eye + sx * f.right + sy * f.up : f.eye;
        d = f.ortho ? f.forward : glm::normalize(f.forward + sx * f.right + sy * f.up);
        ov = o * f.invSpacing;
        dv = d * f.invSpacing;
        // Reciprocals once: divisions are most of a ray's set-up.
        invDv = 1.0f / dv;
        invStep = 1.0f / f.stepMm;
        float t1 = 3.0e38f;
        t0 = 0.0f;
        for (int a = 0; a < 3; ++a) {
            if (dv[a] == 0.0f) {
                if (ov[a] < 0.0f || ov[a] > f.dims[a]) return false;
                continue;
            }
            const float ta = -ov[a] * invDv[a], tb = (f.dims[a] - ov[a]) * invDv[a];
            t0 = std::max(t0, std::min(ta, tb));
            t1 = std::min(t1, std::max(ta, tb));
        }
        t0 += shift * f.stepMm; // sample k at t0 + (k + 1/2) step: the entry + (k + jitter) step
        total = int(std::ceil((t1 - t0) * invStep - 0.5f));
        if (total <= 0) return false;
        first = 0; // a crop or clip keeps samples [first, total) of the same lattice
        if (f.clip.any && !clipSamples(f, o)) return false;
        if (phase != RayPhase::Fresh) {
            cell = r.cell;
            tMax = r.tMax;
        } else {
            const glm::vec3 pin = ov + dv * t0;
            cell =
                glm::clamp(glm::ivec3(glm::floor(pin / float(f.brick))), glm::ivec3(0), f.grid - 1);
        }
        for (int a = 0; a < 3; ++a) {
            stepDir[a] = dv[a] > 0.0f ? 1 : dv[a] < 0.0f ? -1 : 0;
            if (stepDir[a] == 0) {
                tDelta[a] = 3.0e38f;
                if (phase == RayPhase::Fresh) tMax[a] = 3.0e38f;
                continue;
            }
            tDelta[a] = float(f.brick) * std::abs(invDv[a]);
            if (phase != RayPhase::Fresh) continue;
            const float plane = float((cell[a] + (stepDir[a] > 0 ? 1 : 0)) * f.brick);
            tMax[a] = (plane - ov[a]) * invDv[a];
        }
        k = phase == RayPhase::Fresh ? first : r.k;
        entered = false;
        return true;
    }

    /// Narrows the samples to those the clip keeps: [first, total); false when none is.
    bool clipSamples(const Frame& f, glm::vec3 o) {
        float ta, tb;
        return clipLattice(f.clip, o, d, t0, invStep, first, total, ta, tb);
    }

    /// On to the next brick of this batch, sampled or of one value, with samples [k, kEnd) of
    /// the ray; false at the end of the ray or when it stops to wait for a later batch.
    bool next(const Frame& f, RayState& s, RayResume& r) {
        if (entered && !leave(f)) return false;
        entered = false;
        while (k < total) {
            const float tOut = std::min({tMax.x, tMax.y, tMax.z});
            kEnd = std::min(total, int(std::ceil((tOut - t0) * invStep - 0.5f)));
            index = (cell.z * f.grid.y + cell.y) * f.grid.x + cell.x;
            const BrickRef& b = f.bricks[index];
            if (b.slot != Slot::Absent && kEnd > k) {
                if (b.batch != f.batch) {
                    r.cell = cell;
                    r.tMax = tMax;
                    r.k = k;
                    r.brick = index;
                    s.phase = RayPhase::Waiting;
                    return false;
                }
                entered = true;
                return true;
            }
            if (!leave(f)) return false;
        }
        return false;
    }

    /// The ray's origin relative to the corner of the brick next() stopped at.
    glm::vec3 local(const Frame& f) const { return ov - glm::vec3(cell * f.brick); }

  private:
    bool leave(const Frame& f) {
        k = std::max(k, kEnd);
        const int a = tMax.x <= tMax.y ? (tMax.x <= tMax.z ? 0 : 2) : (tMax.y <= tMax.z ? 1 : 2);
        cell[a] += stepDir[a];
        tMax[a] += tDelta[a];
        return cell[a] >= 0 && cell[a] < f.grid[a];
    }
};

/// Where the ray of image-plane position (sx, sy) enters and leaves the segment it keeps (the
/// volume's box, narrowed by the crop and clip planes), in voxels, as RayWalk::begin() sets it
/// up; false when the ray has no sample of its lattice (`shift`: begin()'s) to draw.
/// samplesEnds(): a maximum or minimum samples these two points besides its lattice. Scalar
/// arithmetic throughout (glm's component-wise functions are calls here, at a ray's cost).
inline bool segmentEnds(const Frame& f, float sx, float sy, float shift, glm::vec3& in,
                        glm::vec3& out) {
    glm::vec3 o = f.eye, d = f.forward;
    for (int a = 0; a < 3; ++a) {
        if (f.ortho)
            o[a] += sx * f.right[a] + sy * f.up[a];
        else
            d[a] += sx * f.right[a] + sy * f.up[a];
    }
    if (!f.ortho) {
        const float inv = 1.0f / std::sqrt(d.x * d.x + d.y * d.y + d.z * d.z);
        d = glm::vec3(d.x * inv, d.y * inv, d.z * inv);
    }
    glm::vec3 ov, dv;
    float t0 = 0.0f, t1 = 3.0e38f;
    for (int a = 0; a < 3; ++a) {
        ov[a] = o[a] * f.invSpacing[a];
        dv[a] = d[a] * f.invSpacing[a];
        if (dv[a] == 0.0f) {
            if (ov[a] < 0.0f || ov[a] > f.dims[a]) return false;
            continue;
        }
        const float inv = 1.0f / dv[a];
        const float ta = -ov[a] * inv, tb = (f.dims[a] - ov[a]) * inv;
        t0 = std::max(t0, std::min(ta, tb));
        t1 = std::min(t1, std::max(ta, tb));
    }
    const float invStep = 1.0f / f.stepMm, lattice = t0 + shift * f.stepMm;
    int total = int(std::ceil((t1 - lattice) * invStep - 0.5f));
    if (total <= 0) return false;
    float tIn = t0, tOut = t1;
    if (f.clip.any) { // as RayWalk::clipSamples()
        int first = 0;
        float ta, tb;
        if (!clipLattice(f.clip, o, d, lattice, invStep, first, total, ta, tb)) return false;
        tIn = std::max(tIn, ta);
        tOut = std::min(tOut, tb);
    }
    for (int a = 0; a < 3; ++a) {
        in[a] = ov[a] + dv[a] * tIn;
        out[a] = ov[a] + dv[a] * tOut;
    }
    return true;
}

/// The brick of the level holding voxel position p (in the box [0, dims] but for rounding:
/// truncation is the floor, clamped), and p relative to its corner.
inline int brickHolding(const Frame& f, float invBrick, glm::vec3 p, glm::vec3& local) {
    int cell[3];
    for (int a = 0; a < 3; ++a)
        cell[a] = std::min(std::max(int(p[a] * invBrick), 0), f.grid[a] - 1);
    for (int a = 0; a < 3; ++a)
        local[a] = p[a] - float(cell[a] * f.brick);
    return (cell[2] * f.grid.y + cell[1]) * f.grid.x + cell[0];
}

/// The value at brick-local position `local` of brick b (sampled through its apron, or its
/// one value).
template <class T> float valueIn(const Frame& f, const BrickRef& b, glm::vec3 local) {
    if (b.slot != Slot::Sampled) return b.constant;
    const float shift = float(f.apron) - 0.5f;
    return detail::fetch(static_cast<const T*>(b.voxels), f.edge,
                         glm::vec3(local.x + shift, local.y + shift, local.z + shift));
}

/// Where a ray enters what it keeps through a cut (capping): a crop face or a plane inside the
/// volume's box, with a sample of the ray's lattice behind it (cutEntriesSimd()).
struct CutEntry {
    glm::vec3 p;      ///< the point, in voxels
    glm::vec3 normal; ///< the cut's unit normal, world
    glm::vec3 d;      ///< the ray's direction, world
};

/// Capping (Frame::capping, render/MODES.md): the face of cut entry `e`, drawn into ray state
/// `state` before any of its samples, in the pass that draws the face's brick (the batches go
/// front to back: no later than the ray's first sample's). A brick the plan leaves out, or an
/// empty octree leaf, holds no visible value (composite) or none at or above the iso value: no
/// face. Composite: the table's colour at the value there, its opacity for one voxel's length
/// (Frame::capPower); isosurface: at or above the iso value, the surface's colour, opaque, and
/// the ray is done. Both shaded by the cut's normal.
template <class T> void takeCap(const Frame& f, const CutEntry& e, RayState& state, RayCount& n) {
    glm::vec3 local;
    const int index = brickHolding(f, 1.0f / float(f.brick), e.p, local);
    const BrickRef& b = f.bricks[index];
    if (b.slot == Slot::Absent || b.batch != f.batch) return;
    if (b.slot == Slot::Sampled && f.occ) { // an empty leaf holds no face, as it holds no sample
        glm::ivec3 leaf;
        for (int a = 0; a < 3; ++a)
            leaf[a] = std::min(std::max(int(local[a] / f.leaf), 0), f.leafAxis - 1);
        if (emptyLevel(f, f.occ + std::size_t(index) * f.occWords, leaf) > 0) return;
    }
    const float value = valueIn<T>(f, b, local);
    ++n.samples;
    const float diff = std::abs(e.normal.x * e.d.x + e.normal.y * e.d.y + e.normal.z * e.d.z);
    Rgba c;
    if (f.mode == BlendMode::Isosurface) {
        if (value < f.iso) return;
        c = classify(f, f.iso);
        c.a = 1.0f;
        state.phase = RayPhase::Done;
    } else {
        c = classify(f, value);
        if (c.a <= 0.0f) return;
        c.a = std::min(-std::expm1(std::log1p(-c.a) * f.capPower), 1.0f);
        if (!(c.a > 0.0f)) return;
    }
    if (f.shading) c = light(c, diff, 1.0f);
    // In front of whatever the ray holds (nothing, but for a pass order that rounding could
    // turn): the face is its front-most layer. On an empty ray, composite()'s floats.
    const float keep = 1.0f - c.a;
    state.acc.r = c.a * c.r + keep * state.acc.r;
    state.acc.g = c.a * c.g + keep * state.acc.g;
    state.acc.b = c.a * c.b + keep * state.acc.b;
    state.acc.t *= keep;
    if (state.acc.t <= f.ertT) state.phase = RayPhase::Done;
}

/// What takeEnd() needs of the frame beyond Frame: reciprocals to locate a point (bricks, and
/// octree leaves within one), and where the table is transparent for the mode: a value whose
/// table position (classify()'s, clamped) is at or below `clearBelow` maps to alpha 0 and so
/// cannot make a maximum visible, one at or above `clearAbove` a minimum.
struct EndGrid {
    float invBrick, invLeaf;
    float clearBelow = -1.0f, clearAbove;
    explicit EndGrid(const Frame& f)
        : invBrick(1.0f / float(f.brick)), invLeaf(1.0f / f.leaf), clearAbove(float(f.entries)) {
        int first = f.entries, last = -1; // the entries with alpha above 0
        for (int e = 0; e < f.entries; ++e)
            if (f.tf[4 * e + 3] > 0.0f) {
                first = std::min(first, e);
                last = e;
            }
        // Between entries e - 1 and e the lerp is exact (a + t (b - a)): at position e - 1 it
        // is entry e - 1's alpha, 0.
        clearBelow = float(first - 1);
        clearAbove = last < 0 ? -1.0f : float(last + 1);
    }
    /// Whether samples whose values `bound` bounds (from above for a maximum, below for a
    /// minimum) can change the ray's colour: not when they cannot pass its value so far, nor
    /// when all map to transparency (then the ray's value is transparent too, or passes them).
    [[gnu::always_inline]] bool matters(const Frame& f, float bound, const Accum& acc) const {
        if (!passes(f, bound, acc)) return false;
        const float u = std::clamp(bound * f.tfScale + f.tfOffset, 0.0f, float(f.entries - 1));
        return f.mode == BlendMode::Maximum ? u > clearBelow : u < clearAbove;
    }
};

/// Takes a segment's end at voxel position p into a projecting ray when the brick holding it
/// is drawn in this pass (f.batch): sampled through its apron, or its one value. A brick the
/// plan leaves out holds no value that could change the ray's colour (render/MODES.md), and a
/// brick of another batch takes it in that batch's pass. Under Frame::running, not where the
/// brick's or the leaf's bound says the sample cannot matter (EndGrid::matters()). A point on
/// a face between two bricks or leaves may go to either: the apron gives it the same value in
/// both, and each one's bounds cover it (as they cover the march's samples there).
template <class T>
void takeEnd(const Frame& f, const EndGrid& grid, glm::vec3 p, Accum& acc, RayCount& n) {
    glm::vec3 local;
    const int index = brickHolding(f, grid.invBrick, p, local);
    const BrickRef& b = f.bricks[index];
    if (b.slot == Slot::Absent || b.batch != f.batch) return;
    if (f.running && !grid.matters(f, b.bound, acc)) return;
    if (b.slot == Slot::Sampled && f.running && f.leafBound) {
        glm::ivec3 leaf;
        for (int a = 0; a < 3; ++a)
            leaf[a] = std::min(std::max(int(local[a] * grid.invLeaf), 0), f.leafAxis - 1);
        const int i = index * f.leafCount + (leaf.z * f.leafAxis + leaf.y) * f.leafAxis + leaf.x;
        if (!grid.matters(f, f.leafBound[i], acc)) return;
    }
    const float value = valueIn<T>(f, b, local);
    ++n.samples;
    project(f, acc, value, n.raises);
}

/// The pre-integrated march's link from one sample to the next: the segment end of the last
/// sample whose value was read, and which sample that was (-1: none yet).
struct Front {
    PreintegratedTable::End end;
    int k = -1;
};

/// Sample k's segment (from sample k - 1 to it): `front` when it holds sample k - 1, the
/// sample itself when k is the ray's first (a segment of one value).
inline Rgba segmentColour(const Frame& f, const Front& front, int k,
                          const PreintegratedTable::End& back) {
    const auto c = f.pre->segment(k > 0 && front.k == k - 1 ? front.end : back, back, f.segment);
    return {float(c[0]), float(c[1]), float(c[2]), float(c[3])};
}

/// marchBrick under pre-integration. A sample is skipped only when its whole segment lies in
/// one empty octree node (it and sample k - 1 in the node): every value between theirs is
/// then transparent, so the segment is exactly transparent. The first sample after a leap
/// reads sample k - 1's value first, and a brick left after a leap reads its last sample's,
/// so the next sample's segment starts where the unskipped march's would.
template <class T>
bool marchBrickPre(const Frame& f, const T* v, const std::uint32_t* words, glm::vec3 local,
                   glm::vec3 dv, glm::vec3 dir, float t0, int& k, int kEnd, Accum& acc,
                   Front& front, RayCount& n) {
    const glm::vec3 rel = local + (float(f.apron) - 0.5f);
    auto at = [&](int j) { return t0 + (float(j) + 0.5f) * f.stepMm; };
    auto leafOf = [&](int j) { return glm::ivec3(glm::floor((local + dv * at(j)) / f.leaf)); };
    // Makes sample j the front, reading its value (a sample a leap skipped).
    auto readFront = [&](int j) {
        front.end = f.pre->end(double(detail::fetch(v, f.edge, rel + dv * at(j))));
        front.k = j;
    };
    glm::ivec3 checked(-1);
    for (; k < kEnd; ++k) {
        const float t = at(k);
        if (words) {
            const glm::ivec3 leaf =
                glm::clamp(leafOf(k), glm::ivec3(0), glm::ivec3(f.leafAxis - 1));
            if (leaf != checked) {
                const int l = emptyLevel(f, words, leaf);
                const int shift = f.octDepth - l;
                const glm::ivec3 prev = leafOf(k - 1);
                const bool prevInside =
                    k == 0 || (glm::all(glm::greaterThanEqual(prev, glm::ivec3(0))) &&
                               glm::all(glm::lessThan(prev, glm::ivec3(f.leafAxis))) &&
                               (prev >> shift) == (leaf >> shift));
                if (l > 0 && prevInside) {
                    ++n.leaps;
                    k = std::max(k, std::min(sampleAfterNode(f, local, dv, t0, leaf, l), kEnd) - 1);
                    continue;
                }
                if (l == 0) checked = leaf;
            }
        }
        if (front.k != k - 1 && k > 0) readFront(k - 1);
        const Sample<T> sample(v, f.edge, rel + dv * t);
        const PreintegratedTable::End back = f.pre->end(double(sample.value));
        Rgba c = segmentColour(f, front, k, back);
        front.end = back;
        front.k = k;
        ++n.samples;
        if (c.a <= 0.0f) continue;
        if (f.shading) c = shade(f, c, sample.diffs(), dir);
        composite(acc, c);
        if (acc.t <= f.ertT) return false;
    }
    if (front.k != kEnd - 1 && kEnd > 0) readFront(kEnd - 1);
    return true;
}

} // namespace bc::render::detail
