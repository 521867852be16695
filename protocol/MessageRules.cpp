#include "protocol/detail/MessageRules.h"

#include <algorithm>
#include <array>
#include <charconv>
#include <cmath>
#include <limits>
#include <utility>

namespace bc::protocol::detail {
namespace {

constexpr double kInf = std::numeric_limits<double>::infinity();
constexpr std::size_t kQuotedBytes = 40;

/// NaN lies in no interval.
bool inInterval(double v, double lo, double hi, bool loOpen, bool hiOpen) {
    return (loOpen ? v > lo : v >= lo) && (hiOpen ? v < hi : v <= hi);
}

bool nameChar(char c) {
    return (c >= 'A' && c <= 'Z') || (c >= 'a' && c <= 'z') || (c >= '0' && c <= '9') || c == '.' ||
           c == '_' || c == '-';
}

std::string vec3(const std::array<double, 3>& v) {
    std::string s = "(";
    for (std::size_t i = 0; i < v.size(); ++i)
        s.append(i ? ", " : "").append(number(v[i]));
    return s.append(")");
}

/// "[3]"; built by appends, which GCC 12's -Wrestrict does not misread as overlapping copies.
std::string indexText(std::ptrdiff_t i) {
    return std::string("[").append(std::to_string(i)).append("]");
}

// ---- per message ----------------------------------------------------------------------

void check(Rules& r, const Hello& m) {
    // An inverted version range is not rejected here: it overlaps nothing, which the server
    // answers UnsupportedVersion (fatal) as PROTOCOL.md says.
    r.count("codecs", m.codecs.size(), kMaxCodecs);
    for (std::size_t i = 0; i < m.codecs.size(); ++i)
        r.enumValue({"codecs", i}, std::uint8_t(m.codecs[i]), std::uint8_t(Codec::Png));
    r.text("software", m.software, 0, kMaxSoftwareBytes);
}

void check(Rules& r, const Auth& m) {
    r.text("token", m.token, 1, kMaxTokenBytes);
}

void check(Rules& r, const VolumeInfo& m) {
    r.volumeName("name", m.name);
    r.finite("spacingMm", m.spacingMm);
    r.enumValue("voxelType", std::uint8_t(m.voxelType), 3);
    r.intRange("levels", m.levels, 1, kMaxLevel + 1);
    r.finite("valueMin", m.valueMin);
    r.finite("valueMax", m.valueMax);
}

void check(Rules& r, const VolumeList& m) {
    r.count("volumes", m.volumes.size(), kMaxVolumes);
    for (std::size_t i = 0; i < m.volumes.size() && r.ok(); ++i) {
        r.item("volumes", std::ptrdiff_t(i));
        check(r, m.volumes[i]);
    }
}

void check(Rules& r, const OpenVolume& m) {
    r.volumeName("name", m.name);
}

void check(Rules& r, const VolumeOpened& m) {
    r.item("info");
    check(r, m.info);
}

using Vec3 = std::array<double, 3>;

// GLM's dot, cross and normalize, operation for operation: the renderer's camera check
// (render/Camera.cpp, Camera::validate) is this one in its own module, and the test
// CameraRules.* holds the two to the same verdicts.
double dot(const Vec3& a, const Vec3& b) {
    return a[0] * b[0] + a[1] * b[1] + a[2] * b[2];
}

Vec3 cross(const Vec3& x, const Vec3& y) {
    return {x[1] * y[2] - y[1] * x[2], x[2] * y[0] - y[2] * x[0], x[0] * y[1] - y[0] * x[1]};
}

/// The unit vector along `v` (finite, not zero), scaled first by the power of two that brings
/// its largest component into [1, 2) (exact), so that no squared length overflows.
Vec3 direction(Vec3 v) {
    const int e = std::ilogb(std::max({std::abs(v[0]), std::abs(v[1]), std::abs(v[2])}));
    for (double& c : v)
        c = std::ldexp(c, -e);
    const double inverse = 1.0 / std::sqrt(dot(v, v));
    for (double& c : v)
        c *= inverse;
    return v;
}

void checkView(Rules& r, const SetCamera& m) {
    const Vec3 view{m.target[0] - m.eye[0], m.target[1] - m.eye[1], m.target[2] - m.eye[2]};
    if (view == Vec3{0, 0, 0})
        return r.fail(ErrorCode::OutOfRange, "eye", vec3(m.eye) + " equals target");
    if (!std::isfinite(view[0]) || !std::isfinite(view[1]) || !std::isfinite(view[2]))
        return r.fail(ErrorCode::OutOfRange, "target", "target - eye is not finite");
    const Vec3 side = cross(direction(view), m.up);
    if (!(std::sqrt(dot(side, side)) >= 1e-9))
        r.fail(ErrorCode::OutOfRange, "up",
               vec3(m.up) + " is zero or parallel to the view direction");
}

void check(Rules& r, const SetCamera& m) {
    r.finite("eye", m.eye);
    r.finite("target", m.target);
    r.finite("up", m.up);
    r.finite("fovYDeg", m.fovYDeg);
    r.finite("orthoHeight", m.orthoHeight);
    if (!r.ok()) return;
    checkView(r, m);
    r.realRange("fovYDeg", m.fovYDeg, 0, 180, true, true);
    if (m.orthographic) r.realRange("orthoHeight", m.orthoHeight, 0, kInf, true, true);
}

void check(Rules& r, const TfPoint& p) {
    r.enumValue("placement", std::uint8_t(p.placement), 2);
    r.finite("position", p.position);
    if (p.placement == Placement::Percentile)
        r.realRange("position", p.position, 0, 100, false, false);
    for (std::size_t c = 0; c < 4; ++c)
        r.realRange({"rgba", c}, p.rgba[c], 0, 1, false, false);
}

void checkPoints(Rules& r, const SetTransferFunction& m) {
    if (m.shadingSource == ShadingSource::Preset)
        r.fail(ErrorCode::OutOfRange, "shadingSource", "1 (the preset's) needs kind 0 (preset)");
    if (!m.preset.empty())
        r.fail(ErrorCode::OutOfRange, "preset", "must be empty when kind is 1 (points)");
    r.intRange("points", m.points.size(), 1, kMaxTfPoints);
    for (std::size_t i = 0; i < m.points.size() && r.ok(); ++i) {
        r.item("points", std::ptrdiff_t(i));
        check(r, m.points[i]);
    }
}

void check(Rules& r, const SetTransferFunction& m) {
    r.enumValue("kind", std::uint8_t(m.kind), 1);
    r.enumValue("shadingSource", std::uint8_t(m.shadingSource), 1);
    if (!r.ok()) return;
    if (m.kind == TfKind::Points) return checkPoints(r, m);
    r.text("preset", m.preset, 0, kMaxPresetBytes);
    if (!m.points.empty())
        r.fail(ErrorCode::OutOfRange, "points", "must be empty when kind is 0 (preset)");
}

void checkTechniques(Rules& r, std::uint32_t t) {
    r.bits("techniques", t, kTechAll);
    const bool bricks = (t & kTechBrickSkipping) != 0;
    if ((t & kTechOctreeSkipping) && !bricks)
        r.fail(ErrorCode::OutOfRange, "techniques",
               "octree skipping (bit 1) needs brick skipping (bit 0)");
    if ((t & kTechOcclusionFrustums) && !bricks)
        r.fail(ErrorCode::OutOfRange, "techniques",
               "occlusion frustums (bit 3) need brick skipping (bit 0)");
}

void checkCodecQuality(Rules& r, Codec codec, std::uint8_t q) {
    switch (codec) {
    case Codec::Raw:
        return r.intRange("codecQuality", q, 0, 0);
    case Codec::Zstd:
    case Codec::ZstdDelta:
        return r.intRange("codecQuality", q, 0, 19);
    case Codec::Jpeg:
        return r.intRange("codecQuality", q, 0, 100);
    case Codec::Png:
        return r.intRange("codecQuality", q, 0, 1); // fast, small
    }
}

void check(Rules& r, const SetRenderOptions& m) {
    const RenderOptions& o = m.options;
    r.intRange("width", o.width, 1, kMaxImageEdge);
    r.intRange("height", o.height, 1, kMaxImageEdge);
    r.realRange("stepVoxels", o.stepVoxels, 0, 64, true, false);
    checkTechniques(r, o.techniques);
    r.realRange("ertThreshold", o.ertThreshold, 0, 1, true, false);
    r.enumValue("renderer", std::uint8_t(o.renderer), std::uint8_t(Renderer::Auto));
    r.enumValue("quality", std::uint8_t(o.quality), 2);
    r.enumValue("codec", std::uint8_t(o.codec), std::uint8_t(Codec::Png));
    if (r.ok()) checkCodecQuality(r, o.codec, o.codecQuality);
    if (o.refinedCodec) // on the wire: the codec + 1
        r.intRange("refinedCodec", std::uint8_t(*o.refinedCodec) + 1, 1,
                   std::uint8_t(Codec::Png) + 1);
    if (o.level != kLevelAutomatic) r.intRange("level", o.level, 0, kMaxLevel);
    r.bits("flags", o.flags, kFlagAll);
}

void check(Rules& r, const RequestFrame& m) {
    r.enumValue("mode", std::uint8_t(m.mode), 2);
}

void check(Rules& r, const Frame& m) {
    const FrameHeader& h = m.header;
    r.intRange("width", h.width, 1, kMaxImageEdge);
    r.intRange("height", h.height, 1, kMaxImageEdge);
    r.enumValue("codec", std::uint8_t(h.codec), std::uint8_t(Codec::Png));
    r.intRange("level", h.level, 0, kMaxLevel);
    r.intRange("scale", h.scale, 0, 8);
    r.intRange("estimatedPsnrDb", h.estimatedPsnrDb, 0, kMaxRestPsnrDb);
    const std::uint64_t rawBytes = std::uint64_t(h.width) * h.height * 4;
    if (r.ok() && h.codec == Codec::Raw && m.image.size() != rawBytes)
        r.fail(ErrorCode::BadPayload, "imageBytes",
               std::to_string(m.image.size()) +
                   " is not width x height x 4 = " + std::to_string(rawBytes) + " for a raw image");
}

void check(Rules& r, const Stats& m) {
    r.count("counters", m.counters.size(), kMaxStats);
    for (std::size_t i = 0; i < m.counters.size() && r.ok(); ++i) {
        r.item("counters", std::ptrdiff_t(i));
        r.text("name", m.counters[i].first, 0, kMaxStatNameBytes);
    }
}

void check(Rules& r, const Error& m) {
    r.intRange("code", std::uint16_t(m.code), 1, std::uint16_t(ErrorCode::NotFound));
    r.text("message", m.message, 0, kMaxErrorMessageBytes);
}

void check(Rules& r, const Bye& m) {
    r.enumValue("reason", std::uint16_t(m.reason), 2);
}

void check(Rules& r, const SetFrameBudget& m) {
    r.intRange("interactiveMs", m.interactiveMs, 0, kMaxInteractiveMs);
    if (m.restPsnrDb != 0) r.intRange("restPsnrDb", m.restPsnrDb, kMinRestPsnrDb, kMaxRestPsnrDb);
}

void check(Rules& r, const SetModeAndClip& m) {
    r.enumValue("mode", std::uint8_t(m.mode), std::uint8_t(BlendMode::Isosurface));
    r.finite("isoValue", m.isoValue);
    r.finite("cropMin", m.cropMin);
    r.finite("cropMax", m.cropMax);
    if (!r.ok()) return;
    for (std::size_t a = 0; a < 3 && r.ok(); ++a) {
        if (m.cropped && !(m.cropMin[a] < m.cropMax[a]))
            r.fail(ErrorCode::OutOfRange, "cropMax",
                   "must exceed cropMin on every axis (the box is empty or inverted)");
        if (!m.cropped && (m.cropMin[a] != 0 || m.cropMax[a] != 0))
            r.fail(ErrorCode::OutOfRange, "cropMin", "must be 0 when cropped is 0");
    }
    if (r.ok() && m.cap && m.mode != BlendMode::Composite && m.mode != BlendMode::Isosurface)
        r.fail(ErrorCode::OutOfRange, "cutFlags",
               "cap: the mode draws no surface to cap (composite and isosurface only)");
    r.count("planes", m.planes.size(), kMaxClipPlanes);
    for (std::size_t i = 0; i < m.planes.size() && r.ok(); ++i) {
        r.item("planes", std::ptrdiff_t(i));
        const ClipPlane& p = m.planes[i];
        r.finite("normal", p.normal);
        r.finite("offset", p.offset);
        const double largest =
            std::max({std::abs(p.normal[0]), std::abs(p.normal[1]), std::abs(p.normal[2])});
        if (r.ok() && !(largest > 1e-30))
            r.fail(ErrorCode::OutOfRange, "normal", "is zero (a plane needs a direction)");
    }
}

void check(Rules&, const AuthOk&) {}
void check(Rules&, const ListVolumes&) {}
void check(Rules&, const RequestStats&) {}
void check(Rules&, const RequestHistogram&) {}

void check(Rules& r, const Histogram& m) {
    r.realRange("valueMin", m.valueMin, -1e300, 1e300, false, false);
    r.realRange("valueMax", m.valueMax, m.valueMin, 1e300, false, false);
    r.intRange("counts", m.counts.size(), 1, kMaxHistogramBins);
}

} // namespace

// ---- Rules ----------------------------------------------------------------------------------

void Rules::item(const char* list, std::ptrdiff_t index) {
    mList = list;
    mItem = index;
}

std::string Rules::fieldText(Field field) const {
    std::string s = mMessage;
    if (mList) s.append(".").append(mList);
    if (mList && mItem >= 0) s += indexText(mItem);
    if (field.name && *field.name) s.append(".").append(field.name);
    if (field.index >= 0) s += indexText(field.index);
    return s;
}

void Rules::fail(ErrorCode code, Field field, std::string_view text) {
    if (mViolation) return;
    mViolation = Violation{code, fieldText(field) + ": " + std::string(text)};
}

void Rules::intRange(Field field, std::uint64_t v, std::uint64_t lo, std::uint64_t hi) {
    if (v >= lo && v <= hi) return;
    fail(ErrorCode::OutOfRange, field,
         std::to_string(v) + " is outside " + std::to_string(lo) + ".." + std::to_string(hi));
}

void Rules::enumValue(Field field, std::uint64_t raw, std::uint64_t maxValue) {
    if (raw <= maxValue) return;
    fail(ErrorCode::OutOfRange, field,
         std::to_string(raw) + " is not one of 0.." + std::to_string(maxValue));
}

void Rules::finite(Field field, double v) {
    if (!std::isfinite(v)) fail(ErrorCode::OutOfRange, field, number(v) + " is not finite");
}

void Rules::finite(const char* field, std::span<const double> v) {
    for (std::size_t i = 0; i < v.size(); ++i)
        finite({field, i}, v[i]);
}

void Rules::realRange(Field field, double v, double lo, double hi, bool loOpen, bool hiOpen) {
    if (!inInterval(v, lo, hi, loOpen, hiOpen)) failRange(field, number(v), lo, hi, loOpen, hiOpen);
}

void Rules::realRange(Field field, float v, double lo, double hi, bool loOpen, bool hiOpen) {
    if (!inInterval(v, lo, hi, loOpen, hiOpen)) failRange(field, number(v), lo, hi, loOpen, hiOpen);
}

void Rules::failRange(Field field, const std::string& value, double lo, double hi, bool loOpen,
                      bool hiOpen) {
    fail(ErrorCode::OutOfRange, field,
         value + " is outside " + (loOpen ? "(" : "[") + number(lo) + ", " + number(hi) +
             (hiOpen ? ")" : "]"));
}

void Rules::bits(Field field, std::uint64_t v, std::uint64_t allowedMask) {
    if ((v & ~allowedMask) == 0) return;
    fail(ErrorCode::OutOfRange, field, hex(v) + " has bits outside " + hex(allowedMask));
}

void Rules::text(Field field, std::string_view s, std::size_t minBytes, std::size_t maxBytes) {
    if (s.size() < minBytes || s.size() > maxBytes)
        return fail(ErrorCode::OutOfRange, field,
                    std::to_string(s.size()) + " bytes is outside " + std::to_string(minBytes) +
                        ".." + std::to_string(maxBytes));
    for (std::size_t i = 0; i < s.size();) {
        const std::size_t n = utf8CharBytes(s, i);
        if (n == 0)
            return fail(ErrorCode::BadPayload, field,
                        quoted(s) + " is not valid UTF-8 at byte " + std::to_string(i));
        i += n;
    }
}

void Rules::volumeName(Field field, std::string_view s) {
    if (s.empty() || s.size() > kMaxVolumeNameBytes)
        return fail(ErrorCode::OutOfRange, field,
                    std::to_string(s.size()) + " bytes is outside 1.." +
                        std::to_string(kMaxVolumeNameBytes));
    for (char c : s)
        if (!nameChar(c))
            return fail(ErrorCode::OutOfRange, field,
                        quoted(s) + " has a character outside A-Z a-z 0-9 . _ -");
    if (s.front() == '.') fail(ErrorCode::OutOfRange, field, quoted(s) + " starts with '.'");
}

void Rules::count(Field field, std::size_t n, std::size_t maxEntries) {
    if (n <= maxEntries) return;
    fail(ErrorCode::OutOfRange, field,
         std::to_string(n) + " entries is over the limit of " + std::to_string(maxEntries));
}

// ---- free functions ---------------------------------------------------------------------------

std::optional<Violation> firstViolation(const Message& m) {
    Rules rules(typeName(std::uint8_t(typeOf(m))));
    std::visit([&](const auto& alternative) { check(rules, alternative); }, m);
    return rules.take();
}

std::size_t utf8CharBytes(std::string_view s, std::size_t i) {
    const auto byte = [&](std::size_t k) { return static_cast<unsigned char>(s[k]); };
    const unsigned char b0 = byte(i);
    if (b0 < 0x80) return 1;
    std::size_t n = 0;
    std::uint32_t cp = 0;
    if (b0 >= 0xC2 && b0 <= 0xDF)
        n = 2, cp = b0 & 0x1F;
    else if (b0 >= 0xE0 && b0 <= 0xEF)
        n = 3, cp = b0 & 0x0F;
    else if (b0 >= 0xF0 && b0 <= 0xF4)
        n = 4, cp = b0 & 0x07;
    else
        return 0;
    if (i + n > s.size()) return 0;
    for (std::size_t k = 1; k < n; ++k) {
        if ((byte(i + k) & 0xC0) != 0x80) return 0;
        cp = (cp << 6) | (byte(i + k) & 0x3F);
    }
    const bool overlong = (n == 3 && cp < 0x800) || (n == 4 && cp < 0x10000);
    const bool surrogate = cp >= 0xD800 && cp <= 0xDFFF;
    return overlong || surrogate || cp > 0x10FFFF ? 0 : n;
}

std::string quoted(std::string_view s) {
    static constexpr char kDigits[] = "0123456789abcdef";
    std::string out = "'";
    for (std::size_t i = 0; i < s.size() && i < kQuotedBytes; ++i) {
        const auto c = static_cast<unsigned char>(s[i]);
        if (c >= 0x20 && c < 0x7F && c != '\'' && c != '\\') {
            out += char(c);
        } else {
            out += "\\x";
            out += kDigits[c >> 4];
            out += kDigits[c & 15];
        }
    }
    out += s.size() > kQuotedBytes ? "'..." : "'";
    return out;
}

std::string hex(std::uint64_t v) {
    char buf[24];
    auto end = std::to_chars(buf, buf + sizeof buf, v, 16).ptr;
    return "0x" + std::string(buf, end);
}

namespace {
template <typename T> std::string shortest(T v) {
    if (std::isnan(v)) return "nan";
    if (std::isinf(v)) return v > 0 ? "inf" : "-inf";
    char buf[32];
    auto end = std::to_chars(buf, buf + sizeof buf, v).ptr;
    return std::string(buf, end);
}
} // namespace

std::string number(double v) {
    return shortest(v);
}
std::string number(float v) {
    return shortest(v);
}

} // namespace bc::protocol::detail
