#pragma once
// The frame the render thread is drawing for one session (RenderService): what its first turn
// resolved (renderer, options, view, cost, level and scale), the image so far and where its
// next slice starts, and the refinement pass's check. Render thread only.
#include "render/RenderTypes.h"
#include "render/View.h"
#include "server/FrameCache.h"
#include "server/RenderSlot.h"
#include "server/SlicePlanner.h"

#include <cstdint>
#include <optional>
#include <string>
#include <vector>

namespace bc::render {
class BrickPool;
struct RendererKind;
} // namespace bc::render

namespace bc::server {

/// A frame being drawn: what its first turn resolved, the image so far and where the next slice
/// starts. A frame that fits one slice lives for one turn.
struct FrameDrawing {
    RenderSlot::Job job;
    const render::RendererKind* kind = nullptr;
    /// What the interactive budget keys its rates by: the renderer's name, and the mode when
    /// it is not composite ("cpu mip").
    std::string drawing;
    render::RenderOptions options; ///< the whole frame's (region: whole)
    render::View view;
    std::uint64_t costPerPixel = 0;      ///< estimated samples of one ray (the longest)
    std::uint64_t cost = 0;              ///< of the whole frame
    std::optional<SlicePlanner> slicing; ///< a frame drawn in slices: where the next starts
    /// The frame drawn, 8-bit RGBA (a sliced frame's slices are converted as they come: at
    /// 4096^2 that is 64 MiB where float pixels would take 256).
    std::vector<std::uint8_t> rgba8;
    double sliceTargetMs = 0; ///< the next slice's length
    double slicesMs = 0;      ///< drawing the slices
    render::FrameStats stats;
    const render::BrickPool* pool = nullptr;
    Clock::time_point start;
    std::string rendererChoice;       ///< why d.kind draws it (RendererChoice::reason)
    std::optional<FrameKey> cacheKey; ///< set when the frame cache is on and had no frame
    /// An interactive frame is drawn at the requested size over this (rounded up).
    std::uint32_t divisor = 1;
    /// Sessions drawing interactive frames now, this one included: they share the budget.
    std::uint32_t sharers = 1;
    bool budgeted = false; ///< an interactive frame whose level and scale a time budget chose
    /// A refined frame's estimated PSNR against the converged image (render/
    /// RefinementEstimate.h); negative: none.
    double estimatedPsnrDb = -1;
    /// The first refinement pass at rest under an error bound, where the renderer draws a
    /// stride: the stride of the sparse frame at twice the pass's step that it is checked
    /// against (render::checkStride; 1: no such check), that frame (8-bit RGBA, the lattice's
    /// size) and the image row its next band starts at (a sliced frame draws it in bands of
    /// rows, first).
    std::uint32_t checkStride = 1;
    std::vector<std::uint8_t> check;
    std::uint32_t checkRow = 0;
    double checkMs = 0;      ///< drawing it
    double drawMs = 0;       ///< drawing its slices, not waiting for other sessions' turns
    std::uint32_t draws = 0; ///< render calls so far (slices and bands of the check)

    bool sliced() const { return slicing.has_value(); }
    bool checkDue() const { return checkStride > 1 && checkRow < options.height; }

    /// A refined frame drawn because an adaptive session's camera came to rest.
    bool refinement() const {
        return !job.requested && job.refined &&
               job.state.options.quality == protocol::Quality::Adaptive;
    }
};

} // namespace bc::server
