#include "server/SlicePlanner.h"

#include "brickstore/BrickStore.h"
#include "render/BrickPlan.h"
#include "render/RendererRegistry.h"
#include "server/FrameDrawing.h"
#include "server/RenderService.h"

#include <algorithm>
#include <cmath>
#include <cstdio>

#include <glm/geometric.hpp>

namespace bc::server {

namespace {

std::string giga(std::uint64_t samples) {
    char text[32];
    std::snprintf(text, sizeof text, "%.3g", double(samples) / double(1ull << 30));
    return text;
}

double msSince(const SliceHooks& hooks, std::chrono::steady_clock::time_point t) {
    return std::chrono::duration<double, std::milli>(hooks.now() - t).count();
}

/// Draws the sparse frame a first refinement pass is checked against (render/
/// RefinementEstimate.h), the pass's lattice of pixels at twice its step: its next band of about
/// `budget` cost units (slices' units), or, at 0, all of it that is left. Returns the
/// milliseconds spent loading bricks.
double drawCheck(FrameDrawing& d, const SliceHooks& hooks, double budget) {
    const auto start = hooks.now();
    const render::PixelLattice lattice{d.checkStride};
    const std::uint32_t w = d.options.width, h = d.options.height;
    if (d.check.empty()) d.check.assign(std::size_t(lattice.first(w)) * lattice.first(h) * 4, 0);
    render::RenderOptions options = d.options;
    options.stride = d.checkStride;
    options.stepVoxels = 2.0 * d.options.stepVoxels; // the session's step: a power of two apart
    options.hostKeptBefore = d.stats.hostKeptBytes;  // its bricks count as the frame's
    // Whole lattice rows from d.checkRow, about `budget` cost units, at least one (a sliced
    // frame's); else all that is left.
    const std::uint32_t rows =
        budget > 0 ? d.slicing->checkRows(lattice, d.checkRow, budget) : h - d.checkRow;
    options.region = {0, d.checkRow, w, rows};
    const std::optional<render::PixelRect> at = lattice.of(options.region);
    render::FrameStats stats;
    const render::Image band = hooks.draw(options, stats);
    paste(d.check, lattice.first(w), band, *at);
    accumulate(d.stats, stats, d.draws++ == 0);
    d.checkRow += rows;
    d.checkMs += msSince(hooks, start);
    if (!d.checkDue()) hooks.checkDrawn();
    return std::min(stats.uploadMs, msSince(hooks, start));
}

/// Draws the frame's next slice; true when it was the last.
bool drawNextSlice(FrameDrawing& d, const SliceHooks& hooks) {
    const auto start = hooks.now();
    const double perMs = hooks.sliceSpeeds->of(d.kind->name);
    render::RenderOptions options = d.options;
    if (d.draws == 0) d.sliceTargetMs = hooks.sliceMs();
    const Slice slice = d.slicing->next(d.sliceTargetMs * perMs);
    options.region = slice.region;
    options.hostKeptBefore = d.stats.hostKeptBytes; // the slices keep one frame's bricks
    render::FrameStats stats;
    const render::Image part = hooks.draw(options, stats);
    paste(d.rgba8, d.options.width, part, options.region);
    accumulate(d.stats, stats, d.draws++ == 0);
    // The speed of the rays alone: loading bricks is a cost per slice, not per pixel (when the
    // frame's bricks exceed the host budget, a brick whose footprint spans several slices is
    // loaded by each). Slices are made long enough that it stays at most half of each.
    const double ms = msSince(hooks, start), loadMs = std::min(stats.uploadMs, ms);
    hooks.sliceSpeeds->learn(d.kind->name, slice.cost, ms - loadMs);
    d.sliceTargetMs = std::max(hooks.sliceMs(), 2.0 * loadMs);
    d.slicesMs += msSince(hooks, start);
    d.drawMs = d.checkMs + d.slicesMs;
    hooks.sliceDrawn();
    if (!d.slicing->done()) return false;
    // The whole frame's speed too, so that a frame like it is sliced only when it must be.
    hooks.frameSpeeds->learn(d.kind->name, double(d.cost), d.slicesMs);
    return true;
}

} // namespace

double RendererSpeeds::of(std::string_view renderer) const {
    const auto rate = mCostPerMs.find(renderer);
    return rate == mCostPerMs.end() ? kFirstCostPerMs : rate->second;
}

void RendererSpeeds::learn(const std::string& renderer, double cost, double ms) {
    const double perMs = cost / std::max(ms, 0.01);
    auto [it, fresh] = mCostPerMs.try_emplace(renderer, perMs);
    if (!fresh) it->second = perMs < it->second ? perMs : 0.5 * (it->second + perMs);
}

FrameCost frameCost(const render::LevelGeometry& g, const render::RenderOptions& options,
                    bool objectOrder) {
    const std::uint64_t pixels = std::uint64_t(options.width) * options.height;
    const double diagonal = glm::length(g.box.size());
    FrameCost c;
    c.perPixel = std::uint64_t(std::ceil(diagonal / (options.stepVoxels * g.minSpacing())));
    const double voxels = double(g.dims[0]) * double(g.dims[1]) * double(g.dims[2]);
    c.total = objectOrder ? voxels + double(pixels) : double(pixels) * double(c.perPixel);
    return c;
}

bool drawnInSlices(double cost, double costPerMs, double sliceMs) {
    return cost / costPerMs > 1.5 * sliceMs;
}

void planSlices(FrameDrawing& d, const brickstore::BrickStore& store,
                const RenderServiceConfig& config, const RendererSpeeds& frameSpeeds) {
    // Cost: an upper bound of the samples (every ray as long as the level's diagonal), or the
    // voxels a splatter projects.
    const auto levels = std::uint32_t(store.layout().levels().size());
    const auto level = std::min<std::uint32_t>(std::uint32_t(d.options.level), levels - 1);
    const render::LevelGeometry g = render::LevelGeometry::of(store, level);
    const FrameCost cost = frameCost(g, d.options, d.kind->objectOrder);
    d.costPerPixel = cost.perPixel;
    const std::string& name = d.kind->name;
    const bool sliceable = d.kind->regions;
    const std::uint64_t cap = sliceable ? config.maxFrameSamples : config.maxUnslicedSamples;
    if (cost.total > double(cap))
        throw FrameRefused(
            "frame cost " + giga(std::uint64_t(std::min(cost.total, 1e19))) + " Gi samples (" +
            std::to_string(d.options.width) + "x" + std::to_string(d.options.height) + " pixels, " +
            std::to_string(d.costPerPixel) + " samples per ray, " + name +
            ") is over the server's cap of " + giga(cap) + " Gi samples (" +
            (sliceable ? "frames.max_frame_gsamples" : "frames.max_unsliced_gsamples") + ")");
    d.cost = std::uint64_t(cost.total);
    const double perMs = frameSpeeds.of(name);
    if (sliceable && drawnInSlices(cost.total, perMs, double(config.sliceMs))) {
        d.rgba8.assign(std::size_t(d.options.width) * d.options.height * 4, 0);
        d.slicing.emplace(d.view, g.box, d.options.stepVoxels * g.minSpacing());
        d.sliceTargetMs = config.sliceMs;
    }
}

SlicePlanner::SlicePlanner(const render::View& view, const render::Box& box, double stepMm)
    : mBasis(view.basis), mWidth(view.width), mHeight(view.height), mBox(box), mStepMm(stepMm),
      mRowCost(view.height, -1.0) {}

double SlicePlanner::pixelCost(std::uint32_t x, std::uint32_t y) const {
    const render::Ray ray = mBasis.ray(x, y, mWidth, mHeight);
    const auto [t0, t1] = render::intersectBox(ray, mBox);
    return 1.0 + std::max(0.0, (t1 - std::max(t0, 0.0)) / mStepMm);
}

double SlicePlanner::rowCost(std::uint32_t y) {
    if (mRowCost[y] < 0) {
        double sum = 0;
        for (std::uint32_t x = 0; x < mWidth; ++x)
            sum += pixelCost(x, y);
        mRowCost[y] = sum;
    }
    return mRowCost[y];
}

Slice SlicePlanner::next(double budget) {
    const std::uint32_t w = mWidth, h = mHeight;
    const auto x = std::uint32_t(mNextPixel % w), y = std::uint32_t(mNextPixel / w);
    Slice s;
    double& cost = s.cost;
    if (x == 0 && rowCost(y) <= budget) {
        std::uint32_t rows = 0;
        while (y + rows < h && cost + rowCost(y + rows) <= budget)
            cost += rowCost(y + rows++);
        s.region = {0, y, w, rows};
    } else {
        std::uint32_t n = 0;
        while (x + n < w && (n == 0 || cost + pixelCost(x + n, y) <= budget))
            cost += pixelCost(x + n++, y);
        s.region = {x, y, n, 1};
    }
    mNextPixel += s.region.pixels();
    return s;
}

std::uint32_t SlicePlanner::checkRows(const render::PixelLattice& lattice, std::uint32_t row,
                                      double budget) {
    double cost = 0;
    std::uint32_t j = lattice.first(row);
    do
        cost += rowCost(lattice.pixel(j)) / (2.0 * lattice.stride);
    while (++j < lattice.first(mHeight) && cost < budget);
    return (j < lattice.first(mHeight) ? lattice.pixel(j) : mHeight) - row;
}

void paste(std::vector<std::uint8_t>& frame, std::uint32_t frameWidth, const render::Image& part,
           const render::PixelRect& at) {
    const auto bytes = render::toRgba8(part);
    const std::size_t row = std::size_t(part.width) * 4;
    for (std::uint32_t y = 0; y < part.height; ++y)
        std::copy_n(&bytes[y * row], row, &frame[(std::size_t(at.y + y) * frameWidth + at.x) * 4]);
}

void accumulate(render::FrameStats& total, const render::FrameStats& slice, bool first) {
    if (first)
        total = slice;
    else
        render::addSlice(total, slice);
}

bool drawNext(FrameDrawing& d, const SliceHooks& hooks) {
    if (d.checkDue() && !d.sliced()) {
        drawCheck(d, hooks, 0); // whole, and the pass in the same turn
    } else if (d.checkDue()) {  // a band of it is this turn's slice
        if (d.draws == 0) d.sliceTargetMs = hooks.sliceMs();
        const double loadMs =
            drawCheck(d, hooks, d.sliceTargetMs * hooks.sliceSpeeds->of(d.kind->name));
        d.sliceTargetMs = std::max(hooks.sliceMs(), 2.0 * loadMs);
        d.drawMs = d.checkMs;
        return false;
    }
    if (d.sliced()) return drawNextSlice(d, hooks);
    const auto start = hooks.now();
    render::FrameStats stats;
    d.rgba8 = render::toRgba8(hooks.draw(d.options, stats));
    accumulate(d.stats, stats, d.draws++ == 0);
    const double ms = msSince(hooks, start);
    d.drawMs = d.checkMs + ms;
    hooks.frameSpeeds->learn(d.kind->name, double(d.cost), ms);
    return true;
}

} // namespace bc::server
