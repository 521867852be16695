#pragma once
// Ray-guided residency (render/RESIDENCY.md): what the last frame's rays told the raycaster
// about each brick of its plan. A planned brick no unsaturated ray entered is "hidden"
// (behind saturated rays, or between them); the next frame of the same scene defers loading
// it while the pool lacks it, and its rays ask for it if they reach it after all.
#include "render/BrickPlan.h"

#include <cstdint>
#include <vector>

namespace bc::render::detail {

class RayGuide {
  public:
    /// The plan's sampled bricks (indices into plan.drawn) that the last frame of `scene`
    /// found hidden, less those `keep(index)` says to draw anyway.
    template <class Keep>
    std::vector<std::size_t> deferrable(const BrickPlan& plan, std::uint64_t scene,
                                        std::uint64_t brickCount, Keep&& keep) const {
        std::vector<std::size_t> out;
        if (scene != mScene || mState.size() != brickCount) return out;
        for (std::size_t i = 0; i < plan.drawn.size(); ++i) {
            const PlannedBrick& b = plan.drawn[i];
            if (b.draw == BrickDraw::Sampled && mState[b.index] == kHidden && !keep(b.index))
                out.push_back(i);
        }
        return out;
    }

    /// True when the last frame of `scene` planned brick `index` and no unsaturated ray
    /// entered it.
    bool hidden(std::uint64_t scene, std::uint64_t index) const {
        return scene == mScene && index < mState.size() && mState[index] == kHidden;
    }

    /// This frame's findings: `entered[i]` is non-zero when an unsaturated ray entered brick i
    /// of the level (resident or asked for). Bricks outside the plan become unknown.
    void record(const BrickPlan& plan, std::uint64_t scene,
                const std::vector<std::uint32_t>& entered);

    /// Forget everything (another volume or level, or feedback switched off).
    void reset() {
        mState.clear();
        mScene = 0;
    }

  private:
    static constexpr std::uint8_t kUnknown = 0, kEntered = 1, kHidden = 2;
    std::vector<std::uint8_t> mState; ///< per brick of the level
    std::uint64_t mScene = 0;
};

} // namespace bc::render::detail
