#pragma once
// What every rank needs to draw its part of one slice of a frame (render/SCALEOUT.md): the view
// as rank 0 resolved it for the renderer (camera, drawn size, level, step, shading, the
// slice), so that every rank draws exactly what rank 0 draws, and its byte form between ranks.
#include "protocol/Messages.h"
#include "render/Camera.h"
#include "render/RenderTypes.h"

#include <cstdint>
#include <span>
#include <string>
#include <vector>

namespace bc::server {

struct ClusterOrder {
    std::string volume;   ///< catalog name (every rank serves the same config)
    std::string renderer; ///< resolved ("cpu", "gpu"; never "auto")
    render::Camera camera;
    /// The transfer function as the client sent it: each rank resolves it against its own
    /// catalog (presets of the same config).
    protocol::SetTransferFunction tf;
    /// The renderer's options of this slice as rank 0 draws it: the drawn frame's size (an
    /// interactive frame's divided), the level, the step (a refinement pass's), shading;
    /// `region` is the slice (never whole). Each rank sets parts and part.
    render::RenderOptions options;
};

/// `order` in bytes. @throw std::invalid_argument when a name is over 255 bytes.
std::vector<std::uint8_t> encodeOrder(const ClusterOrder& order);

/// The order in `bytes`, every field checked (an order is rank 0's, but a rank of another build
/// or a torn message must not be drawn from). @throw std::runtime_error naming the field.
ClusterOrder decodeOrder(std::span<const std::uint8_t> bytes);

} // namespace bc::server
