#version 450 core
// The raycaster: one full-screen pass per front-to-back brick batch. The optical model is
// render/OPTICS.md; ReferenceRenderer.cpp is its double-precision twin. Page-table entry kinds
// (-1 absent, -2 constant, -3 deferred) are render/detail/RaycastShader.h's kPage*.
layout(binding = 0) uniform sampler3D uPool;
layout(binding = 1) uniform sampler1D uTf;
layout(binding = 2) uniform sampler2D uPrev;
layout(std430, binding = 0) readonly buffer Pages { ivec2 page[]; };
layout(std430, binding = 1) buffer Counters { uint sampleCount; uint leapCount; uint savedCount; };
// Occlusion frustums: ray starts from the last frame's proxies, and this frame's first hits.
layout(binding = 3) uniform sampler2D uStart;
layout(r32f, binding = 0) uniform image2D uFirstHit;
uniform bool uUseStart, uWriteFirstHit;
// Per brick of the level, the occupancy bits of its octree levels 1..uOctDepth (OCCUPANCY.md).
layout(std430, binding = 2) readonly buffer Occupancy { uint occ[]; };
// Distance maps (render/FineOccupancy.h): the pool of per-brick maps, a byte per cell (4 to a
// word), and per brick of the level its map's word offset (0: none, walk the octree).
layout(std430, binding = 4) readonly buffer Cells { uint cellWords[]; };
layout(std430, binding = 5) readonly buffer CellBases { uint cellBase[]; };
uniform bool uCells;
uniform float uCell;          // cell edge in voxels (a power of two)
uniform int uCellAxis;        // cells per brick axis
// Ray-guided residency: feedback[b] = 1 once an unsaturated ray enters resident brick b, and
// feedback[uBrickCount + b] = 1 once one reaches deferred brick b (planned, not uploaded). A
// ray stops at a deferred brick; uResumeAt holds the sample it goes on from in the next pass
// (-1: done). uResume passes start there; pixels with nothing to resume keep their colour.
layout(std430, binding = 3) buffer Feedback { uint feedback[]; };
layout(r32i, binding = 1) uniform iimage2D uResumeAt;
uniform bool uFeedback, uGuided, uResume;
uniform int uBrickCount;

uniform vec2 uViewport;
uniform vec3 uEye, uForward, uRight, uUp;
uniform bool uOrtho;
uniform vec3 uInvSpacing;     // voxels per mm
uniform vec3 uDims;           // voxels of the level
uniform float uStepMm;
uniform int uBrick, uApron, uEdge;
uniform ivec3 uGrid;          // bricks per axis
uniform ivec3 uSlotGrid;      // slots per axis of the pool
uniform vec3 uInvPoolSize;
uniform float uTfScale, uTfOffset;   // texel value -> TF entry position u (N - 1)
uniform int uTfEntries;
uniform float uErt;           // > 1 disables early termination
uniform bool uShading, uFirstPass, uHardwareFilter, uJitter;
uniform vec3 uGradScale;      // texel difference -> TF-domain units per voxel of the smallest spacing
uniform float uGradFade;
uniform float uAmbient, uDiffuse, uSpecular, uShininess;
uniform int uOctDepth;        // octree levels below a brick; 0 switches the second stage off
uniform int uOccWords;        // words per brick in occ[]
uniform int uLeafAxis;        // leaves per brick axis
uniform float uLeaf;          // leaf edge in voxels
// RenderOptions::mode (render/MODES.md): 0 composite, 1 maximum, 2 minimum, 3 average,
// 4 isosurface at uIso (a texel value). A projecting ray carries (value, count, finished, 0)
// from pass to pass in place of a colour; the renderer maps it through the table at the end.
uniform int uMode;
uniform float uIso;
// A maximum's or minimum's running skip (render/MODES.md): per brick of the level a bound on
// its sample values in texels (from above for a maximum, below for a minimum), then with
// uLeafBounds per octree leaf of each brick (brick * leaves + leaf, after the bricks').
layout(std430, binding = 6) readonly buffer RunningBounds { float runBound[]; };
uniform bool uRunning, uLeafBounds;
// RenderOptions::clip: the crop box and the planes (normal, offset: kept where
// dot(normal, x) + offset >= 0), world mm.
uniform bool uCropped;
uniform vec3 uCropMin, uCropMax;
uniform int uPlaneCount;
uniform vec4 uPlanes[6];
// Capping (render/MODES.md): a ray entering through a cut draws the face there first, its
// opacity the table's raised to uCapPower (1 / the step in voxels). A ray waiting for the
// face's brick (guided) resumes from uResumeAt = -(k + 2).
uniform bool uCap;
uniform float uCapPower;

out vec4 outColor;

// Linear between the two neighbouring table entries, with full-precision weights (texture
// filtering hardware may quantise them, which would blend in entries the skip test excluded).
vec4 classify(float texelValue) {
    float u = clamp(texelValue * uTfScale + uTfOffset, 0.0, float(uTfEntries - 1));
    int i = min(int(u), uTfEntries - 2);
    return mix(texelFetch(uTf, i, 0), texelFetch(uTf, i + 1, 0), u - float(i));
}

ivec3 slotOrigin(int slot) {
    return ivec3(slot % uSlotGrid.x, (slot / uSlotGrid.x) % uSlotGrid.y, slot / (uSlotGrid.x * uSlotGrid.y)) * uEdge;
}

// Trilinear interpolation at q, a position in slot texel space less one half (so voxel j of
// the stored brick sits at q = j), clamped to the slot. Positions stay slot-relative: adding
// the slot's origin before splitting off the fraction would round q differently in each slot.
// The weights are full precision from 8 texel fetches; filtering hardware quantises them (8
// bits on llvmpipe and NVIDIA), so uHardwareFilter trades that exactness for one fetch.
float fetch(vec3 q, ivec3 slot) {
    q = clamp(q, vec3(0.0), vec3(float(uEdge - 1)));
    if (uHardwareFilter) return texture(uPool, (vec3(slot) + q + 0.5) * uInvPoolSize).r;
    vec3 b = floor(q);
    vec3 f = q - b;
    ivec3 i0 = slot + ivec3(b);
    ivec3 i1 = slot + min(ivec3(b) + 1, ivec3(uEdge - 1));
    float c00 = mix(texelFetch(uPool, i0, 0).r, texelFetch(uPool, ivec3(i1.x, i0.y, i0.z), 0).r, f.x);
    float c10 = mix(texelFetch(uPool, ivec3(i0.x, i1.y, i0.z), 0).r, texelFetch(uPool, ivec3(i1.x, i1.y, i0.z), 0).r, f.x);
    float c01 = mix(texelFetch(uPool, ivec3(i0.x, i0.y, i1.z), 0).r, texelFetch(uPool, ivec3(i1.x, i0.y, i1.z), 0).r, f.x);
    float c11 = mix(texelFetch(uPool, ivec3(i0.x, i1.y, i1.z), 0).r, texelFetch(uPool, i1, 0).r, f.x);
    return mix(mix(c00, c10, f.y), mix(c01, c11, f.y), f.z);
}

vec4 shade(vec4 c, vec3 q, ivec3 slot, vec3 dir) {
    vec3 g = vec3(fetch(q + vec3(1, 0, 0), slot) - fetch(q - vec3(1, 0, 0), slot),
                  fetch(q + vec3(0, 1, 0), slot) - fetch(q - vec3(0, 1, 0), slot),
                  fetch(q + vec3(0, 0, 1), slot) - fetch(q - vec3(0, 0, 1), slot)) * uGradScale;
    float len = length(g);
    if (len <= 0.0) return c;
    float diff = abs(dot(g / len, dir));
    vec3 lit = c.rgb * (uAmbient + uDiffuse * diff) + uSpecular * pow(diff, uShininess);
    return vec4(mix(c.rgb, lit, clamp(len / uGradFade, 0.0, 1.0)), c.a);
}

void composite(inout vec4 acc, vec4 c) {
    acc.rgb += (1.0 - acc.a) * c.a * c.rgb;
    acc.a += (1.0 - acc.a) * c.a;
}

// Takes texel value v into a projecting ray; false once no further value can change its
// colour (early termination: past the table's last entry for a maximum, before its first for
// a minimum, where classify() clamps).
bool project(inout vec4 acc, float v) {
    if (uMode == 3) { acc.r += v; acc.g += 1.0; return true; }
    if (acc.g == 0.0 || (uMode == 1 ? v > acc.r : v < acc.r)) acc.r = v;
    acc.g += 1.0;
    float u = acc.r * uTfScale + uTfOffset;
    if (uErt <= 1.0 && (uMode == 1 ? u >= float(uTfEntries - 1) : u <= 0.0)) { acc.b = 1.0; return false; }
    return true;
}

// Whether samples whose values `bound` bounds could change a maximum or minimum so far: not
// when all are at or below the maximum (at or above the minimum) and the ray has a value.
bool passes(float bound, vec4 acc) {
    return acc.g == 0.0 || (uMode == 1 ? bound > acc.r : bound < acc.r);
}

// Whether the ray is done: opaque enough (composite), hit (isosurface), finished (projections).
// BC_MODES (ShaderPrograms.cpp): 0 builds the composite, uncut program, 1 the modes and cuts.
#if BC_MODES
bool finished(vec4 acc) {
    return uMode == 0 ? acc.a >= uErt : uMode == 4 ? acc.a > 0.0 : acc.b > 0.0;
}
#else
bool finished(vec4 acc) {
    return acc.a >= uErt;
}
#endif

// The isosurface's hit on the step from sample k - 1 (below uIso) to sample k at parameter t
// (at or above it), refined by 12 bisections within the slot's voxels; sample k itself when it
// is the ray's first kept sample (the volume's box or the clip cuts the surface there).
float isoHit(int kFirst, int k, float t, float t0, vec3 rel, vec3 dv, ivec3 slot) {
    if (k == kFirst) return t;
    float lo = t0 + (float(k - 1) + 0.5) * uStepMm, hi = t;
    for (int i = 0; i < 12; ++i) {
        float mid = 0.5 * (lo + hi);
        if (fetch(rel + dv * mid, slot) >= uIso) hi = mid; else lo = mid;
    }
    return 0.5 * (lo + hi);
}

// The isosurface's colour, opaque: the table's at uIso.
vec4 isoColour() {
    return vec4(classify(uIso).rgb, 1.0);
}

// Narrows [ta, tb] to what the crop box and the planes keep (world origin o, direction d);
// `entry`: the unit normal of the face that raises ta (as it was where none does).
void clipInterval(vec3 o, vec3 d, inout float ta, inout float tb, inout vec3 entry) {
    if (uCropped) {
        for (int a = 0; a < 3; ++a) {
            if (d[a] == 0.0) { if (o[a] < uCropMin[a] || o[a] > uCropMax[a]) tb = -3.0e38; continue; }
            float u0 = (uCropMin[a] - o[a]) / d[a], u1 = (uCropMax[a] - o[a]) / d[a];
            if (min(u0, u1) > ta) { entry = vec3(0.0); entry[a] = u0 < u1 ? 1.0 : -1.0; }
            ta = max(ta, min(u0, u1));
            tb = min(tb, max(u0, u1));
        }
    }
    for (int i = 0; i < uPlaneCount; ++i) {
        float nd = dot(uPlanes[i].xyz, d), no = dot(uPlanes[i].xyz, o) + uPlanes[i].w;
        if (nd == 0.0) { if (no < 0.0) tb = -3.0e38; continue; }
        float t = -no / nd;
        if (nd > 0.0) { if (t > ta) entry = uPlanes[i].xyz; ta = max(ta, t); } else tb = min(tb, t);
    }
}

// A cut's face at texel value v (capping), `diff` = |cos| between its normal and the ray:
// composite, the table's colour and its opacity for one voxel's length; isosurface, at or
// above uIso, the surface's colour, opaque. Transparent where there is no face.
vec4 capColour(float v, float diff) {
    vec4 c;
    if (uMode == 4) {
        if (v < uIso) return vec4(0.0);
        c = isoColour();
    } else {
        c = classify(v);
        if (c.a <= 0.0) return vec4(0.0);
        c.a = min(1.0 - pow(1.0 - c.a, uCapPower), 1.0);
    }
    if (uShading) c.rgb = c.rgb * (uAmbient + uDiffuse * diff) + uSpecular * pow(diff, uShininess);
    return c;
}

// The coarsest octree level (1..uOctDepth) whose node holding `leaf` is empty, or 0.
int emptyLevel(int base, ivec3 leaf) {
    int first = 0;
    for (int l = 1; l <= uOctDepth; ++l) {
        ivec3 n = leaf >> (uOctDepth - l);
        int s = 1 << l;
        int bit = first + (n.z * s + n.y) * s + n.x;
        if (((occ[base + (bit >> 5)] >> uint(bit & 31)) & 1u) == 0u) return l;
        first += s * s * s;
    }
    return 0;
}

// The ray parameter where p(t) = p0 + dv t leaves the axis-aligned box [lo, lo + size).
float exitParameter(vec3 p0, vec3 dv, vec3 lo, float size) {
    float t = 3.0e38;
    for (int a = 0; a < 3; ++a) {
        if (dv[a] > 0.0) t = min(t, (lo[a] + size - p0[a]) / dv[a]);
        else if (dv[a] < 0.0) t = min(t, (lo[a] - p0[a]) / dv[a]);
    }
    return t;
}

void main() {
    vec4 acc = uFirstPass ? vec4(0.0) : texelFetch(uPrev, ivec2(gl_FragCoord.xy), 0);
    int resumeAt = uResume ? imageLoad(uResumeAt, ivec2(gl_FragCoord.xy)).r : 0;
    // Whether the ray still has its cut's face to draw: a pass of batches draws it where the
    // face's brick is in the batch; a resumed pass where the ray waited for it.
    bool capPending = !uResume || resumeAt <= -2;
    if (resumeAt <= -2) resumeAt = -resumeAt - 2;
    if (finished(acc) || resumeAt < 0) { outColor = acc; return; }
    vec2 s = 2.0 * gl_FragCoord.xy / uViewport - 1.0;
    vec3 o = uOrtho ? uEye + s.x * uRight + s.y * uUp : uEye;
    vec3 d = uOrtho ? uForward : normalize(uForward + s.x * uRight + s.y * uUp);
    vec3 ov = o * uInvSpacing, dv = d * uInvSpacing;   // voxel position at t mm: ov + t dv

    // Box [0, dims] in voxel space; parallel rays inside a slab stay inside.
    float t0 = 0.0, t1 = 3.0e38;
    for (int a = 0; a < 3; ++a) {
        if (dv[a] == 0.0) { if (ov[a] < 0.0 || ov[a] > uDims[a]) { outColor = acc; return; } continue; }
        float ta = -ov[a] / dv[a], tb = (uDims[a] - ov[a]) / dv[a];
        t0 = max(t0, min(ta, tb));
        t1 = min(t1, max(ta, tb));
    }
    float tIn = t0, tOut = t1; // the segment kept (a maximum's or minimum's ends)
    // RenderOptions::jitter: samples from the entry + (k + rayJitter()) step (RenderTypes.cpp,
    // the same integers; y counted from the top as the CPU's pixels are).
    if (uJitter) {
        uint x = uint(gl_FragCoord.x), y = uint(uViewport.y) - 1u - uint(gl_FragCoord.y);
        uint h = x * 3242174889u + y * 2447445414u;
        t0 += (float(h >> 8u) * (1.0 / 16777216.0) - 0.5) * uStepMm;
    }
    int total = int(ceil((t1 - t0) / uStepMm - 0.5));
    if (total <= 0) { outColor = acc; return; }
    // A crop or clip keeps samples [kFirst, total) of the same lattice.
    int kFirst = 0;
    uint taken = 0u, leaps = 0u;
#if BC_MODES
    if (uCropped || uPlaneCount > 0) {
        float ta = -3.0e38, tb = 3.0e38;
        vec3 cutNormal = vec3(0.0);
        clipInterval(o, d, ta, tb, cutNormal);
        if (!(ta <= tb)) { outColor = acc; return; }
        float kb = ceil((tb - t0) / uStepMm - 0.5);
        if (kb < float(total)) total = kb > 0.0 ? int(kb) : 0;
        float ka = ceil((ta - t0) / uStepMm - 0.5);
        if (ka > 0.0) kFirst = ka < float(total) ? int(ka) : total;
        if (kFirst >= total) { outColor = acc; return; }
        bool cut = ta > tIn;
        tIn = max(tIn, ta);
        tOut = min(tOut, tb);
        if (uCap && cut && capPending) { // the face, before every sample of the ray
            vec3 p = ov + dv * tIn;
            ivec3 c = clamp(ivec3(floor(p / float(uBrick))), ivec3(0), uGrid - 1);
            int b = (c.z * uGrid.y + c.y) * uGrid.x + c.x;
            ivec2 e = page[b];
            if (e.x == -3) { // deferred: ask for it and wait, drawing nothing beyond
                feedback[uBrickCount + b] = 1u;
                imageStore(uResumeAt, ivec2(gl_FragCoord.xy), ivec4(-max(resumeAt, kFirst) - 2));
                outColor = acc;
                return;
            }
            if (e.x != -1) { // absent: no visible value, none at or above uIso
                if (uFeedback && e.x >= 0) feedback[b] = 1u;
                float v = e.x == -2 ? intBitsToFloat(e.y)
                                    : fetch(p - vec3(c * uBrick) + (float(uApron) - 0.5), slotOrigin(e.x));
                ++taken;
                // In front of whatever the ray holds: the face is its front-most layer.
                vec4 c = capColour(v, abs(dot(cutNormal, d)));
                acc = vec4(c.a * c.rgb + (1.0 - c.a) * acc.rgb, c.a + (1.0 - c.a) * acc.a);
                if (finished(acc)) {
                    atomicAdd(sampleCount, taken);
                    if (uGuided) imageStore(uResumeAt, ivec2(gl_FragCoord.xy), ivec4(-1));
                    outColor = acc;
                    return;
                }
            }
        }
    }
#endif

    // Occlusion frustums: no sample before the proxies' nearest face can be non-empty. The
    // lattice of sample positions stays that of the box entry; the start only drops samples.
    int k = max(resumeAt, kFirst);
    if (uUseStart && !uResume) {
        float ts = texelFetch(uStart, ivec2(gl_FragCoord.xy), 0).r;
        k = ts >= 1.0e37 ? total : clamp(int(floor((ts - t0) / uStepMm - 0.5)) - 1, 0, total);
        if (k > 0) atomicAdd(savedCount, uint(k));
        if (k >= total) { outColor = acc; return; }
    }
    float tHit = 3.0e38; // this pass's first sample in an occupied leaf or brick

    // Brick DDA: sample k (at t0 + (k + 0.5) step) belongs to the brick whose interval holds it.
    vec3 pin = ov + dv * (t0 + float(k) * uStepMm);
    ivec3 cell = clamp(ivec3(floor(pin / float(uBrick))), ivec3(0), uGrid - 1);
    ivec3 stepDir = ivec3(sign(dv));
    // Each exit parameter comes from its plane directly (not by adding brick widths up), so a
    // ray resumed in a later pass meets the same brick boundaries as one marched throughout.
    vec3 tMax;
    for (int a = 0; a < 3; ++a)
        tMax[a] = stepDir[a] == 0 ? 3.0e38
                                  : (float((cell[a] + (stepDir[a] > 0 ? 1 : 0)) * uBrick) - ov[a]) / dv[a];
    int suspendAt = -1;
    while (k < total) {
        float tOut = min(min(tMax.x, tMax.y), tMax.z);
        int kEnd = min(total, int(ceil((tOut - t0) / uStepMm - 0.5)));
        int brickIndex = (cell.z * uGrid.y + cell.y) * uGrid.x + cell.x;
        ivec2 e = page[brickIndex];
#if BC_MODES
        if (uRunning && e.x != -1 && kEnd > k && !passes(runBound[brickIndex], acc)) {
            ++leaps; // none of its samples can change the value: not even a deferred one's
            e.x = -1;
        }
#endif
        if (e.x == -3 && kEnd > k) { // deferred: wait for it, drawing nothing beyond
            feedback[uBrickCount + brickIndex] = 1u;
            suspendAt = k;
            break;
        }
        if (e.x >= 0 && kEnd > k) {
            if (uFeedback) feedback[brickIndex] = 1u;
            ivec3 slot = slotOrigin(e.x);
            vec3 local = ov - vec3(cell * uBrick);   // brick-local voxel position at t = 0
            vec3 rel = local + (float(uApron) - 0.5);
            int base = brickIndex * uOccWords;
            uint map = uCells ? cellBase[brickIndex] : 0u;
            ivec3 checkedLeaf = ivec3(-1);           // the last leaf found to be sampled
#if BC_MODES
            ivec3 boundLeaf = ivec3(-1);             // the leaf whose running bound is read
            float leafBound = 0.0;
#endif
            for (; k < kEnd; ++k) {
                float t = t0 + (float(k) + 0.5) * uStepMm;
                vec3 q = rel + dv * t;
                if (map != 0u) {
                    // The map decides in place of the octree: a cell at distance d > 0 is the
                    // centre of an empty cube of 2d - 1 cells (corner (c - d) cell + 1/2).
                    ivec3 c = clamp(ivec3(floor((local + dv * t + (uCell - 0.5)) * (1.0 / uCell))),
                                    ivec3(0), ivec3(uCellAxis - 1));
                    uint i = uint((c.z * uCellAxis + c.y) * uCellAxis + c.x);
                    int dist = int((cellWords[map + (i >> 2u)] >> ((i & 3u) * 8u)) & 255u);
                    if (dist > 0) {
                        vec3 lo = vec3(c - dist) * uCell + 0.5;
                        float tExit = exitParameter(local, dv, lo, float(2 * dist - 1) * uCell);
                        int kNext = int(ceil((tExit - t0) / uStepMm - 0.5));
                        ++leaps;
                        k = max(k, min(kNext, kEnd) - 1); // the loop's ++k reaches kNext
                        continue;
                    }
                } else if (uOctDepth > 0) {
                    // Second stage: leap over the largest empty octree node holding the sample.
                    ivec3 leaf = clamp(ivec3(floor((local + dv * t) / uLeaf)), ivec3(0), ivec3(uLeafAxis - 1));
                    if (leaf != checkedLeaf) {
                        int l = emptyLevel(base, leaf);
                        if (l > 0) {
                            float size = uLeaf * float(1 << (uOctDepth - l));
                            vec3 lo = vec3(leaf >> (uOctDepth - l)) * size;
                            float tExit = exitParameter(local, dv, lo, size);
                            int kNext = int(ceil((tExit - t0) / uStepMm - 0.5));
                            ++leaps;
                            k = max(k, min(kNext, kEnd) - 1); // the loop's ++k reaches kNext
                            continue;
                        }
                        checkedLeaf = leaf;
                    }
                }
#if BC_MODES
                if (uRunning && uLeafBounds && acc.g > 0.0) { // the leaf's bound, as the brick's
                    ivec3 leaf = clamp(ivec3(floor((local + dv * t) / uLeaf)), ivec3(0),
                                       ivec3(uLeafAxis - 1));
                    if (leaf != boundLeaf) { // read once per leaf, compared at every sample
                        int leaves = uLeafAxis * uLeafAxis * uLeafAxis;
                        int i = brickIndex * leaves + (leaf.z * uLeafAxis + leaf.y) * uLeafAxis + leaf.x;
                        leafBound = runBound[uBrickCount + i];
                        boundLeaf = leaf;
                    }
                    if (!passes(leafBound, acc)) {
                        float tExit = exitParameter(local, dv, vec3(leaf) * uLeaf, uLeaf);
                        int kNext = int(ceil((tExit - t0) / uStepMm - 0.5));
                        ++leaps;
                        k = max(k, min(kNext, kEnd) - 1); // the loop's ++k reaches kNext
                        continue;
                    }
                }
#endif
                tHit = min(tHit, t);
                float value = fetch(q, slot);
                ++taken;
#if BC_MODES
                if (uMode == 4) {
                    if (value < uIso) continue;
                    vec3 h = rel + dv * isoHit(kFirst, k, t, t0, rel, dv, slot);
                    acc = uShading ? shade(isoColour(), h, slot, d) : isoColour();
                    break;
                }
                if (uMode != 0) {
                    if (!project(acc, value)) break;
                    continue;
                }
#endif
                vec4 c = classify(value);
                if (c.a <= 0.0) continue;
                if (uShading) c = shade(c, q, slot, d);
                composite(acc, c);
                if (acc.a >= uErt) break;
            }
#if BC_MODES
        } else if (e.x == -2 && kEnd > k && uMode != 0) {
            // A brick of one value: a projection takes it once a sample; an isosurface is hit
            // at its first sample or not at all (no gradient: the surface unshaded).
            float value = intBitsToFloat(e.y);
            if (uMode == 4) {
                if (value >= uIso) { ++taken; acc = isoColour(); }
                else { taken += uint(kEnd - k); k = kEnd; }
            } else {
                for (; k < kEnd; ++k) {
                    ++taken;
                    if (!project(acc, value)) break;
                }
            }
#endif
        } else if (e.x == -2 && kEnd > k) {
            vec4 c = classify(intBitsToFloat(e.y));
            if (c.a > 0.0) tHit = min(tHit, t0 + (float(k) + 0.5) * uStepMm);
            if (c.a <= 0.0) { taken += uint(kEnd - k); k = kEnd; }
            for (; k < kEnd; ++k) {
                ++taken;
                if (c.a <= 0.0) continue;
                composite(acc, c);
                if (acc.a >= uErt) break;
            }
        }
        if (finished(acc)) break;
        k = max(k, kEnd);
        int a = tMax.x <= tMax.y ? (tMax.x <= tMax.z ? 0 : 2) : (tMax.y <= tMax.z ? 1 : 2);
        cell[a] += stepDir[a];
        tMax[a] = (float((cell[a] + (stepDir[a] > 0 ? 1 : 0)) * uBrick) - ov[a]) / dv[a];
        if (cell[a] < 0 || cell[a] >= uGrid[a]) break;
    }
#if BC_MODES
    // A maximum's or minimum's segment ends (render/MODES.md), in the passes whose bricks hold
    // them: a brick drawn now gives its value (given again in a later pass, it changes
    // nothing); a deferred one is asked for, the ray waiting after its last sample.
    if ((uMode == 1 || uMode == 2) && !finished(acc)) {
        for (int end = 0; end < 2; ++end) {
            vec3 p = ov + dv * (end == 0 ? tIn : tOut);
            ivec3 c = clamp(ivec3(floor(p / float(uBrick))), ivec3(0), uGrid - 1);
            int b = (c.z * uGrid.y + c.y) * uGrid.x + c.x;
            ivec2 e = page[b];
            if (e.x == -1 || (uRunning && !passes(runBound[b], acc))) continue;
            if (e.x == -3) {
                if (suspendAt < 0) { feedback[uBrickCount + b] = 1u; suspendAt = total; }
                continue;
            }
            ++taken;
            if (e.x == -2) { project(acc, intBitsToFloat(e.y)); continue; }
            if (uFeedback) feedback[b] = 1u;
            project(acc, fetch(p - vec3(c * uBrick) + (float(uApron) - 0.5), slotOrigin(e.x)));
        }
    }
#endif
    if (uWriteFirstHit && tHit < 1.0e37) {
        ivec2 px = ivec2(gl_FragCoord.xy);
        if (tHit < imageLoad(uFirstHit, px).r) imageStore(uFirstHit, px, vec4(tHit));
    }
    if (uGuided) imageStore(uResumeAt, ivec2(gl_FragCoord.xy), ivec4(suspendAt));
    atomicAdd(sampleCount, taken);
    if (leaps > 0u) atomicAdd(leapCount, leaps);
    outColor = acc;
}
