#pragma once
// The CPU raycaster's rays (render/CpuRaycaster.cpp): their states across the passes of a
// frame, and where on the image plane each one starts.
#include "render/RenderTypes.h"
#include "render/detail/CpuRay.h"

#include <cstddef>
#include <cstdint>
#include <memory>
#include <type_traits>

#include <glm/vec2.hpp>

namespace bc::render::detail {

/// The region's ray states, left unconstructed here: the pass's workers construct each on
/// batch 0 as they first touch it (marchPass; planBatches always gives a batch 0, every pixel
/// of the region in it), so a 512² frame's 5 MB is not written twice, once by one thread.
/// Beside them the rays' resume data (RayResume), written only by rays that stop to wait for a
/// later batch: a frame of one batch never touches it.
class RayStates {
  public:
    explicit RayStates(std::size_t n)
        : mData(std::allocator<RayState>().allocate(n)),
          mResume(std::allocator<RayResume>().allocate(n)), mSize(n) {}
    ~RayStates() {
        std::allocator<RayState>().deallocate(mData, mSize);
        std::allocator<RayResume>().deallocate(mResume, mSize);
    }
    RayStates(const RayStates&) = delete;
    RayStates& operator=(const RayStates&) = delete;
    RayState& operator[](std::size_t i) { return mData[i]; }
    const RayState& operator[](std::size_t i) const { return mData[i]; }
    RayResume& resume(std::size_t i) { return mResume[i]; }

  private:
    static_assert(std::is_trivially_destructible_v<RayState>);
    static_assert(std::is_trivially_destructible_v<RayResume>);
    RayState* mData;
    RayResume* mResume;
    std::size_t mSize;
};

/// The image-plane position (Frame's sx, sy in [-1, 1]) of the centre of lattice pixel (x, y).
inline glm::vec2 planeOf(const Frame& f, PixelLattice lattice, std::uint32_t x, std::uint32_t y) {
    return {2.0f * (float(lattice.pixel(x)) + 0.5f) / f.width - 1.0f,
            1.0f - 2.0f * (float(lattice.pixel(y)) + 0.5f) / f.height};
}

} // namespace bc::render::detail
