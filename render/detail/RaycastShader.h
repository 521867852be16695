#pragma once
// GLSL of the raycaster (one full-screen pass per front-to-back brick batch).
#include <string>

namespace bc::render::detail {

const std::string& raycastVertexShader();
const std::string& raycastFragmentShader();

/// Page-table entry kinds (page[i].x): >= 0 is a pool slot.
constexpr int kPageAbsent = -1; ///< not drawn in this batch (culled, skipped, or another batch)
constexpr int kPageConstant =
    -2; ///< one value throughout; page[i].y holds it as float bits (texel units)
/// Planned but not uploaded (the last frame's unsaturated rays never reached it): a ray that
/// reaches it stops and asks for it (ray-guided residency).
constexpr int kPageDeferred = -3;

} // namespace bc::render::detail
