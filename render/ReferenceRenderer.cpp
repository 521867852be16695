#include "render/ReferenceRenderer.h"

#include "brickstore/BrickCache.h"
#include "brickstore/BrickStore.h"
#include "brickstore/StoreVolume.h"
#include "render/BrickPlan.h"
#include "render/TransferFunction.h"

#include <tbb/parallel_for.h>

#include <algorithm>
#include <atomic>
#include <chrono>
#include <cmath>
#include <optional>
#include <thread>

#include <glm/geometric.hpp>

namespace bc::render {

ReferenceVolume::ReferenceVolume(const brickstore::BrickStore& store, std::uint32_t level) {
    auto source = brickstore::openStoreLevel(store, level);
    const auto& info = source->info();
    mDims = info.dims;
    const std::uint64_t sliceVoxels = mDims[0] * mDims[1];
    mVoxels.resize(sliceVoxels * mDims[2]);
    std::vector<std::byte> slice(info.sliceBytes());
    for (std::uint64_t z = 0; z < mDims[2]; ++z) {
        source->readSlices(1, slice);
        for (std::uint64_t i = 0; i < sliceVoxels; ++i)
            mVoxels[z * sliceVoxels + i] =
                float(brickstore::voxelAsDouble(info.type, slice.data(), i));
    }
}

namespace {

/// Trilinear value at continuous voxel position p, clamped to the edge of a volume of `dims`;
/// `at(x, y, z)` reads a voxel. One function for the whole level and for bricks, so both give
/// the same double to the bit.
template <class At>
double trilinear(const std::array<std::uint64_t, 3>& dims, double px, double py, double pz,
                 const At& at) {
    const double p[3] = {px - 0.5, py - 0.5, pz - 0.5};
    std::int64_t i0[3], i1[3];
    double w[3];
    for (int a = 0; a < 3; ++a) {
        const double f = std::floor(p[a]);
        const auto hi = std::int64_t(dims[a]) - 1;
        w[a] = p[a] - f;
        i0[a] = std::clamp<std::int64_t>(std::int64_t(f), 0, hi);
        i1[a] = std::clamp<std::int64_t>(std::int64_t(f) + 1, 0, hi);
    }
    auto lerp = [](double a, double b, double t) { return a + (b - a) * t; };
    const double c00 = lerp(at(i0[0], i0[1], i0[2]), at(i1[0], i0[1], i0[2]), w[0]);
    const double c10 = lerp(at(i0[0], i1[1], i0[2]), at(i1[0], i1[1], i0[2]), w[0]);
    const double c01 = lerp(at(i0[0], i0[1], i1[2]), at(i1[0], i0[1], i1[2]), w[0]);
    const double c11 = lerp(at(i0[0], i1[1], i1[2]), at(i1[0], i1[1], i1[2]), w[0]);
    return lerp(lerp(c00, c10, w[1]), lerp(c01, c11, w[1]), w[2]);
}

} // namespace

double ReferenceVolume::sample(double px, double py, double pz) const {
    return trilinear(mDims, px, py, pz, [&](std::int64_t x, std::int64_t y, std::int64_t z) {
        return double(mVoxels[(std::uint64_t(z) * mDims[1] + std::uint64_t(y)) * mDims[0] +
                              std::uint64_t(x)]);
    });
}

namespace {

struct RayContext {
    const TransferFunctionTable& table;
    const LevelGeometry& geometry;
    const RenderOptions& options;
    glm::dvec3 gradScale; ///< value difference -> TF-domain units per voxel of the smallest spacing
    const PreintegratedTable* pre = nullptr; ///< with RenderOptions::preintegrate
};

/// Blinn-Phong under the headlight: `diff` = |cos| between the normal and the ray, the lit
/// colour weighted by w in [0, 1] against the unlit one.
std::array<double, 4> light(const std::array<double, 4>& rgba, double diff, double w) {
    const double spec = ShadingModel::kSpecular * std::pow(diff, ShadingModel::kShininess);
    std::array<double, 4> out = rgba;
    for (int i = 0; i < 3; ++i) {
        const double lit =
            rgba[i] * (ShadingModel::kAmbient + ShadingModel::kDiffuse * diff) + spec;
        out[i] = rgba[i] + (lit - rgba[i]) * w;
    }
    return out;
}

template <class Volume>
std::array<double, 4> shade(const RayContext& c, const Volume& v, const std::array<double, 4>& rgba,
                            const glm::dvec3& p, const glm::dvec3& dir) {
    const glm::dvec3 g = glm::dvec3(v.sample(p.x + 1, p.y, p.z) - v.sample(p.x - 1, p.y, p.z),
                                    v.sample(p.x, p.y + 1, p.z) - v.sample(p.x, p.y - 1, p.z),
                                    v.sample(p.x, p.y, p.z + 1) - v.sample(p.x, p.y, p.z - 1)) *
                         c.gradScale;
    const double len = glm::length(g);
    if (len <= 0.0) return rgba;
    return light(rgba, std::abs(glm::dot(g / len, dir)),
                 std::clamp(len / ShadingModel::kGradientFade, 0.0, 1.0));
}

/// A ray between passes: its colour so far and its next sample.
struct RayProgress {
    std::array<double, 4> acc{0, 0, 0, 0};
    std::int64_t k = 0;
    bool done = false;
    PreintegratedTable::End front; ///< pre-integration: sample k - 1's (k > 0)
    /// The projections: the largest, smallest or summed value of the samples so far, and how
    /// many there were (0: none yet).
    double value = 0.0;
    std::uint64_t count = 0;
    bool capped = false; ///< capping: the cut face at its start is drawn (or has none)
};

/// Where along the ray the value first reaches `iso` between parameters lo (below it) and
/// hi (at or above it): IsoModel's bisections of the field `at(t)`.
template <class At> double refineIso(double lo, double hi, double iso, const At& at) {
    for (int i = 0; i < IsoModel::kBisections; ++i) {
        const double mid = 0.5 * (lo + hi);
        (at(mid) >= iso ? hi : lo) = mid;
    }
    return 0.5 * (lo + hi);
}

/// Takes sample `value` into a projecting ray (BlendMode Maximum, Minimum, Average).
void project(BlendMode mode, double value, RayProgress& s) {
    if (mode == BlendMode::Average)
        s.value += value;
    else if (s.count == 0 || (mode == BlendMode::Maximum ? value > s.value : value < s.value))
        s.value = value;
    ++s.count;
}

/// A projecting ray's colour: its value mapped through `table` (the function as authored),
/// premultiplied; transparent without samples.
void resolveProjection(BlendMode mode, const TransferFunctionTable& table, RayProgress& s) {
    if (s.count == 0) return;
    const double v = mode == BlendMode::Average ? s.value / double(s.count) : s.value;
    const auto f = table.lookup(v);
    s.acc = {double(f[0]) * f[3], double(f[1]) * f[3], double(f[2]) * f[3], double(f[3])};
}

/// Capping (render/MODES.md): the face of the cut where the ray enters, at voxel position p
/// with unit normal `normal` (world), drawn into the ray before any of its samples. Composite:
/// the table's colour at the value there and its opacity for one voxel's length (the table's
/// is for the step: 1 - (1 - a)^(1 / step)); isosurface: where the value is at or above the
/// iso value, the surface's colour, opaque, and the ray is done. Both shaded by the normal.
template <class Volume>
void takeCap(const RayContext& c, const Volume& v, const glm::dvec3& p, const glm::dvec3& normal,
             const glm::dvec3& dir, RayProgress& s, std::uint64_t& samples) {
    const double value = v.sample(p.x, p.y, p.z);
    ++samples;
    const double diff = std::abs(glm::dot(normal, dir));
    if (c.options.mode == BlendMode::Isosurface) {
        if (value < c.options.isoValue) return;
        const auto f = c.table.lookup(c.options.isoValue);
        std::array<double, 4> rgba{f[0], f[1], f[2], 1.0};
        s.acc = c.options.shading ? light(rgba, diff, 1.0) : rgba;
        s.done = true;
        return;
    }
    const auto f = c.table.lookup(value);
    const double a = -std::expm1(std::log1p(-double(f[3])) / c.options.stepVoxels);
    if (!(a > 0.0)) return;
    std::array<double, 4> rgba{f[0], f[1], f[2], std::min(a, 1.0)};
    if (c.options.shading) rgba = light(rgba, diff, 1.0);
    // In front of whatever the ray holds (nothing, but for a pass order that rounding could
    // turn): the face is its front-most layer.
    const double keep = 1.0 - rgba[3];
    for (int i = 0; i < 3; ++i)
        s.acc[i] = rgba[3] * rgba[i] + keep * s.acc[i];
    s.acc[3] = rgba[3] + keep * s.acc[3];
}

/// Marches one ray from progress.k on; `volumeAt(p)` is the volume that samples point p, or
/// nullptr when it is not drawn in this pass (the ray stops there and goes on in a later one).
/// Adds the ray's samples to `samples` when it ends, and to `oracle` those with non-zero
/// opacity taken before the ray's opacity reaches the early termination threshold (what an
/// ideal skipping renderer would have to take).
/// Pixel (x, y)'s samples start at the box entry + (k + rayJitter(x, y)) step under
/// RenderOptions::jitter (the raycasters' offsets, in double), else + (k + 1/2) step.
template <class VolumeAt>
void marchRay(const RayContext& c, const Ray& ray, std::uint32_t x, std::uint32_t y,
              const VolumeAt& volumeAt, RayProgress& s, std::uint64_t& samples,
              std::uint64_t& oracle) {
    const LevelGeometry& g = c.geometry;
    const glm::dvec3 ov = ray.origin / g.spacing, dv = ray.direction / g.spacing;
    const Box voxelBox{glm::dvec3(0.0),
                       glm::dvec3(double(g.dims[0]), double(g.dims[1]), double(g.dims[2]))};
    auto [t0, t1] = intersectBox({ov, dv}, voxelBox);
    t0 = std::max(t0, 0.0);
    double tIn = t0, tOut = t1; // the segment kept, for samplesEnds() and capping
    bool cut = false;           // whether tIn is a cut inside the box (capsCuts())
    glm::dvec3 cutNormal(0.0);
    const double step = c.options.stepVoxels * g.minSpacing();
    if (c.options.jitter) t0 += (double(rayJitter(x, y)) - 0.5) * step;
    const double count = std::ceil((t1 - t0) / step - 0.5);
    auto total = count > 0 ? std::int64_t(count) : 0;
    std::int64_t first = 0;
    if (c.options.clip.any()) { // samples [first, total) of the same lattice are kept
        const auto [ta, tb] = c.options.clip.interval(ray.origin, ray.direction, &cutNormal);
        const double last = ta <= tb ? std::ceil((tb - t0) / step - 0.5) : 0.0;
        const double from = std::ceil((ta - t0) / step - 0.5);
        if (last < double(total)) total = last > 0 ? std::int64_t(last) : 0;
        if (from > 0.0) first = from < double(total) ? std::int64_t(from) : total;
        s.k = std::max(s.k, first);
        cut = ta > tIn;
        tIn = std::max(tIn, ta);
        tOut = std::min(tOut, tb);
    }
    const BlendMode mode = c.options.mode;
    // The cut's face, in the pass that draws its point: the batches go front to back, so that
    // is no later than the pass of the ray's first sample (a ray done with its samples may
    // still wait for it: its face may lie in a brick of a later pass that holds none of them).
    if (cut && !s.capped && first < total && capsCuts(c.options)) {
        const glm::dvec3 p = ov + dv * tIn;
        if (const auto* volume = volumeAt(p)) {
            s.capped = true;
            takeCap(c, *volume, p, cutNormal, ray.direction, s, samples);
            if (s.done) return;
        }
    }
    // The segment's ends, each in the pass that draws its point (before the lattice's end: the
    // exit's brick may come in a later pass than the ray's last sample).
    bool endTaken = false;
    if (samplesEnds(mode) && first < total)
        for (const double t : {tIn, tOut}) {
            const glm::dvec3 p = ov + dv * t;
            if (const auto* volume = volumeAt(p)) {
                project(mode, volume->sample(p.x, p.y, p.z), s);
                ++samples;
                endTaken = true;
            }
        }
    if (s.done) {
        if (endTaken) resolveProjection(mode, c.table, s);
        return;
    }
    std::array<double, 4>& acc = s.acc;
    auto tOf = [&](std::int64_t k) { return t0 + (double(k) + 0.5) * step; };
    for (std::int64_t k = s.k; k < total; ++k) {
        const glm::dvec3 p = ov + dv * tOf(k);
        const auto* volume = volumeAt(p);
        if (volume == nullptr) {
            s.k = k;
            return;
        }
        const double value = volume->sample(p.x, p.y, p.z);
        if (mode == BlendMode::Isosurface) {
            if (value < c.options.isoValue) continue;
            // The first sample at or above the value: the surface lies since the one before
            // (the first sample kept: the surface is where the volume or the clip cuts it).
            const double t = k == first
                                 ? tOf(k)
                                 : refineIso(tOf(k - 1), tOf(k), c.options.isoValue, [&](double u) {
                                       const glm::dvec3 q = ov + dv * u;
                                       return volume->sample(q.x, q.y, q.z);
                                   });
            const glm::dvec3 hit = ov + dv * t;
            const auto f = c.table.lookup(c.options.isoValue);
            std::array<double, 4> rgba{f[0], f[1], f[2], 1.0};
            if (c.options.shading) rgba = shade(c, *volume, rgba, hit, ray.direction);
            acc = rgba;
            samples += std::uint64_t(k + 1);
            s.done = true;
            return;
        }
        if (mode != BlendMode::Composite) {
            project(mode, value, s);
            continue;
        }
        std::array<double, 4> rgba;
        if (c.pre) {
            // The segment from sample k - 1 to k (the first sample's: its value alone).
            const PreintegratedTable::End back = c.pre->end(value);
            rgba = c.pre->segment(k == 0 ? back : s.front, back, c.options.stepVoxels);
            s.front = back;
        } else {
            const auto f = c.table.lookup(value);
            rgba = {f[0], f[1], f[2], f[3]};
        }
        if (rgba[3] <= 0.0) continue;
        if (acc[3] < c.options.ertThreshold) ++oracle;
        if (c.options.shading) rgba = shade(c, *volume, rgba, p, ray.direction);
        const double w = (1.0 - acc[3]) * rgba[3];
        for (int i = 0; i < 3; ++i)
            acc[i] += w * rgba[i];
        acc[3] += w;
    }
    samples += std::uint64_t(total);
    s.done = true;
    if (isProjection(mode)) resolveProjection(mode, c.table, s);
}

/// Runs `pixel(x, y, i, samples, oracle)` for every pixel of `region` (i: its index in the
/// region, row by row) on `threads` threads (0 = all cores). Pixels are shared out in runs of a
/// few of one row, so a region of a few pixels (a slice of a frame at a tiny step, as the
/// daemon draws long frames) still keeps every core busy.
template <class Pixel>
void forEachPixel(unsigned threads, const PixelRect& region, const Pixel& pixel,
                  FrameStats& stats) {
    constexpr std::uint32_t kRunPixels = 16;
    const std::uint32_t runsPerRow = (region.width + kRunPixels - 1) / kRunPixels;
    const std::uint64_t runs = std::uint64_t(runsPerRow) * region.height;
    std::atomic<std::uint64_t> nextRun{0};
    std::atomic<std::uint64_t> samples{0}, oracle{0};
    auto worker = [&] {
        std::uint64_t mine = 0, mineOracle = 0;
        for (std::uint64_t run; (run = nextRun++) < runs;) {
            const auto row = std::uint32_t(run / runsPerRow);
            const std::uint32_t x0 = std::uint32_t(run % runsPerRow) * kRunPixels;
            const std::uint32_t x1 = std::min(x0 + kRunPixels, region.width);
            for (std::uint32_t x = x0; x < x1; ++x)
                pixel(region.x + x, region.y + row, std::size_t(row) * region.width + x, mine,
                      mineOracle);
        }
        samples += mine;
        oracle += mineOracle;
    };
    threads = threads ? threads : std::max(1u, std::thread::hardware_concurrency());
    std::vector<std::thread> pool;
    for (unsigned i = 1; i < threads; ++i)
        pool.emplace_back(worker);
    worker();
    for (auto& t : pool)
        t.join();
    stats.samples += samples;
    stats.oracleSamples += oracle;
}

Image imageOf(const std::vector<RayProgress>& rays, std::uint32_t width, std::uint32_t height) {
    Image image(width, height);
    for (std::uint32_t y = 0; y < height; ++y)
        for (std::uint32_t x = 0; x < width; ++x) {
            float* px = image.pixel(x, y);
            for (int i = 0; i < 4; ++i)
                px[i] = float(std::clamp(rays[std::size_t(y) * width + x].acc[i], 0.0, 1.0));
        }
    return image;
}

/// One brick as the reference samples it: a sample point of its payload reads only voxels
/// of the stored brick (apron >= 2 covers the trilinear and the gradient's reads), by global
/// index, so it gives ReferenceVolume::sample's double exactly. A constant brick (apron
/// included) gives its value, which trilinear weights of equal values give exactly too.
template <class T> struct BrickSampler {
    const T* voxels = nullptr; ///< while its batch is drawn; null for a constant brick
    double constant = 0.0;
    std::array<std::int64_t, 3> first{}; ///< global index of the stored brick's voxel 0
    std::array<std::uint64_t, 3> dims{}; ///< the level's
    std::int64_t edge = 0;
    std::uint32_t batch = 0;

    double sample(double px, double py, double pz) const {
        if (voxels == nullptr) return constant;
        return trilinear(dims, px, py, pz, [&](std::int64_t x, std::int64_t y, std::int64_t z) {
            return double(voxels[((z - first[2]) * edge + (y - first[1])) * edge + (x - first[0])]);
        });
    }
};

template <class T>
std::vector<BrickSampler<T>> brickSamplers(const LevelGeometry& g, const BrickPlan& plan,
                                           const std::vector<std::size_t>& ends) {
    std::vector<BrickSampler<T>> bricks(g.brickCount());
    for (std::size_t batch = 0, i = 0; batch < ends.size(); ++batch)
        for (; i < ends[batch]; ++i) {
            const PlannedBrick& b = plan.drawn[i];
            BrickSampler<T>& s = bricks[b.index];
            for (int a = 0; a < 3; ++a)
                s.first[a] = std::int64_t(b.key.pos[a]) * g.brickVoxels - g.apronVoxels;
            s.dims = g.dims;
            s.edge = g.brickVoxels + 2 * g.apronVoxels;
            s.constant = b.constantValue;
            s.batch = std::uint32_t(batch);
        }
    return bricks;
}

/// The reference over the host cache: every brick of the level in front-to-back batches that
/// fit the cache's budget, each pinned while its pass runs; a ray stops at the first sample
/// whose brick is in a later batch and goes on from there.
template <class T>
void renderBricked(const Scene& scene, const RayContext& c, const ViewBasis& view,
                   const ReferenceConfig& config, std::vector<RayProgress>& rays,
                   FrameStats& stats) {
    const LevelGeometry& g = c.geometry;
    const BrickPlan plan = planEveryBrick(scene.store, g, view);
    const auto ends = planBatches(plan, scene.store.brickBytes(), scene.cache.stats().budgetBytes);
    std::vector<BrickSampler<T>> bricks = brickSamplers<T>(g, plan, ends);
    const std::uint32_t w = c.options.width, h = c.options.height;
    const PixelRect region = c.options.drawn();
    for (std::size_t batch = 0, first = 0; batch < ends.size(); first = ends[batch++]) {
        const auto loadStart = std::chrono::steady_clock::now();
        std::vector<brickstore::BrickPin> pins(ends[batch] - first);
        tbb::parallel_for(first, ends[batch], [&](std::size_t i) {
            const PlannedBrick& b = plan.drawn[i];
            if (b.draw != BrickDraw::Sampled) return;
            pins[i - first] = scene.cache.pin(b.key);
            bricks[b.index].voxels = reinterpret_cast<const T*>(pins[i - first].data().data());
        });
        stats.uploadMs +=
            std::chrono::duration<double, std::milli>(std::chrono::steady_clock::now() - loadStart)
                .count();
        auto volumeAt = [&](const glm::dvec3& p) -> const BrickSampler<T>* {
            std::uint64_t index = 0;
            for (int a = 2; a >= 0; --a) {
                const double cell = std::floor(p[a] / double(g.brickVoxels));
                index = index * g.bricks[a] +
                        std::uint64_t(std::clamp(cell, 0.0, double(g.bricks[a] - 1)));
            }
            const BrickSampler<T>& b = bricks[index];
            return b.batch == batch ? &b : nullptr;
        };
        forEachPixel(
            config.threads, region,
            [&](std::uint32_t x, std::uint32_t y, std::size_t i, std::uint64_t& samples,
                std::uint64_t& oracle) {
                marchRay(c, view.ray(x, y, w, h), x, y, volumeAt, rays[i], samples, oracle);
            },
            stats);
    }
    stats.batches = std::uint32_t(ends.size());
}

} // namespace

Image renderReference(const brickstore::BrickStore& store, const ReferenceVolume& volume,
                      const TransferFunction& tf, const Camera& camera,
                      const RenderOptions& options, FrameStats& stats,
                      const ReferenceConfig& config) {
    options.validate();
    const auto pre = options.preintegrate ? std::make_optional(tf.preintegrated()) : std::nullopt;
    // The projections and the isosurface map values through the function as authored.
    const double tableStep = options.mode == BlendMode::Composite ? options.stepVoxels : 1.0;
    return renderReference(store, volume, tf.table(tableStep),
                           ViewBasis::from(camera, options.width, options.height), options, stats,
                           config, pre ? &*pre : nullptr);
}

Image renderReference(const brickstore::BrickStore& store, const ReferenceVolume& volume,
                      const TransferFunctionTable& table, const ViewBasis& view,
                      const RenderOptions& options, FrameStats& stats,
                      const ReferenceConfig& config, const PreintegratedTable* preintegrated) {
    const auto start = std::chrono::steady_clock::now();
    options.validate();
    stats = FrameStats{};
    const auto levels = std::uint32_t(store.layout().levels().size());
    const std::uint32_t level = std::min<std::uint32_t>(std::uint32_t(options.level), levels - 1);
    const LevelGeometry geometry = LevelGeometry::of(store, level);
    if (geometry.dims != volume.dims())
        throw std::invalid_argument("reference volume is not the requested level");
    const double span = table.domainMax - table.domainMin;
    if (options.preintegrate && preintegrated == nullptr)
        throw std::invalid_argument("renderReference: preintegrate without a pre-integration "
                                    "table");
    const RayContext context{table, geometry, options,
                             0.5 / span * geometry.minSpacing() / geometry.spacing,
                             options.preintegrate ? preintegrated : nullptr};
    const std::uint32_t w = options.width, h = options.height;
    const PixelRect region = options.drawn();
    std::vector<RayProgress> rays(region.pixels());
    auto whole = [&](const glm::dvec3&) { return &volume; };
    forEachPixel(
        config.threads, region,
        [&](std::uint32_t x, std::uint32_t y, std::size_t i, std::uint64_t& samples,
            std::uint64_t& oracle) {
            marchRay(context, view.ray(x, y, w, h), x, y, whole, rays[i], samples, oracle);
        },
        stats);
    stats.level = level;
    stats.batches = 1;
    stats.totalMs =
        std::chrono::duration<double, std::milli>(std::chrono::steady_clock::now() - start).count();
    return imageOf(rays, region.width, region.height);
}

// ---- ReferenceRenderer ------------------------------------------------------------------

ReferenceRenderer::ReferenceRenderer(const ReferenceRendererConfig& config) : mConfig(config) {}
ReferenceRenderer::~ReferenceRenderer() = default;

Image ReferenceRenderer::render(const Scene& scene, const View& view, const RenderOptions& options,
                                FrameStats& stats) {
    options.validate();
    checkView(view, options, true);
    const auto levels = std::uint32_t(scene.store.layout().levels().size());
    const std::uint32_t level = std::min<std::uint32_t>(std::uint32_t(options.level), levels - 1);
    const auto& dims = scene.store.layout().levels()[level].dims;
    if (dims[0] * dims[1] * dims[2] > mConfig.maxVoxels)
        throw std::invalid_argument("the reference renderer is not offered for volumes over " +
                                    std::to_string(mConfig.maxVoxels >> 20) + " Mi voxels");
    // Full precision: the table has the default entries (tables are equal for one step and
    // entry count, so the shared classification's serves).
    FrameStats ignored;
    RenderOptions tablesOnly = options;
    tablesOnly.skip = SkipMode::None;
    const FrameClassification classified =
        classifyFrame(scene, level, tablesOnly, options.stepVoxels, ignored);
    const LevelGeometry g = LevelGeometry::of(scene.store, level);
    // An isosurface's refinement and gradient read around a point up to a step from its
    // sample, which may be in a brick of another batch: the level is read whole.
    if (g.apronVoxels < 2 || options.mode == BlendMode::Isosurface)
        return renderWhole(scene, *classified.table, classified.preintegrated.get(), view, options,
                           stats);
    const auto start = std::chrono::steady_clock::now();
    mVolume.reset(); // a level held whole for an earlier store goes
    stats = FrameStats{};
    const double span = classified.table->domainMax - classified.table->domainMin;
    const RayContext context{*classified.table, g, options, 0.5 / span * g.minSpacing() / g.spacing,
                             classified.preintegrated.get()};
    std::vector<RayProgress> rays(options.drawn().pixels());
    switch (scene.store.info().volume.type) {
    case brickstore::VoxelType::U8:
        renderBricked<std::uint8_t>(scene, context, view.basis, mConfig.threads, rays, stats);
        break;
    case brickstore::VoxelType::U16:
        renderBricked<std::uint16_t>(scene, context, view.basis, mConfig.threads, rays, stats);
        break;
    case brickstore::VoxelType::I16:
        renderBricked<std::int16_t>(scene, context, view.basis, mConfig.threads, rays, stats);
        break;
    case brickstore::VoxelType::F32:
        renderBricked<float>(scene, context, view.basis, mConfig.threads, rays, stats);
        break;
    }
    stats.level = level;
    stats.totalMs =
        std::chrono::duration<double, std::milli>(std::chrono::steady_clock::now() - start).count();
    return imageOf(rays, options.drawn().width, options.drawn().height);
}

Image ReferenceRenderer::renderWhole(const Scene& scene, const TransferFunctionTable& table,
                                     const PreintegratedTable* preintegrated, const View& view,
                                     const RenderOptions& options, FrameStats& stats) {
    const auto levels = std::uint32_t(scene.store.layout().levels().size());
    const std::uint32_t level = std::min<std::uint32_t>(std::uint32_t(options.level), levels - 1);
    if (!mVolume || mStoreInstance != scene.store.instance() || mLevel != level) {
        mVolume.reset(); // the old level's voxels go before the new ones are read
        mVolume = std::make_unique<ReferenceVolume>(scene.store, level);
        mStoreInstance = scene.store.instance();
        mLevel = level;
    }
    return renderReference(scene.store, *mVolume, table, view.basis, options, stats,
                           mConfig.threads, preintegrated);
}

} // namespace bc::render
