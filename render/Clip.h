#pragma once
// What of the volume a frame draws: a crop box and up to six clip planes (render/MODES.md
// "Crop and clip"). Samples outside are not taken and bricks wholly outside are neither loaded
// nor drawn; the samples inside lie exactly where they would without it, so moving a cut
// changes only what it cuts.
#include <array>
#include <cstdint>

#include <glm/vec3.hpp>

namespace bc::render {

struct Box;

/// A half-space a frame keeps: the world points x (mm) with dot(normal, x) + offset >= 0
/// (the normal points into the part kept; it need not be of unit length).
struct ClipPlane {
    std::array<double, 3> normal{0.0, 0.0, 1.0};
    double offset = 0.0;
    bool operator==(const ClipPlane&) const = default;
};

struct Clip {
    static constexpr std::uint32_t kMaxPlanes = 6;
    /// The crop box in world mm (the volume's box is [0, dims * spacing]); off: none.
    bool cropped = false;
    std::array<double, 3> cropMin{}, cropMax{};
    std::uint32_t planeCount = 0;
    std::array<ClipPlane, kMaxPlanes> planes{};
    /// Capping: a ray that enters what is kept through a cut (a crop face or a plane inside
    /// the volume's box) draws the cut face there before anything behind it, as a surface of
    /// the material it cuts (render/MODES.md "Capping"). Composite and isosurface frames only.
    bool cap = false;

    bool any() const { return cropped || planeCount > 0; }
    /// Throws std::invalid_argument naming the field: a crop box that is empty, inverted or
    /// not finite ("crop"), more than kMaxPlanes planes, a plane whose normal is zero or not
    /// finite or whose offset is not finite ("clip[i]").
    void validate() const;
    /// The ray parameters [ta, tb] of origin `o` + t `d` (world) that are kept (ta > tb: none;
    /// infinite ends where nothing bounds them), in double. `entryNormal`, when given: the unit
    /// normal (world, into the part kept) of the crop face or plane that sets ta; 0 where
    /// nothing bounds the start.
    std::array<double, 2> interval(const glm::dvec3& o, const glm::dvec3& d,
                                   glm::dvec3* entryNormal = nullptr) const;
    /// Whether world box `box` lies wholly outside what is kept (the crop box misses it, or
    /// it lies on the cut side of a plane). Conservative: a box that touches is inside.
    bool outside(const Box& box) const;
    bool operator==(const Clip&) const = default;
};

/// The clip in float, as the CPU raycaster's rays use it (render/detail/CpuRay.h).
struct ClipF {
    bool cropped = false;
    glm::vec3 cropMin{0.0f}, cropMax{0.0f};
    int planeCount = 0;
    std::array<glm::vec3, Clip::kMaxPlanes> normals{}; ///< of unit length
    bool cap = false;
    std::array<float, Clip::kMaxPlanes> offsets{};
    bool any = false;

    static ClipF of(const Clip& c);
    /// Clip::interval in float: [ta, tb] of o + t d kept (cutEntriesSimd() in
    /// render/detail/CpuMarchBegin-inl.h has its operations a vector of rays at a time).
    void interval(glm::vec3 o, glm::vec3 d, float& ta, float& tb) const {
        if (cropped)
            for (int a = 0; a < 3; ++a) {
                if (d[a] == 0.0f) {
                    if (o[a] < cropMin[a] || o[a] > cropMax[a]) tb = -3.0e38f;
                    continue;
                }
                const float inv = 1.0f / d[a];
                const float u0 = (cropMin[a] - o[a]) * inv, u1 = (cropMax[a] - o[a]) * inv;
                ta = u0 < u1 ? (u0 > ta ? u0 : ta) : (u1 > ta ? u1 : ta);
                tb = u0 < u1 ? (u1 < tb ? u1 : tb) : (u0 < tb ? u0 : tb);
            }
        for (int i = 0; i < planeCount; ++i) {
            const glm::vec3& n = normals[std::size_t(i)];
            const float nd = n.x * d.x + n.y * d.y + n.z * d.z;
            const float no = n.x * o.x + n.y * o.y + n.z * o.z + offsets[std::size_t(i)];
            if (nd == 0.0f) {
                if (no < 0.0f) tb = -3.0e38f;
                continue;
            }
            const float t = -no / nd;
            if (nd > 0.0f)
                ta = t > ta ? t : ta;
            else
                tb = t < tb ? t : tb;
        }
    }
};

} // namespace bc::render
