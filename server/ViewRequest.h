#pragma once
// What a session asked for, in the renderer's terms: the protocol's camera, transfer function
// and options translated to render/ types, and the interactive-frame policy. Shared by the
// daemon and by tests that render "the same request" directly.
#include "protocol/Messages.h"
#include "render/Camera.h"
#include "render/Image.h"
#include "render/RenderTypes.h"
#include "render/TransferFunction.h"

#include <cstdint>
#include <memory>
#include <string>

namespace bc::server {

/// The renderer's camera for a protocol camera (already validated by the decoder).
render::Camera toCamera(const protocol::SetCamera& camera);

/// The renderer's options for a protocol request. Interactive frames (the camera is moving)
/// are drawn at half the width and height, rounded up, and scaled back up by interactiveUpscale.
render::RenderOptions toRenderOptions(const protocol::RenderOptions& options, bool interactive);

/// A transfer function placed for a volume: a preset by name, or the message's points
/// (through the same parser as the files, so errors name the field: "points[2].rgba[1]").
/// @throw render::RenderInputError naming the preset or point at fault.
std::shared_ptr<const render::TransferFunction>
toTransferFunction(const protocol::SetTransferFunction& message,
                   const render::VolumeValueStats& stats);

/// Whether shading is on for this request: RenderOptions' shading bit, unless the transfer
/// function message asked for its preset's default.
bool shadingFor(const protocol::RenderOptions& options,
                const protocol::SetTransferFunction& tfMessage,
                const render::TransferFunction& tf);

/// An interactive frame brought back to the requested size (pixel replication, exact).
render::Image interactiveUpscale(const render::Image& half, std::uint32_t width,
                                 std::uint32_t height);

} // namespace bc::server
