#pragma once
// The true image: the reference renderer's frame at a step small enough that
// halving it no longer changes the image by more than a tolerance. The reference at the same
// step as a renderer shows that the renderer implements the model; only the converged frame
// shows how far a frame is from the image the model converges to (render/OPTICS.md).
#include "render/Image.h"
#include "render/RenderTypes.h"

#include <cstdint>
#include <string>
#include <vector>

namespace bc::render {

class Renderer;
struct Scene;
struct View;

struct ConvergenceConfig {
    double startStepVoxels = 1.0; ///< the first step; each further frame halves it
    /// Converged once the largest |a-b| over the four channels of all pixels of two successive
    /// frames (premultiplied RGBA in [0, 1], before any 8-bit rounding) is below this.
    double toleranceRgba = 0.5 / 255.0;
    /// No frame at a step below this: the search stops there, not converged. (1/64: the
    /// smallest power of two that RenderOptions accepts, which is 0.01.)
    double floorStepVoxels = 1.0 / 64.0;
    /// 0: none. Otherwise no halving is started whose frame (predicted as twice the last
    /// one's time) would end after this many ms from the start: not converged.
    double timeLimitMs = 0.0;

    /// @throw std::invalid_argument naming the field: a tolerance or step that is not finite
    /// and > 0, a floor above the start, a negative or non-finite time limit.
    void validate() const;
};

/// One frame of the search.
struct ConvergenceStep {
    double stepVoxels = 0.0;
    double renderMs = 0.0;
    std::uint64_t samples = 0;
    /// Max abs difference (RGBA) to the frame at twice this step; NaN for the first frame.
    double maxAbsToPrevious = 0.0;
    double rmseToPrevious = 0.0; ///< the same as RMSE over RGBA (NaN for the first frame)
};

enum class ConvergenceStop { Converged, FloorStep, TimeLimit };

/// "converged", "floor step" or "time limit".
const char* toString(ConvergenceStop stop);

struct ConvergedReference {
    Image image;                ///< the last (finest) frame drawn
    double imageStepVoxels = 0; ///< its step
    /// Converged: the step whose halving changed the image by under the tolerance
    /// (2 * imageStepVoxels). Not converged: imageStepVoxels (the finest reached).
    double stepVoxels = 0;
    bool converged = false;
    ConvergenceStop stop = ConvergenceStop::FloorStep;
    std::vector<ConvergenceStep> steps; ///< every frame, coarsest first
    double totalMs = 0;
};

/// Draws `options` with `reference` at config.startStepVoxels, then at half that step, and so
/// on, until two successive frames differ by less than the tolerance, the next step would be
/// below the floor, or the time limit would be passed. `reference` should be the float64
/// reference renderer (any Renderer works; the result is that renderer's limit). Options other
/// than stepVoxels are used as given.
/// @throw std::invalid_argument on a bad config or options (also at the finest step the search
/// could reach), before anything is drawn; what reference.render throws.
ConvergedReference renderConverged(Renderer& reference, const Scene& scene, const View& view,
                                   const RenderOptions& options, const ConvergenceConfig& config);

} // namespace bc::render
