#pragma once
// Long frames in slices (RenderService): a frame of a renderer that draws regions, and that would
// take longer than about a slice, is drawn a slice per turn. What a frame costs is estimated in
// cost units (samples): as a whole, an upper bound (every ray as long as the level's diagonal);
// per pixel, for sizing slices, its ray's samples inside the level's box over the step (plus one
// for the ray), so that rows that miss the volume are not taken for dense ones. Slices are made
// of about the units a renderer draws in the slice's time, at the speed it has shown.
//
// Nothing here reads a clock of its own: durations are reported (RendererSpeeds::learn), and
// drawNext times the pieces it draws by the clock it is handed (SliceHooks::now), so that a test
// drives it with a clock it moves. Render thread only.
#include "render/Camera.h"
#include "render/Image.h"
#include "render/RenderTypes.h"
#include "render/View.h"

#include <chrono>
#include <cstdint>
#include <functional>
#include <map>
#include <stdexcept>
#include <string>
#include <string_view>
#include <vector>

namespace bc::brickstore {
class BrickStore;
}

namespace bc::render {
struct LevelGeometry;
}

namespace bc::server {

struct FrameDrawing;
struct RenderServiceConfig;

/// What each renderer draws per millisecond, in cost units, learnt from the durations its
/// frames or slices took. The estimates are upper bounds whose truth varies across an image
/// (skipping, early ray termination, rays that miss): a slower speed is taken at once, so that a
/// slice that ran long is not followed by another, and a faster one is approached by halves.
class RendererSpeeds {
  public:
    /// Cost units (samples) per millisecond assumed of a renderer before it has drawn anything:
    /// low (2 M samples/s, the reference renderer's order on one slow core), so that a first
    /// frame that turns out heavy is sliced rather than drawn whole, and its first slice is
    /// short on any machine (at 20 M samples/s assumed, a first slice under ThreadSanitizer took
    /// 18 s). The measured speed replaces it from the first slice on.
    static constexpr double kFirstCostPerMs = 2000.0;

    /// The speed of `renderer`, or kFirstCostPerMs before it has drawn anything.
    double of(std::string_view renderer) const;
    /// `renderer` drew `cost` units in `ms` (as the caller measured it; under 0.01 ms counts as
    /// 0.01 ms).
    void learn(const std::string& renderer, double cost, double ms);

  private:
    std::map<std::string, double, std::less<>> mCostPerMs;
};

/// A frame's estimated cost.
struct FrameCost {
    std::uint64_t perPixel = 0; ///< samples of the longest ray: the level's diagonal over the step
    /// Of the whole frame: pixels x perPixel, or for a renderer whose cost follows the voxels it
    /// projects (RendererKind::objectOrder), the level's voxels plus the pixels.
    double total = 0;
};

/// The cost of a frame of `options` (its size and step) at level `g`.
FrameCost frameCost(const render::LevelGeometry& g, const render::RenderOptions& options,
                    bool objectOrder);

/// Whether a frame of `cost` units drawn at `costPerMs` is drawn in slices of about `sliceMs`:
/// when it would take more than one and a half.
bool drawnInSlices(double cost, double costPerMs, double sliceMs);

/// A frame over its cost cap: answered OutOfRange, not RenderFailed.
struct FrameRefused : std::runtime_error {
    using std::runtime_error::runtime_error;
};

/// Sets the cost of frame `d` (its kind, options and view resolved) at its level of `store`, and
/// whether it is drawn in slices (then d.slicing, its image and its first slice's length), as
/// `config` caps and slices frames and at the speed `frameSpeeds` has of its renderer.
/// @throw FrameRefused when the cost is over the cap of its kind (sliced or not).
void planSlices(FrameDrawing& d, const brickstore::BrickStore& store,
                const RenderServiceConfig& config, const RendererSpeeds& frameSpeeds);

/// A region of the frame and its estimated cost.
struct Slice {
    render::PixelRect region;
    double cost = 0;
};

/// Where a sliced frame's next slice starts and what its rows cost (computed as the cursor
/// reaches them).
class SlicePlanner {
  public:
    /// A frame of `view` (its width x height) over the level's box `box`, sampled every `stepMm`.
    SlicePlanner(const render::View& view, const render::Box& box, double stepMm);

    /// Estimated cost of pixel (x, y): its ray's samples inside the box, plus one for the ray.
    double pixelCost(std::uint32_t x, std::uint32_t y) const;
    /// Estimated cost of row `y` (kept once computed).
    double rowCost(std::uint32_t y);
    /// The next slice of about `budget` cost units (at least one pixel), and the cursor past it:
    /// whole rows from the cursor when it is at a row's start and its row fits, else a run of
    /// the cursor's row.
    Slice next(double budget);
    /// Whether every pixel has been in a slice.
    bool done() const { return mNextPixel >= std::uint64_t(mWidth) * mHeight; }
    /// Image rows from `row` on for the next band of the sparse frame `lattice` of this frame
    /// drawn at twice the step (a lattice row takes a stride-th of its image row's rays): whole
    /// lattice rows of about `budget` cost units, at least one.
    std::uint32_t checkRows(const render::PixelLattice& lattice, std::uint32_t row, double budget);

  private:
    render::ViewBasis mBasis;
    std::uint32_t mWidth, mHeight;
    render::Box mBox;
    double mStepMm;
    std::uint64_t mNextPixel = 0; ///< row-major cursor
    std::vector<double> mRowCost; ///< per row (< 0: not computed yet)
};

/// Copies `part`, converted to 8-bit RGBA, into `frame` (8-bit RGBA, `frameWidth` pixels a row)
/// at `at` (part's size).
void paste(std::vector<std::uint8_t>& frame, std::uint32_t frameWidth, const render::Image& part,
           const render::PixelRect& at);

/// The frame's statistics with those of its next slice (the first is the frame's so far).
void accumulate(render::FrameStats& total, const render::FrameStats& slice, bool first);

/// What drawing a frame's next piece needs of the render thread.
struct SliceHooks {
    /// Draws `options.region` of the frame (RenderService::drawRegion).
    std::function<render::Image(const render::RenderOptions& options, render::FrameStats& stats)>
        draw;
    /// How long the next slice should be beside the other sessions (RenderService::sliceMsBeside).
    std::function<double()> sliceMs;
    /// The clock the pieces are timed by.
    std::function<std::chrono::steady_clock::time_point()> now;
    /// Told of each slice drawn, and of each sparse frame a refinement pass was checked against.
    std::function<void()> sliceDrawn, checkDrawn;
    /// Whole frames against their upper-bound cost (whether to slice), and slices against their
    /// pixels' estimated samples (how large a slice is).
    RendererSpeeds* frameSpeeds = nullptr;
    RendererSpeeds* sliceSpeeds = nullptr;
};

/// Draws the next piece of frame `d` (prepared: FrameDrawing::slicing set when it is sliced);
/// true when the frame is complete. A first refinement pass checked against a sparse frame
/// (FrameDrawing::checkStride) draws that frame first: in the same turn when the pass is drawn
/// whole, in bands of rows, a turn each, when it is sliced.
bool drawNext(FrameDrawing& d, const SliceHooks& hooks);

} // namespace bc::server
