#pragma once
// The CPU raycaster's passes (render/CpuRaycaster.cpp): the rays marched over 8x8 tiles on
// every core, each tile's rays one by one (the scalar or the SIMD brick march) or in packets
// (render/detail/CpuMarchSimd.h), and the region's image from their colours.
#include "brickstore/VoxelType.h"
#include "render/Image.h"
#include "render/Partition.h"
#include "render/RenderTypes.h"
#include "render/detail/CpuRay.h"
#include "render/detail/CpuRaycastRays.h"

#include <cstdint>
#include <vector>

namespace bc::render::detail {

/// One pass over the rays of `rect` (within `region`) for the bricks of batch f.batch, whose
/// voxels are of `type` (rays: the region's, row by row; only those of rect are touched). Both
/// rectangles are of the lattice's pixels (RenderOptions::stride): ray (x, y) is the ray of
/// image pixel (lattice.pixel(x), lattice.pixel(y)). `fronts`: the rays' links between samples
/// under pre-integration (f.pre, one per ray of the region), else empty. Adds the pass's
/// samples and leaps to `total`.
void marchPass(brickstore::VoxelType type, const Frame& f, PixelLattice lattice,
               const PixelRect& region, const PixelRect& rect, RayStates& rays,
               std::vector<Front>& fronts, RayCount& total);

/// The region's image: the rays' colours over `marched` (region coordinates; not visible: no
/// pixel), transparent black elsewhere; clamped to [0, 1] unless `clamp` is false (a part's
/// segments, which the compositing clamps once laid together: a shaded segment's colour may
/// exceed 1). `raw`: a projection's pixels (value, count, 0, 0; render/Composite.h).
Image imageOf(const RayStates& rays, std::uint32_t width, std::uint32_t height,
              const Footprint& marched, bool clamp, bool raw = false);

} // namespace bc::render::detail
