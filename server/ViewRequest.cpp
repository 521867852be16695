#include "server/ViewRequest.h"

#include "render/Error.h"
#include "server/InteractiveBudget.h"

#include <algorithm>
#include <cmath>

namespace bc::server {

render::Camera toCamera(const protocol::SetCamera& c) {
    render::Camera out;
    out.eye = {c.eye[0], c.eye[1], c.eye[2]};
    out.target = {c.target[0], c.target[1], c.target[2]};
    out.up = {c.up[0], c.up[1], c.up[2]};
    out.fovYDeg = c.fovYDeg;
    out.orthographic = c.orthographic;
    out.orthoHeight = c.orthoHeight;
    return out;
}

void applyModeAndClip(render::RenderOptions& options, const protocol::SetModeAndClip& m) {
    static_assert(int(protocol::BlendMode::Isosurface) == int(render::BlendMode::Isosurface));
    options.mode = render::BlendMode(m.mode); // the same values, in the same order
    options.isoValue = m.isoValue;
    options.clip = {};
    options.clip.cropped = m.cropped;
    options.clip.cropMin = m.cropMin;
    options.clip.cropMax = m.cropMax;
    for (const protocol::ClipPlane& p : m.planes)
        options.clip.planes[options.clip.planeCount++] = {p.normal, p.offset};
    options.clip.cap = m.cap;
}

render::RenderOptions toRenderOptions(const protocol::RenderOptions& o, std::uint32_t divisor) {
    using namespace protocol;
    render::RenderOptions r;
    r.width = InteractiveBudget::drawnEdge(o.width, std::max<std::uint32_t>(divisor, 1));
    r.height = InteractiveBudget::drawnEdge(o.height, std::max<std::uint32_t>(divisor, 1));
    r.stepVoxels = o.stepVoxels;
    r.earlyTermination = (o.techniques & kTechEarlyTermination) != 0;
    r.ertThreshold = o.ertThreshold;
    const bool bricks = (o.techniques & kTechBrickSkipping) != 0;
    r.skip = !bricks                                ? render::SkipMode::None
             : (o.techniques & kTechOctreeSkipping) ? render::SkipMode::All
                                                    : render::SkipMode::Bricks;
    r.occlusionFrustums = bricks && (o.techniques & kTechOcclusionFrustums) != 0;
    r.shading = (o.techniques & kTechShading) != 0;
    r.rayGuided = (o.techniques & kTechRayGuided) != 0;
    r.jitter = (o.techniques & kTechJitter) != 0;
    r.level = o.level == kLevelAutomatic ? 0 : o.level;
    r.interactive = o.level == kLevelAutomatic; // a coarser level when level 0 exceeds the pool
    return r;
}

namespace {

render::Placement toPlacement(protocol::Placement p) {
    switch (p) {
    case protocol::Placement::Value:
        return render::Placement::Value;
    case protocol::Placement::Fraction:
        return render::Placement::Fraction;
    case protocol::Placement::Percentile:
        return render::Placement::Percentile;
    }
    return render::Placement::Value;
}

} // namespace

std::shared_ptr<const render::TransferFunction>
toTransferFunction(const protocol::SetTransferFunction& m, const render::VolumeValueStats& stats,
                   const PresetTexts& configPresets) {
    using render::TransferFunction;
    if (m.kind == protocol::TfKind::Preset) {
        if (const auto it = configPresets.find(m.preset); it != configPresets.end())
            return std::make_shared<const TransferFunction>(
                TransferFunction::parse(it->second, "<preset " + m.preset + ">", stats));
        if (!TransferFunction::isPreset(m.preset))
            throw render::RenderInputError("SetTransferFunction", "preset",
                                           "not a preset of this server");
        return std::make_shared<const TransferFunction>(TransferFunction::preset(m.preset, stats));
    }
    std::vector<render::PointSpec> points;
    points.reserve(m.points.size());
    for (const auto& p : m.points)
        points.push_back({toPlacement(p.placement), p.position, p.rgba});
    return std::make_shared<const TransferFunction>(TransferFunction::fromPoints(
        points, "SetTransferFunction", stats, "SetTransferFunction", m.shading));
}

bool shadingFor(const protocol::RenderOptions& options,
                const protocol::SetTransferFunction& tfMessage,
                const render::TransferFunction& tf) {
    if ((options.techniques & protocol::kTechShading) == 0) return false;
    if (tfMessage.shadingSource == protocol::ShadingSource::Message) return tfMessage.shading;
    return tf.shading().value_or(true);
}

std::vector<std::uint8_t> upscaleBy(const std::vector<std::uint8_t>& drawn,
                                    std::uint32_t drawnWidth, std::uint32_t drawnHeight,
                                    std::uint32_t width, std::uint32_t height,
                                    std::uint32_t divisor) {
    std::vector<std::uint8_t> out(std::size_t(width) * height * 4);
    const std::uint32_t d = std::max<std::uint32_t>(divisor, 1);
    for (std::uint32_t y = 0; y < height; ++y) {
        const std::uint8_t* row =
            &drawn[std::size_t(std::min(y / d, drawnHeight - 1)) * drawnWidth * 4];
        std::uint8_t* to = &out[std::size_t(y) * width * 4];
        for (std::uint32_t x = 0; x < width; ++x)
            std::copy_n(row + std::size_t(std::min(x / d, drawnWidth - 1)) * 4, 4, to + 4 * x);
    }
    return out;
}

} // namespace bc::server
