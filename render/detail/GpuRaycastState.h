#pragma once
// What the GPU raycaster's sources (render/GpuRaycaster*.cpp) share: its GL state (program,
// render targets, the frame's buffers, the GPU's copies of the classification), the level a
// frame draws at, the pins of a batch and the frame's clock. Render thread only.
#include "render/GpuRaycaster.h"
#include "render/Renderer.h"
#include "render/detail/Gl.h"
#include "render/detail/OcclusionFrustums.h"
#include "render/detail/RayGuide.h"

#include <chrono>
#include <cstddef>
#include <cstdint>
#include <memory>
#include <vector>

namespace bc::render {

class FineOccupancy;

namespace detail {

using Clock = std::chrono::steady_clock;
inline double msSince(Clock::time_point t) {
    return std::chrono::duration<double, std::milli>(Clock::now() - t).count();
}

/// A composite, uncut frame: the only kind that may start its rays at the last frame's
/// occlusion frustums and record its first hits for the next (those of a projection or a cut
/// are not the scene's surfaces), and the kind the plain shader build draws.
inline bool compositeUncut(const RenderOptions& options) {
    return options.mode == BlendMode::Composite && !options.clip.any();
}

/// Unpins the pool's slots when a batch ends, also when a brick load throws mid-batch.
struct BatchPins {
    BrickPool& pool;
    ~BatchPins() { pool.unpinAll(); }
};

/// FNV-1a over the bytes mixed in: the keys under which the raycaster keeps what a frame put
/// on the GPU (the first hits' scene, the running skip's bounds).
struct KeyHash {
    std::uint64_t h = 1469598103934665603ull;
    void mix(const void* data, std::size_t bytes) {
        for (std::size_t i = 0; i < bytes; ++i)
            h = (h ^ static_cast<const unsigned char*>(data)[i]) * 1099511628211ull;
    }
    template <class V> void mix(const V& value) { mix(&value, sizeof value); }
};

} // namespace detail

struct GpuRaycaster::Gpu {
    /// The shader built for composite, uncut frames and with the modes and cuts
    /// (ShaderPrograms.cpp); `program` is the frame's, one of the two (prepare()).
    gl::Program plainProgram, modesProgram;
    GLuint program = 0;
    gl::VertexArray vao;
    gl::Texture tf;
    gl::Buffer pages, counters;
    gl::Buffer occupancy; ///< OccupancyTrees::words() of classification occupancyId
    std::uint64_t occupancyWords = 0, occupancyId = 0;
    /// The running skip's bounds in pool texels: per brick of the level, then per leaf of
    /// each (GpuRaycaster::uploadRunningBounds), for the frame of key runningKey (0: none yet).
    gl::Buffer runningBounds;
    std::uint64_t runningKey = 0, runningFloats = 0;
    /// The distance maps: a copy of the FineOccupancy pool of (cellsId, cellsVoxels), the
    /// slots flagged in cellsUploaded copied; and per brick of the level its map's word offset.
    gl::Buffer cells, cellBase;
    std::uint64_t cellsId = 0, cellsVoxels = 0, cellsCapacity = 0;
    std::vector<std::uint8_t> cellsUploaded;
    std::uint64_t cellBaseBricks = 0;
    std::unique_ptr<detail::OcclusionFrustums> occlusion; ///< created on first use
    gl::Buffer feedback; ///< per brick of the level: entered, then asked for (2 uints)
    std::uint64_t feedbackBricks = 0;
    detail::RayGuide guide;
    gl::Texture accum[2];
    gl::Framebuffer fbo[2];
    gl::Texture resumeAt; ///< R32I: the sample a stopped ray goes on from, or -1
    std::uint32_t width = 0, height = 0;

    // Setup (GpuRaycaster.cpp).
    void ensureTargets(std::uint32_t w, std::uint32_t h);
    void uploadTable(const TransferFunctionTable& table);

    // A frame's buffers and bindings (GpuRaycasterDraw.cpp).
    /// The feedback buffer for `brickCount` bricks, zeroed and bound.
    void resetFeedback(std::uint64_t brickCount);
    /// Zeroes the asked-for half of the feedback buffer (the next round's requests).
    void clearRequests();
    /// Binds the program, the pool texture, the table, the storage buffers and the targets.
    void bindForDraw(GLuint poolTexture);

    // The distance maps (GpuRaycasterResidency.cpp).
    /// Binds one-word placeholders for a frame without maps (the bindings must name buffers).
    void bindCellPlaceholders();
    /// Makes the copy of `fine`'s pool anew when it is another classification's (`id`) or size.
    void ensureCellCopy(const FineOccupancy& fine, std::uint64_t id);
    /// Copies the slots of `offsets` (words into fine's pool) not copied yet.
    void copyNewCellSlots(const FineOccupancy& fine, const std::vector<std::uint32_t>& offsets);
    /// Uploads the per-brick map offsets.
    void uploadCellBase(const std::vector<std::uint32_t>& offsets);
};

/// The level a frame of `scene` draws at and what it classifies through (chooseLevel plans
/// with the table of the asked level: tables do not depend on the level).
struct GpuRaycaster::Prepared {
    std::uint32_t level = 0;
    FrameClassification classified;
};

} // namespace bc::render
