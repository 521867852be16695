#include "render/detail/HybridSplatRecords.h"

#include "render/SplatGeometry.h"

#include <algorithm>
#include <cmath>

#include <glm/geometric.hpp>

namespace bc::render::detail {
namespace {

/// The pixel rectangle of the bounding box of a sphere's screen ellipse (projectSphere's),
/// without hypot and atan2 (a third of a record's cost). Precondition: the sphere lies in
/// front of the eye plane (classifyDraw's Splat). False when the box misses the image or the
/// ellipse is not finite. The box may differ by an ulp, which moves at most a pixel centre on
/// the rim, where the footprint is 0.
bool splatRect(const SplatView& view, const glm::dvec3& centre, double radius, std::uint32_t w,
               std::uint32_t h, std::uint32_t rect[4]) {
    const glm::dvec3 rel = centre - view.eye;
    const glm::dvec3 c(glm::dot(rel, view.right), glm::dot(rel, view.up),
                       glm::dot(rel, view.forward));
    glm::dvec2 mid, half;
    if (view.orthographic) {
        mid = view.orthoScale * glm::dvec2(c.x, c.y);
        half = glm::dvec2(view.orthoScale * radius);
    } else {
        // projectPerspective's ellipse: with q = c / |c|, s = r / |c|, g = q.z^2 - s^2 and
        // e1 = q.xy / |q.xy|, centre f q.z / g q.xy and semi-axes f s cos(alpha) / g e1 and
        // f s / sqrt(g) e1 turned by 90 deg; the box's half size follows per axis.
        const double dist2 = glm::dot(c, c), s2 = radius * radius / dist2;
        const double g = (c.z * c.z - radius * radius) / dist2,
                     rho2 = (c.x * c.x + c.y * c.y) / dist2;
        if (!(g > 0.0)) return false;
        const double e1x2 = rho2 > 0.0 ? c.x * c.x / dist2 / rho2 : 1.0, e1y2 = 1.0 - e1x2;
        const double f = view.focalLength, k = f * std::sqrt(s2) / g, cz = c.z / std::sqrt(dist2);
        mid = (f * cz / g / std::sqrt(dist2)) * glm::dvec2(c.x, c.y);
        half = k * glm::dvec2(std::sqrt((1.0 - s2) * e1x2 + g * e1y2),
                              std::sqrt((1.0 - s2) * e1y2 + g * e1x2));
    }
    if (!(std::isfinite(mid.x) && std::isfinite(mid.y) && std::isfinite(half.x) &&
          std::isfinite(half.y)))
        return false;
    return pixelRect(mid - half, mid + half, w, h, rect);
}

} // namespace

DrawRecord RecordMaker::operator()(const Visible& v) const {
    DrawRecord r;
    r.voxel = &v;
    const VoxelDraw d = classifyDraw(mF, v.centre, v.rgba[3]);
    if (d.kind == VoxelDraw::Kind::Point)
        pointRecord(d, r);
    else if (d.kind == VoxelDraw::Kind::Splat)
        splatRecord(v.centre, d.lnT, r);
    return r;
}

void RecordMaker::pointRecord(const VoxelDraw& d, DrawRecord& r) const {
    // A point covers its voxel's projected area (pixels^2) with the voxel's opacity over one
    // voxel of path; that coverage is spread by the footprint at each pixel centre,
    // normalised over the unclipped lattice, so no point is lost between pixel centres.
    const double R = mF.pointFilter;
    std::uint32_t rect[4];
    if (!pixelRect(d.image - R, d.image + R, mW, mH, rect)) return;
    const double fx = d.image.x + 0.5 * mW - 0.5, fy = 0.5 * mH - 0.5 - d.image.y;
    r.dx = float(rect[0] - fx);
    r.dy = float(rect[1] - fy);
    const int i0 = int(std::ceil(fx - R)) - int(rect[0]),
              i1 = int(std::floor(fx + R)) - int(rect[0]);
    const int j0 = int(std::ceil(fy - R)) - int(rect[1]),
              j1 = int(std::floor(fy + R)) - int(rect[1]);
    float sum = 0.0f;
    for (int j = j0; j <= j1; ++j)
        for (int i = i0; i <= i1; ++i)
            sum += mFp.bySquaredDistance(pointDistance2(r, i, j, mInvFilter2));
    const double total =
        (1.0 - std::exp(-d.lnT * mF.voxelSteps)) * mF.voxelAreaMm2 * d.scale * d.scale;
    if (sum > 0.0f) {
        r.scale = float(total / sum);
    } else { // the whole coverage to the nearest pixel
        r.nearest = true;
        r.scale = float(total);
        const long nx = std::lround(fx), ny = std::lround(fy);
        if (nx >= 0 && ny >= 0 && nx < long(mW) && ny < long(mH)) {
            r.nearX = std::int32_t(nx);
            r.nearY = std::int32_t(ny);
        }
    }
    r.kind = DrawRecord::Kind::Point;
    std::copy(rect, rect + 4, r.rect);
}

void RecordMaker::splatRecord(const glm::dvec3& centre, double lnT, DrawRecord& r) const {
    std::uint32_t rect[4];
    if (!splatRect(mF.view, centre, mF.radiusMm, mW, mH, rect)) return;
    const glm::dvec3 rel = centre - mF.view.eye;
    const glm::dvec3 c(glm::dot(rel, mF.view.right), glm::dot(rel, mF.view.up),
                       glm::dot(rel, mF.view.forward));
    const glm::dvec2 p0 = SplatView::pixelCentre(rect[0], rect[1], mW, mH);
    if (mF.view.orthographic) {
        const double s = mF.view.orthoScale;
        r.dx = float(p0.x - s * c.x);
        r.dy = float(p0.y - s * c.y);
        r.scale = float(1.0 / (s * mF.radiusMm * s * mF.radiusMm));
    } else {
        const double fl = mF.view.focalLength, q = c.z / (fl * mF.radiusMm);
        r.tanX = float(c.x / c.z);
        r.tanY = float(c.y / c.z);
        r.dx = float(p0.x - fl * c.x / c.z);
        r.dy = float(p0.y - fl * c.y / c.z);
        r.scale = float(q * q);
    }
    r.opticalDepth = float(lnT * mF.depthScale);
    r.kind = DrawRecord::Kind::Splat;
    std::copy(rect, rect + 4, r.rect);
}

} // namespace bc::render::detail
