#pragma once
// What the raycaster's shader (render/shaders/raycast.frag.glsl, built as
// ShaderProgram::Raycast) and its C++ agree on beyond the uniforms: the page-table entries.

namespace bc::render::detail {

/// Page-table entry kinds (page[i].x): >= 0 is a pool slot. raycast.frag.glsl spells them as
/// literals.
constexpr int kPageAbsent = -1; ///< not drawn in this batch (culled, skipped, or another batch)
constexpr int kPageConstant =
    -2; ///< one value throughout; page[i].y holds it as float bits (texel units)
/// Planned but not uploaded (the last frame's unsaturated rays never reached it): a ray that
/// reaches it stops and asks for it (ray-guided residency).
constexpr int kPageDeferred = -3;

} // namespace bc::render::detail
