#include "render/Renderer.h"

#include <stdexcept>
#include <string>

namespace bc::render {

Renderer::~Renderer() = default;

Image Renderer::render(const brickstore::BrickStore& store, brickstore::BrickCache& cache,
                       const TransferFunction& tf, const Camera& camera,
                       const RenderOptions& options, FrameStats& stats) {
    options.validate();
    if (!mOwnClassifications) mOwnClassifications = std::make_unique<ClassificationCache>();
    return render(Scene{store, cache, tf, *mOwnClassifications},
                  View::of(camera, options.width, options.height), options, stats);
}

FrameClassification classifyFrame(const Scene& scene, std::uint32_t level,
                                  const RenderOptions& options, double stepVoxels,
                                  FrameStats& stats) {
    const bool octrees = options.skip == SkipMode::All;
    bool built = false;
    FrameClassification f;
    f.classification = scene.classifications.get(scene.store, level, scene.tf,
                                                 octrees ? &options.octree : nullptr, &built);
    f.table = f.classification->table(stepVoxels);
    f.occupancy = octrees ? f.classification->occupancy() : nullptr;
    if (options.preintegrate) f.preintegrated = f.classification->preintegrated();
    stats.octreeBricksRebuilt = built ? f.classification->build().bricksRebuilt : 0;
    stats.octreeRebuildMs = built ? f.classification->build().ms : 0.0;
    return f;
}

void Renderer::checkView(const View& view, const RenderOptions& options, bool drawsRegions,
                         bool drawsParts, bool drawsStrided) {
    if (view.width != options.width || view.height != options.height)
        throw std::invalid_argument("the view is " + std::to_string(view.width) + "x" +
                                    std::to_string(view.height) + ", the options ask for " +
                                    std::to_string(options.width) + "x" +
                                    std::to_string(options.height));
    if (!drawsRegions && !options.region.whole())
        throw std::invalid_argument("region: this renderer draws whole images only");
    if (!drawsParts && options.parts > 1)
        throw std::invalid_argument("parts: this renderer draws whole volumes only (the CPU "
                                    "and GPU raycasters draw parts)");
    if (!drawsStrided && options.stride > 1)
        throw std::invalid_argument("stride: this renderer draws every pixel (the CPU raycaster "
                                    "draws a stride)");
}

void Renderer::refusePreintegration(const RenderOptions& options, const char* renderer) {
    if (options.preintegrate)
        throw std::invalid_argument(std::string("preintegrate: the ") + renderer +
                                    " does not pre-integrate (the CPU raycaster and the reference "
                                    "do)");
}

} // namespace bc::render
