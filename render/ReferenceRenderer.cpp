#include "render/ReferenceRenderer.h"

#include "brickstore/BrickStore.h"
#include "brickstore/StoreVolume.h"
#include "render/BrickPlan.h"
#include "render/TransferFunction.h"

#include <algorithm>
#include <atomic>
#include <chrono>
#include <cmath>
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

double ReferenceVolume::sample(double px, double py, double pz) const {
    const double p[3] = {px - 0.5, py - 0.5, pz - 0.5};
    std::int64_t i0[3], i1[3];
    double w[3];
    for (int a = 0; a < 3; ++a) {
        const double f = std::floor(p[a]);
        const auto hi = std::int64_t(mDims[a]) - 1;
        w[a] = p[a] - f;
        i0[a] = std::clamp<std::int64_t>(std::int64_t(f), 0, hi);
        i1[a] = std::clamp<std::int64_t>(std::int64_t(f) + 1, 0, hi);
    }
    auto at = [&](std::int64_t x, std::int64_t y, std::int64_t z) {
        return double(mVoxels[(std::uint64_t(z) * mDims[1] + std::uint64_t(y)) * mDims[0] +
                              std::uint64_t(x)]);
    };
    auto lerp = [](double a, double b, double t) { return a + (b - a) * t; };
    const double c00 = lerp(at(i0[0], i0[1], i0[2]), at(i1[0], i0[1], i0[2]), w[0]);
    const double c10 = lerp(at(i0[0], i1[1], i0[2]), at(i1[0], i1[1], i0[2]), w[0]);
    const double c01 = lerp(at(i0[0], i0[1], i1[2]), at(i1[0], i0[1], i1[2]), w[0]);
    const double c11 = lerp(at(i0[0], i1[1], i1[2]), at(i1[0], i1[1], i1[2]), w[0]);
    return lerp(lerp(c00, c10, w[1]), lerp(c01, c11, w[1]), w[2]);
}

namespace {

struct RayContext {
    const ReferenceVolume& volume;
    const TransferFunctionTable& table;
    const LevelGeometry& geometry;
    const RenderOptions& options;
    glm::dvec3 gradScale; ///< value difference -> TF-domain units per voxel of the smallest spacing
};

std::array<double, 4> shade(const RayContext& c, const std::array<double, 4>& rgba,
                            const glm::dvec3& p, const glm::dvec3& dir) {
    const ReferenceVolume& v = c.volume;
    const glm::dvec3 g = glm::dvec3(v.sample(p.x + 1, p.y, p.z) - v.sample(p.x - 1, p.y, p.z),
                                    v.sample(p.x, p.y + 1, p.z) - v.sample(p.x, p.y - 1, p.z),
                                    v.sample(p.x, p.y, p.z + 1) - v.sample(p.x, p.y, p.z - 1)) *
                         c.gradScale;
    const double len = glm::length(g);
    if (len <= 0.0) return rgba;
    const double diff = std::abs(glm::dot(g / len, dir));
    const double spec = ShadingModel::kSpecular * std::pow(diff, ShadingModel::kShininess);
    const double w = std::clamp(len / ShadingModel::kGradientFade, 0.0, 1.0);
    std::array<double, 4> out = rgba;
    for (int i = 0; i < 3; ++i) {
        const double lit =
            rgba[i] * (ShadingModel::kAmbient + ShadingModel::kDiffuse * diff) + spec;
        out[i] = rgba[i] + (lit - rgba[i]) * w;
    }
    return out;
}

/// Marches one ray; returns premultiplied RGBA and adds its samples to `samples`, and to
/// `oracle` those with non-zero opacity taken before the ray's opacity reaches the early
/// termination threshold (what an ideal skipping renderer would have to take).
std::array<double, 4> marchRay(const RayContext& c, const Ray& ray, std::uint64_t& samples,
                               std::uint64_t& oracle) {
    const LevelGeometry& g = c.geometry;
    const glm::dvec3 ov = ray.origin / g.spacing, dv = ray.direction / g.spacing;
    const Box voxelBox{glm::dvec3(0.0),
                       glm::dvec3(double(g.dims[0]), double(g.dims[1]), double(g.dims[2]))};
    auto [t0, t1] = intersectBox({ov, dv}, voxelBox);
    t0 = std::max(t0, 0.0);
    const double step = c.options.stepVoxels * g.minSpacing();
    const double count = std::ceil((t1 - t0) / step - 0.5);
    std::array<double, 4> acc{0, 0, 0, 0};
    if (!(count > 0)) return acc;
    const auto total = std::int64_t(count);
    for (std::int64_t k = 0; k < total; ++k) {
        const glm::dvec3 p = ov + dv * (t0 + (double(k) + 0.5) * step);
        const auto f = c.table.lookup(c.volume.sample(p.x, p.y, p.z));
        std::array<double, 4> rgba{f[0], f[1], f[2], f[3]};
        if (rgba[3] <= 0.0) continue;
        if (acc[3] < c.options.ertThreshold) ++oracle;
        if (c.options.shading) rgba = shade(c, rgba, p, ray.direction);
        const double w = (1.0 - acc[3]) * rgba[3];
        for (int i = 0; i < 3; ++i)
            acc[i] += w * rgba[i];
        acc[3] += w;
    }
    samples += std::uint64_t(total);
    return acc;
}

} // namespace

Image renderReference(const brickstore::BrickStore& store, const ReferenceVolume& volume,
                      const TransferFunction& tf, const Camera& camera,
                      const RenderOptions& options, FrameStats& stats,
                      const ReferenceConfig& config) {
    options.validate();
    return renderReference(store, volume, tf.table(options.stepVoxels),
                           ViewBasis::from(camera, options.width, options.height), options, stats,
                           config);
}

Image renderReference(const brickstore::BrickStore& store, const ReferenceVolume& volume,
                      const TransferFunctionTable& table, const ViewBasis& view,
                      const RenderOptions& options, FrameStats& stats,
                      const ReferenceConfig& config) {
    const auto start = std::chrono::steady_clock::now();
    options.validate();
    stats = FrameStats{};
    const auto levels = std::uint32_t(store.layout().levels().size());
    const std::uint32_t level = std::min<std::uint32_t>(std::uint32_t(options.level), levels - 1);
    const LevelGeometry geometry = LevelGeometry::of(store, level);
    if (geometry.dims != volume.dims())
        throw std::invalid_argument("reference volume is not the requested level");
    const double span = table.domainMax - table.domainMin;
    const RayContext context{volume, table, geometry, options,
                             0.5 / span * geometry.minSpacing() / geometry.spacing};

    // Runs of pixels of the region in row order, shared out one at a time: a region of a few
    // pixels (a slice of a frame at a tiny step) still keeps every core busy.
    const PixelRect region = options.drawn();
    Image image(region.width, region.height);
    constexpr std::uint32_t kRunPixels = 16;
    const std::uint32_t runsPerRow = (region.width + kRunPixels - 1) / kRunPixels;
    const std::uint64_t runs = std::uint64_t(runsPerRow) * region.height;
    std::atomic<std::uint64_t> nextRun{0};
    std::atomic<std::uint64_t> samples{0}, oracle{0};
    auto worker = [&] {
        std::uint64_t mine = 0, mineOracle = 0;
        for (std::uint64_t run; (run = nextRun++) < runs;) {
            const std::uint32_t y = region.y + std::uint32_t(run / runsPerRow);
            const std::uint32_t x0 = region.x + std::uint32_t(run % runsPerRow) * kRunPixels;
            const std::uint32_t x1 = std::min(x0 + kRunPixels, region.x + region.width);
            for (std::uint32_t x = x0; x < x1; ++x) {
                const auto acc = marchRay(context, view.ray(x, y, options.width, options.height),
                                          mine, mineOracle);
                float* px = image.pixel(x - region.x, y - region.y);
                for (int i = 0; i < 4; ++i)
                    px[i] = float(std::clamp(acc[i], 0.0, 1.0));
            }
        }
        samples += mine;
        oracle += mineOracle;
    };
    unsigned threads =
        config.threads ? config.threads : std::max(1u, std::thread::hardware_concurrency());
    std::vector<std::thread> pool;
    for (unsigned i = 1; i < threads; ++i)
        pool.emplace_back(worker);
    worker();
    for (auto& t : pool)
        t.join();
    stats.level = level;
    stats.samples = samples;
    stats.oracleSamples = oracle;
    stats.totalMs =
        std::chrono::duration<double, std::milli>(std::chrono::steady_clock::now() - start).count();
    return image;
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
    if (!mVolume || mStoreInstance != scene.store.instance() || mLevel != level) {
        mVolume.reset(); // the old level's voxels go before the new ones are read
        mVolume = std::make_unique<ReferenceVolume>(scene.store, level);
        mStoreInstance = scene.store.instance();
        mLevel = level;
    }
    // Full precision: the table has the default entries (tables are equal for one step and
    // entry count, so the shared classification's serves).
    FrameStats ignored;
    RenderOptions tablesOnly = options;
    tablesOnly.skip = SkipMode::None;
    const FrameClassification classified =
        classifyFrame(scene, level, tablesOnly, options.stepVoxels, ignored);
    return renderReference(scene.store, *mVolume, *classified.table, view.basis, options, stats,
                           mConfig.threads);
}

} // namespace bc::render
