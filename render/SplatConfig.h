#pragma once
// What both hybrid splatters (render/HybridSplatter.h on the CPU, render/GpuSplatter.h on
// OpenGL) are configured with and count, apart from the splatters themselves, so that their
// shared preparation (render/detail/SplatPrep) depends on neither.
#include <cstdint>

namespace bc::render {

struct HybridSplatterConfig {
    double radiusVoxels = 1.25;        ///< sphere radius in units of the largest spacing
    double sigmaOverRadius = 0.5;      ///< kernel width (SplatFootprintConfig)
    double pointThresholdPixels = 0.5; ///< projected radius below which a voxel is a point
    double pointFilterPixels = 1.0;    ///< radius of a point's circular screen filter
    bool occlusionCulling = true;      ///< skip voxels whose tiles are all opaque
    std::uint32_t tilePixels = 8;      ///< edge of a culling tile
    /// Splats: the footprint of the exact ray-centre distance from a 1D table over d^2
    /// (fast); false: the paper's exact index and 2D (index, half angle) table. The two
    /// differ by the 2D table's error (SplatFootprint::kTableRelativeError).
    bool exactDistanceFootprint = true;
    /// Draw in horizontal bands of whole tiles on every core (TBB); the same image and
    /// counts, to the bit, as false (one band, the calling thread drawing).
    bool parallelDraw = true;
    /// Throws std::invalid_argument naming the field when a value is out of range.
    void validate() const;
};

/// What the last frame drew, beyond FrameStats (samples = points + splats).
struct HybridSplatStats {
    std::uint64_t points = 0, splats = 0;
    std::uint64_t culled = 0;        ///< visible voxels skipped by occlusion culling
    std::uint64_t bricksCulled = 0;  ///< planned bricks skipped whole (their tiles opaque)
    std::uint64_t leavesSkipped = 0; ///< empty octree leaves skipped unread
    std::uint64_t slabs = 0;         ///< point slabs composited
};

} // namespace bc::render
