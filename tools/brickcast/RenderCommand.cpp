// brickcast render STORE -o OUT.png: one frame on the renderer `auto` picks (the GPU raycaster on a
// hardware GPU, else the CPU raycaster), one named by --renderer, or the CPU reference.
#include "brickstore/BrickCache.h"
#include "brickstore/BrickStore.h"
#include "brickstore/Error.h"
#include "brickstore/HostMemory.h"
#include "render/BrickPlan.h"
#include "render/Camera.h"
#include "render/ConvergedReference.h"
#include "render/CpuRaycaster.h"
#include "render/EglContext.h"
#include "render/GpuRaycaster.h"
#include "render/GpuSplatter.h"
#include "render/HybridSplatter.h"
#include "render/Image.h"
#include "render/ReferenceRenderer.h"
#include "render/Renderer.h"
#include "render/RendererChoice.h"
#include "render/RendererRegistry.h"
#include "render/TransferFunction.h"
#include "tools/Parse.h"
#include "tools/TransferFunctionFile.h"
#include "tools/brickcast/Commands.h"

#ifdef BC_HAVE_MPI
#include "render/Composite.h"
#include "render/Partition.h"
#include "server/cluster/MpiRuntime.h"
#include "server/cluster/SortLast.h"
#endif

#include <CLI/CLI.hpp>
#include <nlohmann/json.hpp>
#include <tbb/global_control.h>

#include <algorithm>
#include <chrono>
#include <cmath>
#include <cstdio>
#include <fstream>
#include <functional>
#include <limits>
#include <memory>
#include <optional>
#include <thread>
#include <vector>

namespace bc::cli {
namespace {

struct RenderCliOptions {
    std::string store, output, size = "256,256", tf = "ct-skin", orbit, eye, target, up,
                               ert = "0.99", skip = "all", statsPath, renderer = "auto",
                               mode = "composite";
    std::optional<double> iso;      ///< --iso
    std::string crop;               ///< --crop X0,X1,Y0,Y1,Z0,Z1 (mm)
    std::vector<std::string> clips; ///< --clip NX,NY,NZ,D, each
    bool cap = false;               ///< --cap
    double fov = 30.0, step = 1.0, octreeRatio = 1.0;
    std::uint32_t octreeLevelLimit = 32, cells = render::RenderOptions{}.cellVoxels;
    bool ortho = false, noShading = false, noSimd = false, noPackets = false, noRayGuided = false,
         noRunningSkip = false, jitter = false, preintegrate = false, reference = false,
         interactive = false, mpi = false, mpiBarrier = false;
    double mpiTimeoutS = 60.0;
    std::uint64_t gpuBudgetMb = 512, hostBudgetMb = 1024; // the latter: "auto" in addRenderCommand
    std::int32_t level = 0;
    std::uint32_t repeat = 1;
    std::uint32_t threads = 0; ///< 0: every core
    /// --converge [TOL]: empty when not given ("default" when given without a value).
    std::string converge;
    double convergeFloor = 1.0 / 64.0, convergeTimeS = 0.0;
};

glm::dvec3 vec3Of(const std::string& text, const std::string& what) {
    const auto v = tools::parseNumbers(text, what, 3, 3);
    return {v[0], v[1], v[2]};
}

render::Camera cameraOf(const RenderCliOptions& o, const render::Box& box) {
    render::Camera c;
    if (!o.eye.empty() || !o.target.empty()) {
        if (o.eye.empty() || o.target.empty())
            throw std::invalid_argument("--eye and --target go together");
        c.eye = vec3Of(o.eye, "--eye");
        c.target = vec3Of(o.target, "--target");
        c.up = o.up.empty() ? glm::dvec3(0, 0, 1) : vec3Of(o.up, "--up");
        c.fovYDeg = o.fov;
        c.orthoHeight = 2.0 * box.radius();
    } else {
        const auto v = tools::parseNumbers(o.orbit.empty() ? "30,20" : o.orbit, "--orbit", 2, 3);
        c = render::Camera::orbit(box, v[0], v[1], v.size() > 2 ? v[2] : 1.0, o.fov);
        if (!o.up.empty()) c.up = vec3Of(o.up, "--up"); // e.g. 0,0,-1 for scans stored head-down
    }
    c.orthographic = o.ortho;
    c.validate();
    return c;
}

render::RenderOptions renderOptionsOf(const RenderCliOptions& o) {
    render::RenderOptions r;
    const auto wh = tools::parseNumbers(o.size, "--size", 2, 2);
    if (wh[0] < 1 || wh[1] < 1 || wh[0] > 16384 || wh[1] > 16384 || wh[0] != std::floor(wh[0]) ||
        wh[1] != std::floor(wh[1]))
        throw std::invalid_argument("--size: '" + o.size + "' must be two integers in 1..16384");
    r.width = std::uint32_t(wh[0]);
    r.height = std::uint32_t(wh[1]);
    r.stepVoxels = o.step;
    r.earlyTermination = o.ert != "off";
    if (r.earlyTermination) r.ertThreshold = tools::parseNumbers(o.ert, "--ert", 1, 1)[0];
    r.skip = render::parseSkipMode(o.skip);
    r.mode = render::parseBlendMode(o.mode);
    if ((r.mode == render::BlendMode::Isosurface) != o.iso.has_value())
        throw std::invalid_argument(o.iso
                                        ? "--iso: only with --mode iso"
                                        : "--mode iso: needs --iso VALUE (in the volume's units)");
    if (o.iso) r.isoValue = *o.iso;
    if (!o.crop.empty()) {
        const auto c = tools::parseNumbers(o.crop, "--crop", 6, 6);
        r.clip.cropped = true;
        r.clip.cropMin = {c[0], c[2], c[4]};
        r.clip.cropMax = {c[1], c[3], c[5]};
    }
    if (o.clips.size() > render::Clip::kMaxPlanes)
        throw std::invalid_argument("--clip: " + std::to_string(o.clips.size()) +
                                    " planes, at most " + std::to_string(render::Clip::kMaxPlanes));
    for (const std::string& text : o.clips) {
        const auto p = tools::parseNumbers(text, "--clip", 4, 4);
        r.clip.planes[r.clip.planeCount++] = {{p[0], p[1], p[2]}, p[3]};
    }
    r.clip.cap = o.cap;
    r.shading = !o.noShading;
    r.simd = !o.noSimd;
    r.packets = !o.noPackets;
    r.runningSkip = !o.noRunningSkip;
    r.rayGuided = !o.noRayGuided;
    r.jitter = o.jitter;
    r.preintegrate = o.preintegrate;
    r.level = o.level;
    r.interactive = o.interactive;
    r.octree.ratioThreshold = o.octreeRatio;
    r.octree.levelLimit = o.octreeLevelLimit;
    r.cellVoxels = o.cells;
    r.validate();
    return r;
}

nlohmann::json statsJson(const render::FrameStats& s, const std::string& renderer,
                         const render::RenderOptions& o) {
    const double pixels = double(o.width) * o.height;
    return {{"renderer", renderer},
            {"rendererName", s.renderer},
            {"rendererChoice", s.rendererChoice},
            {"width", o.width},
            {"height", o.height},
            {"level", s.level},
            {"mode", render::toString(o.mode)},
            {"samples", s.samples},
            {"samplesPerPixel", double(s.samples) / pixels},
            {"samplesRaising", s.samplesRaising},
            {"bricksTotal", s.bricksTotal},
            {"bricksCulled", s.bricksCulled},
            {"bricksSkipped", s.bricksSkipped},
            {"bricksVisited", s.bricksVisited},
            {"bricksConstant", s.bricksConstant},
            {"bricksUploaded", s.bricksUploaded},
            {"bytesUploaded", s.bytesUploaded},
            {"batches", s.batches},
            {"bricksEntered", s.bricksEntered},
            {"bricksDeferred", s.bricksDeferred},
            {"bricksRequested", s.bricksRequested},
            {"resumePasses", s.resumePasses},
            {"bricksUnreached", s.bricksUnreached},
            {"guidedFallback", s.guidedFallback},
            {"octreeLeaps", s.octreeLeaps},
            {"octreeBricksRebuilt", s.octreeBricksRebuilt},
            {"octreeRebuildMs", s.octreeRebuildMs},
            {"cellBricksBuilt", s.cellBricksBuilt},
            {"cellBuildMs", s.cellBuildMs},
            {"cellBricks", s.cellBricks},
            {"occlusionUsed", s.occlusionUsed},
            {"occlusionReason", s.occlusionReason},
            {"occlusionFrustums", s.occlusionFrustums},
            {"occlusionTriangles", s.occlusionTriangles},
            {"occlusionBuildMs", s.occlusionBuildMs},
            {"samplesSavedByStart", s.samplesSavedByStart},
            {"uploadMs", s.uploadMs},
            {"renderMs", s.renderMs},
            {"readbackMs", s.readbackMs},
            {"totalMs", s.totalMs}};
}

/// The renderers draw past a leaf table that fails its checksum (its brick is treated as
/// occupied everywhere, so the image stays conservative), which would leave a corrupt store
/// unnoticed: the command checks every stored brick's leaf table of the level it drew.
/// @throw StoreCorrupt naming the first bad brick and the store, and how many more there are.
void checkLeafTables(const brickstore::BrickStore& store, std::uint32_t level) {
    const auto& levels = store.layout().levels();
    if (level >= levels.size()) return;
    const auto& l = levels[level];
    std::vector<std::string> faults;
    for (std::uint64_t b = 0; b < l.brickCount(); ++b) {
        const brickstore::BrickKey key = store.layout().keyOf(l.firstBrick + b);
        if (!store.record(key).stored()) continue;
        try {
            store.leafRanges(key);
        } catch (const brickstore::StoreCorrupt& e) {
            faults.push_back(e.what());
        }
    }
    if (faults.empty()) return;
    throw brickstore::StoreCorrupt(
        faults.front() +
        (faults.size() > 1 ? " (and " + std::to_string(faults.size() - 1) + " more bricks)" : "") +
        "; no image written");
}

/// --repeat: the first frame's time and the warm frames' median, min and max.
void printRepeatSummary(const std::vector<double>& frameMs) {
    if (frameMs.size() < 2) return;
    std::vector<double> warm(frameMs.begin() + 1, frameMs.end());
    std::sort(warm.begin(), warm.end());
    std::printf("%zu frames: first %.1f ms, warm median %.1f ms (min %.1f, max %.1f)\n",
                frameMs.size(), frameMs.front(), warm[warm.size() / 2], warm.front(), warm.back());
}

render::ConvergenceConfig convergenceConfigOf(const RenderCliOptions& o) {
    render::ConvergenceConfig c;
    if (o.converge != "default") {
        const double tol = tools::parseNumbers(o.converge, "--converge", 1, 1)[0];
        if (!std::isfinite(tol) || tol <= 0.0)
            throw std::invalid_argument("--converge: the tolerance '" + o.converge +
                                        "' must be a finite number > 0 (RGBA in [0, 1])");
        c.toleranceRgba = tol;
    }
    c.startStepVoxels = o.step;
    c.floorStepVoxels = std::min(o.convergeFloor, o.step);
    if (!std::isfinite(o.convergeTimeS) || o.convergeTimeS < 0.0)
        throw std::invalid_argument("--converge-time-s must be finite and >= 0");
    c.timeLimitMs = o.convergeTimeS * 1e3;
    c.validate();
    return c;
}

nlohmann::json convergenceJson(const render::ConvergedReference& r,
                               const render::ConvergenceConfig& c) {
    nlohmann::json steps = nlohmann::json::array();
    for (const auto& s : r.steps)
        steps.push_back(
            {{"stepVoxels", s.stepVoxels},
             {"renderMs", s.renderMs},
             {"samples", s.samples},
             {"maxAbsToPrevious", std::isnan(s.maxAbsToPrevious)
                                      ? nlohmann::json(nullptr)
                                      : nlohmann::json(s.maxAbsToPrevious)},
             {"rmseToPrevious", std::isnan(s.rmseToPrevious) ? nlohmann::json(nullptr)
                                                             : nlohmann::json(s.rmseToPrevious)}});
    return {{"converged", r.converged},
            {"stop", render::toString(r.stop)},
            {"stepVoxels", r.stepVoxels},
            {"imageStepVoxels", r.imageStepVoxels},
            {"toleranceRgba", c.toleranceRgba},
            {"startStepVoxels", c.startStepVoxels},
            {"floorStepVoxels", c.floorStepVoxels},
            {"timeLimitMs", c.timeLimitMs},
            {"metric", "max abs difference over RGBA (premultiplied, [0,1], float) of "
                       "successive frames"},
            {"totalMs", r.totalMs},
            {"steps", steps}};
}

/// --reference --converge: the reference at --step, --step/2, ... until halving changes the
/// image by under the tolerance; prints each frame's step, time and difference.
render::Image convergedImage(const RenderCliOptions& o, const brickstore::BrickStore& store,
                             brickstore::BrickCache& cache, const render::TransferFunction& tf,
                             const render::Camera& camera, const render::RenderOptions& options,
                             render::FrameStats& stats, nlohmann::json& convergence) {
    const render::ConvergenceConfig config = convergenceConfigOf(o);
    render::ReferenceRendererConfig referenceConfig;
    referenceConfig.maxVoxels = std::numeric_limits<std::uint64_t>::max();
    render::ReferenceRenderer reference(referenceConfig);
    render::ClassificationCache classifications;
    render::ConvergedReference r = render::renderConverged(
        reference, render::Scene{store, cache, tf, classifications},
        render::View::of(camera, options.width, options.height), options, config);
    for (const auto& s : r.steps)
        std::printf("step %.6g: %.1f ms, to the previous step max abs %.3f/255, RMSE %.4f/255\n",
                    s.stepVoxels, s.renderMs, s.maxAbsToPrevious * 255.0, s.rmseToPrevious * 255.0);
    std::printf("%s: step %.6g (image at %.6g), tolerance %.3f/255, %.1f ms in all\n",
                r.converged ? "converged" : "NOT converged", r.stepVoxels, r.imageStepVoxels,
                config.toleranceRgba * 255.0, r.totalMs);
    convergence = convergenceJson(r, config);
    stats = render::FrameStats{};
    stats.samples = r.steps.back().samples;
    stats.totalMs = r.totalMs;
    return std::move(r.image);
}

#ifdef BC_HAVE_MPI
/// --mpi, under mpirun: rank r draws part r of the level's brick grid split into one part per
/// rank (render/Partition.h) over its footprint with the CPU raycaster (the GPU one with
/// --renderer gpu), the parts are
/// composited by direct send (server/cluster/SortLast.h), and rank 0 writes the PNG and the
/// stats (each rank's render time, samples and bytes, the compositing time, the imbalance).
void renderAcrossRanks(const RenderCliOptions& o, const server::cluster::MpiRuntime& mpi) {
    using namespace server::cluster;
    if (o.reference || !o.converge.empty())
        throw std::invalid_argument("--mpi draws with the CPU or GPU raycaster, not the reference");
    const render::RendererKind* kind = render::RendererRegistry::builtin().find(o.renderer);
    if (o.renderer != "auto" && !(kind && kind->parts))
        throw std::invalid_argument(
            "--mpi draws with the CPU or GPU raycaster (--renderer cpu or gpu), not " + o.renderer);
    if (!(o.mpiTimeoutS > 0.0 && o.mpiTimeoutS <= 86400.0))
        throw std::invalid_argument("--mpi-timeout-s must lie in (0, 86400]");
    auto store = brickstore::BrickStore::open(o.store);
    render::RenderOptions options = renderOptionsOf(o);
    const auto tf =
        tools::loadTransferFunction(o.tf, render::VolumeValueStats::fromStore(store->info()));
    const render::Camera camera = cameraOf(o, render::LevelGeometry::of(*store, 0).box);
    const auto levels = std::uint32_t(store->layout().levels().size());
    const std::uint32_t level = std::min<std::uint32_t>(std::uint32_t(options.level), levels - 1);
    const render::LevelGeometry g = render::LevelGeometry::of(*store, level);
    const auto ranks = std::uint32_t(mpi.size()), me = std::uint32_t(mpi.rank());
    const render::Partition partition = render::Partition::ofLevel(*store, level, ranks);
    const render::View view = render::View::of(camera, options.width, options.height);
    SortLastFrame frame{options.width,
                        options.height,
                        {},
                        partition.frontToBack(g, view.basis),
                        render::combineFor(options.mode)};
    for (std::uint32_t r = 0; r < ranks; ++r)
        frame.footprints.push_back(render::footprint(g, partition.region(r), view));
    brickstore::BrickCache cache(*store, brickstore::BrickCacheConfig{o.hostBudgetMb << 20});
    // auto is the CPU raycaster here: every rank would otherwise make a GL context to decide.
    std::unique_ptr<render::EglContext> context;
    std::unique_ptr<render::Renderer> drawer;
    if (o.renderer == "gpu") {
        context = std::make_unique<render::EglContext>();
        drawer = std::make_unique<render::GpuRaycaster>();
    } else {
        drawer = std::make_unique<render::CpuRaycaster>();
    }
    render::Renderer& raycaster = *drawer;
    render::ClassificationCache classifications;
    const render::Scene scene{*store, cache, tf, classifications};
    options.parts = ranks;
    options.part = me;
    options.region = frame.footprints[me].rect;
    render::FrameStats stats;
    CompositeStats composite;
    render::Image image;
    std::vector<double> frameMs, renderMs, compositeMs;
    for (std::uint32_t i = 0; i < o.repeat; ++i) {
        MPI_Barrier(MPI_COMM_WORLD); // every rank starts the frame together
        const auto start = std::chrono::steady_clock::now();
        render::PartialImage mine{frame.footprints[me].rect, {}};
        stats = render::FrameStats{};
        if (frame.footprints[me].visible)
            mine.image = raycaster.render(scene, view, options, stats);
        if (o.mpiBarrier) MPI_Barrier(MPI_COMM_WORLD); // compositing timed on its own
        image = compositeDirectSend(MPI_COMM_WORLD, 0, frame, mine, int(i % 30000) + 1,
                                    std::chrono::milliseconds(std::int64_t(o.mpiTimeoutS * 1e3)),
                                    composite);
        frameMs.push_back(
            std::chrono::duration<double, std::milli>(std::chrono::steady_clock::now() - start)
                .count());
        renderMs.push_back(stats.totalMs);
        compositeMs.push_back(composite.ms);
    }
    // Each rank's last frame to rank 0.
    const double mine[5] = {stats.totalMs, double(stats.samples), composite.ms,
                            double(composite.bytesSent), double(composite.bytesReceived)};
    std::vector<double> all(me == 0 ? 5 * ranks : 0);
    MPI_Gather(mine, 5, MPI_DOUBLE, all.data(), 5, MPI_DOUBLE, 0, MPI_COMM_WORLD);
    if (me != 0) return;
    checkLeafTables(*store, level);
    if (frame.combine != render::PartsCombine::Over) // the projection's combined values
        render::resolveProjections(
            image, options.mode,
            *classifications
                 .get(*store, level, tf, nullptr, nullptr, render::SkipRule::of(options))
                 ->table(1.0));
    render::writePng(o.output, image);
    double maxMs = 0, sumMs = 0, bytes = 0;
    std::uint64_t samples = 0;
    nlohmann::json perRank = nlohmann::json::array();
    for (std::uint32_t r = 0; r < ranks; ++r) {
        const double* v = &all[5 * r];
        maxMs = std::max(maxMs, v[0]);
        sumMs += v[0];
        samples += std::uint64_t(v[1]);
        bytes += v[3];
        const render::BrickBox& b = partition.region(r);
        perRank.push_back(
            {{"rank", r},
             {"renderMs", v[0]},
             {"samples", std::uint64_t(v[1])},
             {"compositeMs", v[2]},
             {"bytesSent", std::uint64_t(v[3])},
             {"bytesReceived", std::uint64_t(v[4])},
             {"bricks", b.count()},
             {"bricksLo", b.lo},
             {"bricksHi", b.hi},
             {"storedBytes", partition.weight(r)},
             {"footprint",
              frame.footprints[r].visible
                  ? nlohmann::json{frame.footprints[r].rect.x, frame.footprints[r].rect.y,
                                   frame.footprints[r].rect.width, frame.footprints[r].rect.height}
                  : nlohmann::json(nullptr)}});
    }
    const double imbalance = sumMs > 0 ? maxMs / (sumMs / ranks) : 1.0;
    std::printf("%s: %ux%u, level %u, %u ranks, %.1f ms (render max %.1f, imbalance %.2f, "
                "composite %.1f ms, %s moved), %.1f samples/pixel\n",
                o.output.c_str(), options.width, options.height, level, ranks, frameMs.back(),
                maxMs, imbalance, composite.ms, tools::formatBytes(bytes).c_str(),
                double(samples) / (double(options.width) * options.height));
    printRepeatSummary(frameMs);
    if (!o.statsPath.empty()) {
        nlohmann::json j{
            {"renderer", std::string(o.renderer == "gpu" ? "GPU" : "CPU") +
                             " raycaster, sort-last over MPI ranks (direct send)"},
            {"width", options.width},
            {"height", options.height},
            {"level", level},
            {"ranks", ranks},
            {"samples", samples},
            {"samplesPerPixel", double(samples) / (double(options.width) * options.height)},
            {"frameMs", frameMs},
            {"renderMsMax", maxMs},
            {"renderMsMean", sumMs / ranks},
            {"imbalance", imbalance},
            {"compositeMs", composite.ms},
            {"compositeMsFrames", compositeMs},
            {"renderMsFrames", renderMs},
            {"compositeAfterBarrier", o.mpiBarrier},
            {"bytesComposited", std::uint64_t(bytes)},
            {"perRank", perRank}};
        std::ofstream f(o.statsPath);
        f << j.dump(2) << "\n";
        if (!f) throw std::runtime_error(o.statsPath + ": cannot write the stats");
    }
}

/// --mpi: MPI for this process; an error on any rank ends every rank (the others would wait
/// for its part for ever), printed with its rank.
void runRenderMpi(const RenderCliOptions& o) {
    server::cluster::MpiRuntime mpi;
    try {
        renderAcrossRanks(o, mpi);
    } catch (const std::exception& e) {
        std::fprintf(stderr, "brickcast: rank %d of %d: %s\n", mpi.rank(), mpi.size(), e.what());
        std::fflush(stderr);
        server::cluster::MpiRuntime::abortAll(2);
    }
}
#endif

void runRender(const RenderCliOptions& o) {
    // --threads: the CPU renderers' worker threads (TBB's), e.g. one per rank's core under MPI.
    std::optional<tbb::global_control> threads;
    if (o.threads > 0)
        threads.emplace(tbb::global_control::max_allowed_parallelism, std::size_t(o.threads));
    if (o.mpi) {
#ifdef BC_HAVE_MPI
        runRenderMpi(o);
        return;
#else
        throw std::invalid_argument("--mpi: this brickcast was built without MPI "
                                    "(libopenmpi-dev; cmake -DBC_WITH_MPI=ON)");
#endif
    }
    if (!o.converge.empty() && !o.reference)
        throw std::invalid_argument("--converge needs --reference");
    auto store = brickstore::BrickStore::open(o.store);
    const render::RenderOptions options = renderOptionsOf(o);
    const auto tf =
        tools::loadTransferFunction(o.tf, render::VolumeValueStats::fromStore(store->info()));
    const render::Camera camera = cameraOf(o, render::LevelGeometry::of(*store, 0).box);
    render::FrameStats stats;
    render::Image image;
    std::string renderer;
    const render::RendererRegistry& registry = render::RendererRegistry::builtin();
    if (o.renderer != "auto" && (o.renderer == "reference" || !registry.find(o.renderer)))
        throw std::invalid_argument("--renderer: '" + o.renderer +
                                    "' is not auto, gpu, cpu, splat or splat-gpu");
    // One renderer draws the view --repeat times: the later frames are warm (host cache, GPU
    // pool, octrees and, for the GPU raycaster, occlusion frustums of the same view).
    std::unique_ptr<render::EglContext> context;
    const render::RendererChoice choice =
        o.reference ? render::RendererChoice{"reference", "asked for reference (--reference)"}
                    : render::resolveRenderer(o.renderer, context);
    if (o.renderer == "auto") std::fprintf(stderr, "render: %s\n", choice.reason.c_str());
    std::unique_ptr<brickstore::BrickCache> cache;
    std::function<render::Image(render::FrameStats&)> draw;
    std::function<std::string()> describe;
    if (o.reference) {
        // Through the host cache in batches that fit --host-budget-mb, never the level whole
        // (the same image to the bit: render/RESIDENCY.md); no cap on the level's size, which
        // the daemon has for its clients: here the user asked for it.
        cache = std::make_unique<brickstore::BrickCache>(
            *store, brickstore::BrickCacheConfig{o.hostBudgetMb << 20});
        render::ReferenceRendererConfig config;
        config.maxVoxels = std::numeric_limits<std::uint64_t>::max();
        auto reference = std::make_shared<render::ReferenceRenderer>(config);
        draw = [&, reference](render::FrameStats& s) {
            return reference->render(*store, *cache, tf, camera, options, s);
        };
        describe = [] { return std::string("CPU reference (double)"); };
    } else {
        if (registry.find(choice.name)->needsGl && !context)
            context = std::make_unique<render::EglContext>();
        cache = std::make_unique<brickstore::BrickCache>(
            *store, brickstore::BrickCacheConfig{o.hostBudgetMb << 20});
        if (choice.name == "splat") {
            auto splatter = std::make_shared<render::HybridSplatter>();
            draw = [&, splatter](render::FrameStats& s) {
                return splatter->render(*store, *cache, tf, camera, options, s);
            };
            describe = [splatter] {
                const auto& f = splatter->lastFrame();
                return "hybrid splatter (CPU, " + std::to_string(f.points) + " points, " +
                       std::to_string(f.splats) + " splats, " + std::to_string(f.culled) +
                       " culled)";
            };
        } else if (choice.name == "splat-gpu") {
            auto splatter = std::make_shared<render::GpuSplatter>();
            draw = [&, splatter](render::FrameStats& s) {
                return splatter->render(*store, *cache, tf, camera, options, s);
            };
            describe = [&, splatter] {
                const auto& f = splatter->lastFrame();
                return "hybrid splatter (" + context->renderer() + ", " + std::to_string(f.points) +
                       " points, " + std::to_string(f.splats) + " splats)";
            };
        } else if (choice.name == "cpu") {
            auto raycaster = std::make_shared<render::CpuRaycaster>();
            draw = [&, raycaster](render::FrameStats& s) {
                return raycaster->render(*store, *cache, tf, camera, options, s);
            };
            describe = [&o] {
                return "CPU raycaster (float, " +
                       // The modes other than composite march in packets or else scalar.
                       (o.noSimd || (o.mode != "composite" && (o.noPackets || o.preintegrate))
                            ? std::string("scalar")
                            : render::CpuRaycaster::simdTarget() +
                                  (o.noPackets || o.preintegrate ? " samples" : " packets")) +
                       ", " + std::to_string(std::thread::hardware_concurrency()) + " threads)";
            };
        } else {
            auto raycaster = std::make_shared<render::GpuRaycaster>(
                render::GpuRaycasterConfig{o.gpuBudgetMb << 20});
            draw = [&, raycaster](render::FrameStats& s) {
                return raycaster->render(*store, *cache, tf, camera, options, s);
            };
            describe = [&] { return context->renderer() + " via EGL " + context->platform(); };
        }
    }
    std::vector<double> frameMs;
    nlohmann::json convergence;
    if (!o.converge.empty()) {
        image = convergedImage(o, *store, *cache, tf, camera, options, stats, convergence);
        frameMs.push_back(stats.totalMs);
        describe = [] { return std::string("CPU reference (double), converged"); };
    } else {
        for (std::uint32_t i = 0; i < o.repeat; ++i) {
            image = draw(stats);
            stats.renderer = choice.name;
            stats.rendererChoice = choice.reason;
            frameMs.push_back(stats.totalMs);
        }
    }
    renderer = describe();
    checkLeafTables(*store, stats.level);
    render::writePng(o.output, image);
    std::printf(
        "%s: %ux%u, level %u, %.1f ms (upload %.1f, render %.1f, readback %.1f), %.1f "
        "samples/pixel, "
        "bricks %llu visited / %llu skipped / %llu culled, %llu uploaded (%s), %u batch(es) [%s]\n",
        o.output.c_str(), options.width, options.height, stats.level, stats.totalMs, stats.uploadMs,
        stats.renderMs, stats.readbackMs,
        double(stats.samples) / (double(options.width) * options.height),
        (unsigned long long)stats.bricksVisited, (unsigned long long)stats.bricksSkipped,
        (unsigned long long)stats.bricksCulled, (unsigned long long)stats.bricksUploaded,
        tools::formatBytes(double(stats.bytesUploaded)).c_str(), stats.batches, renderer.c_str());
    printRepeatSummary(frameMs);
    if (!o.statsPath.empty()) {
        auto j = statsJson(stats, renderer, options);
        j["frameMs"] = frameMs; // every frame's totalMs; the other fields are the last frame's
        if (!convergence.is_null()) j["convergence"] = convergence;
        std::ofstream f(o.statsPath);
        f << j.dump(2) << "\n";
        if (!f) throw std::runtime_error(o.statsPath + ": cannot write the stats");
    }
}

} // namespace

void renderStoreToPng(const std::string& storePath, const std::string& output,
                      const std::string& tfName, const std::string& orbit, const std::string& size,
                      bool reference) {
    RenderCliOptions o;
    o.store = storePath;
    o.output = output;
    o.tf = tfName;
    o.orbit = orbit;
    o.size = size;
    o.reference = reference;
    runRender(o);
}

void addRenderCommand(CLI::App& app) {
    auto o = std::make_shared<RenderCliOptions>();
    auto* cmd = app.add_subcommand("render", "Render one frame of a store to PNG (GPU or CPU "
                                             "raycaster, auto picks; or the CPU reference)");
    cmd->add_option("STORE", o->store, "Store file")->required();
    cmd->add_option("-o,--output", o->output, "PNG to write")->required();
    cmd->add_option("--size", o->size, "Image W,H")->capture_default_str();
    cmd->add_option(
           "--tf", o->tf,
           "Transfer function: a JSON file or a preset (" +
               [] {
                   std::string s;
                   for (const auto& n : render::TransferFunction::presetNames())
                       s += (s.empty() ? "" : ", ") + n;
                   return s;
               }() +
               ")")
        ->capture_default_str();
    auto* orbit =
        cmd->add_option("--orbit", o->orbit, "AZ,EL[,DIST] around the volume (default 30,20,1)");
    auto* eye = cmd->add_option("--eye", o->eye, "Camera position X,Y,Z (mm)")->excludes(orbit);
    cmd->add_option("--target", o->target, "Point looked at X,Y,Z (mm)")
        ->excludes(orbit)
        ->needs(eye);
    cmd->add_option("--up", o->up, "Up vector X,Y,Z (default +z)");
    auto* fov = cmd->add_option("--fov", o->fov, "Vertical field of view in degrees")
                    ->capture_default_str();
    cmd->add_flag("--ortho", o->ortho, "Orthographic projection")->excludes(fov);
    cmd->add_option("--step", o->step, "Sample distance in voxels of the smallest spacing")
        ->capture_default_str();
    cmd->add_option("--ert", o->ert, "Early ray termination threshold, or 'off'")
        ->capture_default_str();
    cmd->add_option("--skip", o->skip,
                    "Empty-space skipping: none, bricks (first stage), all (+ per-brick octrees)")
        ->capture_default_str();
    cmd->add_option("--mode", o->mode,
                    "What a ray makes of its samples: composite, mip (maximum), minip (minimum), "
                    "average, iso (the surface at --iso); the raycasters and the reference")
        ->capture_default_str();
    cmd->add_option("--iso", o->iso, "With --mode iso: the surface's value, in the volume's units");
    cmd->add_option("--crop", o->crop,
                    "Draw only inside the box X0,X1,Y0,Y1,Z0,Z1 (mm; the volume spans 0 to "
                    "dims x spacing); the raycasters and the reference");
    cmd->add_option("--clip", o->clips,
                    "Keep the side NX*x + NY*y + NZ*z + D >= 0 of a plane (mm); up to six, "
                    "each its own --clip (--clip=-1,0,0,90 when it starts with a minus); the "
                    "raycasters and the reference")
        ->allow_extra_args(false);
    cmd->add_flag("--cap", o->cap,
                  "Draw the faces the crop and clip planes cut, shaded, coloured by the transfer "
                  "function (composite and iso modes)");
    cmd->add_option("--octree-ratio", o->octreeRatio,
                    "Draw an octree node whole once this share of its leaves is non-empty")
        ->capture_default_str();
    cmd->add_option("--octree-level-limit", o->octreeLevelLimit,
                    "Deepest octree level descended (0 = the brick)")
        ->capture_default_str();
    cmd->add_option("--cells", o->cells,
                    "CPU raycaster: leap by distance maps over cells of this many voxels, built "
                    "from the drawn bricks (1, 2, 4; 0: the octree alone; same image)")
        ->capture_default_str();
    cmd->add_flag("--no-shading", o->noShading, "No gradient shading");
    cmd->add_flag("--no-simd", o->noSimd,
                  "CPU raycaster: the scalar sample loop instead of the SIMD one (same image)");
    cmd->add_flag("--no-packets", o->noPackets,
                  "CPU raycaster: SIMD across one ray's samples instead of across rays (same "
                  "image)");
    cmd->add_flag("--no-running-skip", o->noRunningSkip,
                  "mip and minip: keep every brick and leaf whose values could not pass the "
                  "ray's value so far (the raycasters; same image)");
    cmd->add_flag("--no-ray-guided", o->noRayGuided,
                  "Load every planned brick: the GPU raycaster uploads those the last frame "
                  "found hidden, the CPU raycaster those no ray still marching can enter (same "
                  "image)");
    cmd->add_flag("--jitter", o->jitter,
                  "Start each ray's samples at a per-pixel offset (noise instead of rings)");
    cmd->add_flag("--preintegrate", o->preintegrate,
                  "Classify segments between samples through the pre-integrated transfer function "
                  "(CPU raycaster and reference)");
    cmd->add_option("--gpu-budget-mb", o->gpuBudgetMb, "GPU brick pool budget")
        ->capture_default_str();
    o->hostBudgetMb =
        brickstore::autoHostBudgetBytes(brickstore::hostMemory().perProcessBytes()) >> 20;
    cmd->add_option("--host-budget-mb", o->hostBudgetMb,
                    "Host brick cache budget (default: a quarter of the memory this process may "
                    "use, as brickcastd's host_mb = \"auto\")")
        ->capture_default_str();
    cmd->add_option("--level", o->level, "Pyramid level (0 = full resolution)")
        ->capture_default_str();
    cmd->add_flag("--interactive", o->interactive,
                  "Draw a coarser level when the view exceeds the GPU budget");
    cmd->add_option("--renderer", o->renderer,
                    "auto (gpu on a hardware GPU, cpu where OpenGL is a software rasteriser "
                    "such as llvmpipe or there is none), gpu (EGL raycaster), cpu (the CPU "
                    "raycaster, fastest without a GPU), splat (hybrid forward splatting, CPU) or "
                    "splat-gpu (the same, drawn by OpenGL)")
        ->capture_default_str();
    cmd->add_flag("--reference", o->reference, "Render with the CPU reference renderer");
    cmd->add_option("--converge", o->converge,
                    "With --reference: halve --step until the image changes by under TOL (max "
                    "abs over RGBA in [0,1]; default 0.5/255); the step and the differences go "
                    "into --stats")
        ->expected(0, 1)
        ->default_str("default");
    cmd->add_option("--converge-floor", o->convergeFloor,
                    "--converge: smallest step tried (voxels); reaching it is NOT converged")
        ->capture_default_str();
    cmd->add_option("--converge-time-s", o->convergeTimeS,
                    "--converge: no halving that would end after this many seconds (0 = none)")
        ->capture_default_str();
    cmd->add_option("--threads", o->threads,
                    "Worker threads of the CPU renderers (0 = every core; under mpirun, the "
                    "cores of each rank)")
        ->capture_default_str()
        ->check(CLI::Range(0, 4096));
    cmd->add_flag("--mpi", o->mpi,
                  "Under mpirun: draw the frame sort-last over the job's ranks, each rank its part "
                  "of the brick grid (the CPU raycaster, or the GPU one with --renderer gpu: a "
                  "GL context per rank), composited by direct send; rank 0 writes the PNG and "
                  "the stats (render/SCALEOUT.md)");
    cmd->add_flag("--mpi-barrier", o->mpiBarrier,
                  "--mpi: every rank waits for the others' parts before compositing, so that the "
                  "compositing time is its own (benchmarks); without it a rank's compositing "
                  "time includes waiting for slower ranks");
    cmd->add_option("--mpi-timeout-s", o->mpiTimeoutS,
                    "--mpi: a rank that has not answered after this many seconds fails the frame")
        ->capture_default_str();
    cmd->add_option("--stats", o->statsPath, "Write the frame's stats as JSON");
    cmd->add_option("--repeat", o->repeat,
                    "Draw the view this many times with one renderer (later frames warm); the "
                    "image and stats are the last frame's, frameMs lists every frame's time")
        ->capture_default_str()
        ->check(CLI::Range(1, 10000));
    cmd->callback([o] { runRender(*o); });
}

} // namespace bc::cli
