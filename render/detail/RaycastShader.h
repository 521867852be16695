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

} // namespace bc::render::detail
