#include "render/Renderer.h"

#include "render/TransferFunction.h"

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
    const bool composite = options.mode == BlendMode::Composite;
    const bool octrees = options.skip == SkipMode::All && options.mode != BlendMode::Average;
    if (options.mode == BlendMode::Isosurface &&
        !(options.isoValue >= scene.tf.domainMin() && options.isoValue <= scene.tf.domainMax()))
        throw std::invalid_argument("iso: " + std::to_string(options.isoValue) +
                                    " is outside the volume's values [" +
                                    std::to_string(scene.tf.domainMin()) + ", " +
                                    std::to_string(scene.tf.domainMax()) + "]");
    bool built = false;
    FrameClassification f;
    f.classification =
        scene.classifications.get(scene.store, level, scene.tf, octrees ? &options.octree : nullptr,
                                  &built, SkipRule::of(options));
    f.table = f.classification->table(composite ? stepVoxels : 1.0);
    f.skipTable = composite ? f.table : f.classification->skipTable();
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

void Renderer::refuseModesAndClips(const RenderOptions& options, const char* renderer) {
    if (options.clip.any())
        throw std::invalid_argument(std::string(options.clip.cropped ? "crop" : "clip") + ": the " +
                                    renderer +
                                    ": whole volumes only (the raycasters and the reference "
                                    "crop and clip)");
    if (options.mode != BlendMode::Composite)
        throw std::invalid_argument(std::string("mode: the ") + renderer +
                                    ": composite only, not " + toString(options.mode) +
                                    " (the raycasters and the reference draw every mode)");
}

} // namespace bc::render
