#pragma once
// A view: a camera validated once, its basis for an image size, and that size. Renderers take
// views, so neither they nor the daemon validate the same camera again or rebuild its basis.
#include "render/Camera.h"

#include <cstdint>

namespace bc::render {

struct View {
    Camera camera;
    ViewBasis basis;
    std::uint32_t width = 0, height = 0;

    /// A camera from an API caller, validated here.
    /// @throw std::invalid_argument naming the field (Camera::validate) or a zero size.
    static View of(const Camera& camera, std::uint32_t width, std::uint32_t height);
    /// A camera whose validity was decided where it came from: the protocol's decoder applies
    /// Camera::validate's rules to every SetCamera, so the daemon does not check it again.
    /// @throw std::invalid_argument on a zero size.
    static View ofDecoded(const Camera& camera, std::uint32_t width, std::uint32_t height);
};

/// The camera one frame on, if it keeps moving as it did from `a` to `b`: a turn about a fixed
/// target (an orbit) continues as the same rotation and zoom; anything else moves eye and
/// target on by the same step. What prefetch uploads bricks for.
Camera predictNext(const Camera& a, const Camera& b);

} // namespace bc::render
