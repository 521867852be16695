#pragma once
// Camera paths a thin client flies without knowing anything of the renderer: the daemon's
// orbit about a volume's box [0, dims * spacing] (the same cameras as render::Camera::orbit).
#include "protocol/Messages.h"

namespace bc::client {

/// Eye on a sphere about the box centre; distance 1 fits the box's bounding sphere into the
/// vertical field of view (30 degrees). +z up (+y when looking along z).
protocol::SetCamera orbitCamera(const protocol::VolumeInfo& volume, double azimuthDeg,
                                double elevationDeg, double distance = 1.0,
                                std::uint32_t cameraId = 0);

} // namespace bc::client
