#include "client/Orbit.h"

#include <cmath>

namespace bc::client {

protocol::SetCamera orbitCamera(const protocol::VolumeInfo& v, double azimuthDeg,
                                double elevationDeg, double distance, std::uint32_t cameraId) {
    constexpr double kPi = 3.14159265358979323846;
    double centre[3], r2 = 0;
    for (int a = 0; a < 3; ++a) {
        const double extent = double(v.dims[a]) * v.spacingMm[a];
        centre[a] = 0.5 * extent;
        r2 += 0.25 * extent * extent;
    }
    protocol::SetCamera c;
    c.cameraId = cameraId;
    const double az = azimuthDeg * kPi / 180, el = elevationDeg * kPi / 180;
    const double dir[3] = {std::cos(el) * std::cos(az), std::cos(el) * std::sin(az), std::sin(el)};
    const double fit = std::sqrt(r2) / std::sin(0.5 * c.fovYDeg * kPi / 180) * distance;
    for (int a = 0; a < 3; ++a) {
        c.target[a] = centre[a];
        c.eye[a] = centre[a] + dir[a] * fit;
    }
    c.up = std::abs(std::sin(el)) > 0.999 ? std::array<double, 3>{0, 1, 0}
                                          : std::array<double, 3>{0, 0, 1};
    c.orthoHeight = 2.0 * std::sqrt(r2) * distance;
    return c;
}

} // namespace bc::client
