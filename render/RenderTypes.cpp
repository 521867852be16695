#include "render/RenderTypes.h"

#include <algorithm>
#include <cmath>
#include <stdexcept>

namespace bc::render {

SkipMode parseSkipMode(const std::string& text) {
    if (text == "none") return SkipMode::None;
    if (text == "bricks") return SkipMode::Bricks;
    if (text == "all") return SkipMode::All;
    throw std::invalid_argument("skip mode '" + text + "' is not one of none, bricks, all");
}

const char* toString(SkipMode mode) {
    switch (mode) {
    case SkipMode::None:
        return "none";
    case SkipMode::Bricks:
        return "bricks";
    case SkipMode::All:
        return "all";
    }
    return "?";
}

BlendMode parseBlendMode(const std::string& text) {
    if (text == "composite") return BlendMode::Composite;
    if (text == "mip") return BlendMode::Maximum;
    if (text == "minip") return BlendMode::Minimum;
    if (text == "average") return BlendMode::Average;
    if (text == "iso") return BlendMode::Isosurface;
    throw std::invalid_argument("mode '" + text +
                                "' is not one of composite, mip, minip, average, iso");
}

const char* toString(BlendMode mode) {
    switch (mode) {
    case BlendMode::Composite:
        return "composite";
    case BlendMode::Maximum:
        return "mip";
    case BlendMode::Minimum:
        return "minip";
    case BlendMode::Average:
        return "average";
    case BlendMode::Isosurface:
        return "iso";
    }
    return "?";
}

float rayJitter(std::uint32_t x, std::uint32_t y) {
    // 2^32 / plastic number and 2^32 / plastic number^2, rounded; wrap-around is the fract.
    const std::uint32_t h = x * 3242174889u + y * 2447445414u;
    return float(h >> 8) * 0x1p-24f;
}

void RenderOptions::validate() const {
    constexpr std::uint32_t kMaxEdge = 16384, kMaxStride = 256;
    if (width == 0 || height == 0 || width > kMaxEdge || height > kMaxEdge)
        throw std::invalid_argument("size: " + std::to_string(width) + "x" +
                                    std::to_string(height) + " is outside 1.." +
                                    std::to_string(kMaxEdge));
    if (!(stepVoxels >= 0.01 && stepVoxels <= 64.0))
        throw std::invalid_argument("step: must lie in [0.01, 64] voxels");
    if (!(ertThreshold > 0.0 && ertThreshold <= 1.0))
        throw std::invalid_argument("ert: threshold must lie in (0, 1]");
    if (level < 0) throw std::invalid_argument("level: must not be negative");
    if (!region.whole() && (region.height == 0 || region.x >= width || region.y >= height ||
                            region.width > width - region.x || region.height > height - region.y))
        throw std::invalid_argument(
            "region: " + std::to_string(region.width) + "x" + std::to_string(region.height) +
            " at " + std::to_string(region.x) + "," + std::to_string(region.y) + " is not inside " +
            std::to_string(width) + "x" + std::to_string(height));
    if (parts == 0 || parts > 4096 || part >= parts)
        throw std::invalid_argument("parts: part " + std::to_string(part) + " of " +
                                    std::to_string(parts) +
                                    " (parts must lie in 1..4096, part "
                                    "below parts)");
    if (stride == 0 || stride > kMaxStride)
        throw std::invalid_argument("stride: " + std::to_string(stride) + " is outside 1.." +
                                    std::to_string(kMaxStride));
    if (stride / 2 >= width || stride / 2 >= height)
        throw std::invalid_argument("stride: " + std::to_string(stride) + " leaves no pixel of " +
                                    std::to_string(width) + "x" + std::to_string(height));
    if (stride > 1 && parts > 1)
        throw std::invalid_argument("stride: " + std::to_string(stride) +
                                    " draws the whole volume (one part)");
    if (!region.whole() && !lattice().of(region))
        throw std::invalid_argument("stride: the region " + std::to_string(region.width) + "x" +
                                    std::to_string(region.height) + " at " +
                                    std::to_string(region.x) + "," + std::to_string(region.y) +
                                    " holds no pixel of stride " + std::to_string(stride));
    if (cellVoxels != 0 && (cellVoxels > 64 || (cellVoxels & (cellVoxels - 1)) != 0))
        throw std::invalid_argument("cells: " + std::to_string(cellVoxels) +
                                    " voxels; 0 (none) or a power of two up to 64");
    if (mode == BlendMode::Isosurface && !std::isfinite(isoValue))
        throw std::invalid_argument("iso: the iso value must be a finite number");
    if (mode != BlendMode::Composite && preintegrate)
        throw std::invalid_argument(std::string("preintegrate: mode ") + toString(mode) +
                                    " takes no segments (composite only)");
    if (clip.cap && isProjection(mode))
        throw std::invalid_argument(std::string("cap: mode ") + toString(mode) +
                                    " draws no surface to cap (composite and isosurface only)");
    clip.validate();
    octree.validate();
    occlusion.validate();
}

void OcclusionConfig::validate() const {
    if (blockPixels < 1 || blockPixels > 64)
        throw std::invalid_argument("occlusion block size must lie in 1..64 pixels, got " +
                                    std::to_string(blockPixels));
    if (probeEvery < 2)
        throw std::invalid_argument("occlusion probe interval must be at least 2 frames");
}

void addSlice(FrameStats& frame, const FrameStats& slice) {
    FrameStats& f = frame;
    const FrameStats& s = slice;
    f.samples += s.samples;
    f.oracleSamples += s.oracleSamples;
    f.bricksCulled = std::min(f.bricksCulled, s.bricksCulled);
    f.bricksSkipped = std::max(f.bricksSkipped, s.bricksSkipped);
    f.bricksVisited = std::max(f.bricksVisited, s.bricksVisited);
    f.bricksConstant = std::max(f.bricksConstant, s.bricksConstant);
    f.bricksUploaded += s.bricksUploaded;
    f.bytesUploaded += s.bytesUploaded;
    f.batches += s.batches;
    f.bricksEntered = std::max(f.bricksEntered, s.bricksEntered);
    f.bricksDeferred += s.bricksDeferred;
    f.bricksRequested += s.bricksRequested;
    f.resumePasses += s.resumePasses;
    f.guidedFallback = f.guidedFallback || s.guidedFallback;
    f.bricksUnreached += s.bricksUnreached;
    f.hostKeptBytes += s.hostKeptBytes;
    f.octreeLeaps += s.octreeLeaps;
    f.samplesRaising += s.samplesRaising;
    f.octreeBricksRebuilt += s.octreeBricksRebuilt;
    f.octreeRebuildMs += s.octreeRebuildMs;
    f.cellBricksBuilt += s.cellBricksBuilt;
    f.cellBuildMs += s.cellBuildMs;
    f.cellBricks = std::max(f.cellBricks, s.cellBricks);
    if (s.occlusionUsed && !f.occlusionUsed) {
        f.occlusionUsed = true;
        f.occlusionReason = s.occlusionReason;
    }
    f.occlusionFrustums += s.occlusionFrustums;
    f.occlusionTriangles += s.occlusionTriangles;
    f.occlusionBuildMs += s.occlusionBuildMs;
    f.samplesSavedByStart += s.samplesSavedByStart;
    f.uploadMs += s.uploadMs;
    f.renderMs += s.renderMs;
    f.readbackMs += s.readbackMs;
    f.totalMs += s.totalMs;
}

} // namespace bc::render
