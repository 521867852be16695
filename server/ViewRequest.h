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
#include <map>
#include <memory>
#include <string>
#include <vector>

namespace bc::server {

/// The renderer's camera for a protocol camera (already validated by the decoder).
render::Camera toCamera(const protocol::SetCamera& camera);

/// The renderer's options for a protocol request, drawn at its width and height over `divisor`
/// (rounded up; InteractiveBudget::drawnEdge): 1 for a refined frame; an interactive frame's
/// (the camera is moving) is 2 (half size) or what the server's frame-time budget allows
/// (server/InteractiveBudget.h), and the frame is scaled back up by upscaleBy.
render::RenderOptions toRenderOptions(const protocol::RenderOptions& options,
                                      std::uint32_t divisor);

/// `options` with the session's mode, iso value, crop box and clip planes (SetModeAndClip).
void applyModeAndClip(render::RenderOptions& options, const protocol::SetModeAndClip& m);

/// Presets a config added: name -> JSON text (Catalog::configPresets).
using PresetTexts = std::map<std::string, std::string>;

/// A transfer function placed for a volume: a preset by name (the config's, then the built-in
/// ones), or the message's points (TransferFunction::fromPoints, so errors name the field:
/// "points[2].rgba[1]"). Never reads a file: no string from the wire reaches the filesystem.
/// @throw render::RenderInputError naming the point at fault, or field "preset" (without
/// repeating the name) when neither the config nor the built-in presets have it.
std::shared_ptr<const render::TransferFunction>
toTransferFunction(const protocol::SetTransferFunction& message,
                   const render::VolumeValueStats& stats, const PresetTexts& configPresets);

/// Whether shading is on for this request: RenderOptions' shading bit, unless the transfer
/// function message asked for its preset's default.
bool shadingFor(const protocol::RenderOptions& options,
                const protocol::SetTransferFunction& tfMessage, const render::TransferFunction& tf);

/// A frame drawn at ceil(width / divisor) x ceil(height / divisor) (8-bit RGBA, `drawnWidth` x
/// `drawnHeight`) brought back to width x height: each drawn pixel replicated divisor x divisor
/// times (the last row and column clipped).
std::vector<std::uint8_t> upscaleBy(const std::vector<std::uint8_t>& drawn,
                                    std::uint32_t drawnWidth, std::uint32_t drawnHeight,
                                    std::uint32_t width, std::uint32_t height,
                                    std::uint32_t divisor);

} // namespace bc::server
