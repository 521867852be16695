#pragma once
// Interactive frames on a time budget (issue 22, its first step): while a camera moves, the
// daemon draws each frame at the requested size divided by a whole number (1, 2, 3, 4, 6, 8)
// and scales it back up, choosing the divisor so that the frame is expected to take at most
// `[frames] interactive_ms`. The expectation comes from the frames drawn: per volume and
// renderer, the time per drawn pixel of its latest interactive frames. Image scale is the
// first thing given up because it costs least: on the shared scans a quarter-size frame at
// full resolution is both faster and closer to the converged image than a full-size frame
// of the next pyramid level (README, "Frames on a budget").
//
// The model is one rate per (volume, renderer): ms a frame = rate x pixels drawn. A frame
// that ran slower than predicted is believed at once; a faster one moves the rate half way,
// so one fast frame does not buy a larger image that then runs late. With a fixed cost per
// frame the rate measured at a small size overstates a larger one's, so the choice errs
// towards the smaller image rather than oscillating. Render thread only.
#include <cstdint>
#include <map>
#include <string>
#include <utility>

namespace bc::server {

class InteractiveBudget {
  public:
    /// The divisors tried, largest image first.
    static constexpr std::uint32_t kDivisors[] = {1, 2, 3, 4, 6, 8};
    /// The divisor when nothing is known yet of a volume and renderer: today's half size.
    static constexpr std::uint32_t kFirstDivisor = 2;
    /// No drawn edge is made shorter than this (unless the request's is).
    static constexpr std::uint32_t kMinEdge = 16;

    /// `targetMs` > 0: the time an interactive frame should take.
    explicit InteractiveBudget(double targetMs);

    double targetMs() const { return mTargetMs; }

    /// The divisor for the next interactive frame of `volume` drawn by `renderer` at a
    /// requested `width` x `height`: the smallest whose frame is expected within the target,
    /// else the largest allowed.
    std::uint32_t divisor(const std::string& volume, const std::string& renderer,
                          std::uint32_t width, std::uint32_t height) const;

    /// An interactive frame of `volume` by `renderer`, `pixels` drawn, took `ms`.
    void record(const std::string& volume, const std::string& renderer, std::uint64_t pixels,
                double ms);

    /// The expected ms of a frame of `pixels` (negative while nothing is known).
    double expectedMs(const std::string& volume, const std::string& renderer,
                      std::uint64_t pixels) const;

    /// The drawn edge for a requested `edge` and `divisor`: ceil(edge / divisor).
    static std::uint32_t drawnEdge(std::uint32_t edge, std::uint32_t divisor) {
        return (edge + divisor - 1) / divisor;
    }

  private:
    double mTargetMs;
    std::map<std::pair<std::string, std::string>, double> mMsPerPixel;
};

} // namespace bc::server
