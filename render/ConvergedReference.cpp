#include "render/ConvergedReference.h"

#include "render/ImageMetrics.h"
#include "render/Renderer.h"

#include <chrono>
#include <cmath>
#include <limits>
#include <stdexcept>
#include <string>

namespace bc::render {

namespace {

void requirePositive(double value, const char* field) {
    if (!std::isfinite(value) || value <= 0.0)
        throw std::invalid_argument(std::string("convergence: ") + field +
                                    " must be finite and > 0 (got " + std::to_string(value) + ")");
}

double msSince(std::chrono::steady_clock::time_point start) {
    return std::chrono::duration<double, std::milli>(std::chrono::steady_clock::now() - start)
        .count();
}

} // namespace

void ConvergenceConfig::validate() const {
    requirePositive(toleranceRgba, "toleranceRgba");
    requirePositive(startStepVoxels, "startStepVoxels");
    requirePositive(floorStepVoxels, "floorStepVoxels");
    if (floorStepVoxels > startStepVoxels)
        throw std::invalid_argument(
            "convergence: floorStepVoxels (" + std::to_string(floorStepVoxels) +
            ") is above startStepVoxels (" + std::to_string(startStepVoxels) + ")");
    if (!std::isfinite(timeLimitMs) || timeLimitMs < 0.0)
        throw std::invalid_argument("convergence: timeLimitMs must be finite and >= 0 (got " +
                                    std::to_string(timeLimitMs) + ")");
}

const char* toString(ConvergenceStop stop) {
    switch (stop) {
    case ConvergenceStop::Converged:
        return "converged";
    case ConvergenceStop::FloorStep:
        return "floor step";
    case ConvergenceStop::TimeLimit:
        return "time limit";
    }
    return "?";
}

ConvergedReference renderConverged(Renderer& reference, const Scene& scene, const View& view,
                                   const RenderOptions& options, const ConvergenceConfig& config) {
    config.validate();
    RenderOptions o = options;
    o.stepVoxels = config.startStepVoxels;
    while (0.5 * o.stepVoxels >= config.floorStepVoxels)
        o.stepVoxels *= 0.5;
    try { // the finest step too, so a bad floor fails now, not after minutes
        o.validate();
    } catch (const std::invalid_argument& e) {
        throw std::invalid_argument("convergence: the finest step it could reach, " +
                                    std::to_string(o.stepVoxels) + " (floorStepVoxels " +
                                    std::to_string(config.floorStepVoxels) + "): " + e.what());
    }
    const auto start = std::chrono::steady_clock::now();
    ConvergedReference out;
    for (double step = config.startStepVoxels;; step *= 0.5) {
        o.stepVoxels = step;
        FrameStats stats;
        Image image = reference.render(scene, view, o, stats);
        const double nan = std::numeric_limits<double>::quiet_NaN();
        ConvergenceStep s{step, stats.totalMs, stats.samples, nan, nan};
        if (!out.steps.empty()) {
            const ImageComparison c = compareImages(out.image, image);
            s.maxAbsToPrevious = c.maxAbs;
            s.rmseToPrevious = c.rmse;
        }
        out.steps.push_back(s);
        out.image = std::move(image);
        out.imageStepVoxels = out.stepVoxels = step;
        // A NaN difference is not below the tolerance: the search goes on to the floor.
        if (s.maxAbsToPrevious < config.toleranceRgba) {
            out.converged = true;
            out.stop = ConvergenceStop::Converged;
            out.stepVoxels = 2.0 * step;
            break;
        }
        if (0.5 * step < config.floorStepVoxels) {
            out.stop = ConvergenceStop::FloorStep;
            break;
        }
        if (config.timeLimitMs > 0.0 && msSince(start) + 2.0 * s.renderMs > config.timeLimitMs) {
            out.stop = ConvergenceStop::TimeLimit;
            break;
        }
    }
    out.totalMs = msSince(start);
    return out;
}

} // namespace bc::render
