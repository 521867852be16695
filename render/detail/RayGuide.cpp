#include "render/detail/RayGuide.h"

namespace bc::render::detail {

void RayGuide::record(const BrickPlan& plan, std::uint64_t scene,
                      const std::vector<std::uint32_t>& entered) {
    mScene = scene;
    mState.assign(entered.size(), kUnknown);
    for (const PlannedBrick& b : plan.drawn)
        if (b.draw == BrickDraw::Sampled && b.index < entered.size())
            mState[b.index] = entered[b.index] != 0 ? kEntered : kHidden;
}

} // namespace bc::render::detail
