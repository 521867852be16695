#include "protocol/Messages.h"

#include "protocol/Error.h"
#include "protocol/detail/ByteIo.h"
#include "protocol/detail/MessageRules.h"

#include <algorithm>
#include <type_traits>

namespace bc::protocol {
namespace {

using detail::ByteWriter;

// Variant alternatives are in wire order: alternative i is message type i + 1.
static_assert(std::variant_size_v<Message> == std::size_t(MessageType::SetModeAndClip));
static_assert(
    std::is_same_v<std::variant_alternative_t<std::size_t(MessageType::SetCamera) - 1, Message>,
                   SetCamera>);
static_assert(std::is_same_v<
              std::variant_alternative_t<std::size_t(MessageType::Frame) - 1, Message>, Frame>);

void write(ByteWriter& w, const Hello& m) {
    w.u16(m.versionMin);
    w.u16(m.versionMax);
    w.u32(m.capabilities);
    w.u8(static_cast<std::uint8_t>(m.codecs.size()));
    for (Codec c : m.codecs)
        w.u8(std::uint8_t(c));
    w.str(m.software);
}

void write(ByteWriter& w, const Auth& m) {
    w.str(m.token);
}

void write(ByteWriter& w, const VolumeInfo& m) {
    w.str(m.name);
    for (auto d : m.dims)
        w.u32(d);
    for (auto s : m.spacingMm)
        w.f64(s);
    w.u8(std::uint8_t(m.voxelType));
    w.u8(m.levels);
    w.f64(m.valueMin);
    w.f64(m.valueMax);
    w.u64(m.storedBytes);
}

void write(ByteWriter& w, const VolumeList& m) {
    w.u16(static_cast<std::uint16_t>(m.volumes.size()));
    for (const auto& v : m.volumes)
        write(w, v);
}

void write(ByteWriter& w, const OpenVolume& m) {
    w.str(m.name);
}
void write(ByteWriter& w, const VolumeOpened& m) {
    write(w, m.info);
}

void write(ByteWriter& w, const SetCamera& m) {
    w.u32(m.cameraId);
    for (const auto* v : {&m.eye, &m.target, &m.up})
        for (double x : *v)
            w.f64(x);
    w.f64(m.fovYDeg);
    w.boolean(m.orthographic);
    w.f64(m.orthoHeight);
}

void write(ByteWriter& w, const SetTransferFunction& m) {
    w.u8(std::uint8_t(m.kind));
    w.boolean(m.shading);
    w.u8(std::uint8_t(m.shadingSource));
    if (m.kind == TfKind::Preset) return w.str(m.preset);
    w.u16(static_cast<std::uint16_t>(m.points.size()));
    for (const auto& p : m.points) {
        w.u8(std::uint8_t(p.placement));
        w.f64(p.position);
        for (float c : p.rgba)
            w.f32(c);
    }
}

void write(ByteWriter& w, const SetRenderOptions& m) {
    const RenderOptions& o = m.options;
    w.u16(o.width);
    w.u16(o.height);
    w.f32(o.stepVoxels);
    w.u32(o.techniques);
    w.f32(o.ertThreshold);
    w.u8(std::uint8_t(o.renderer));
    w.u8(std::uint8_t(o.quality));
    w.u8(std::uint8_t(o.codec));
    w.u8(o.codecQuality);
    w.u8(o.level);
    w.u8(o.refinedCodec ? std::uint8_t(std::uint8_t(*o.refinedCodec) + 1) : 0);
    w.u16(o.flags);
}

void write(ByteWriter& w, const RequestFrame& m) {
    w.u8(std::uint8_t(m.mode));
}

void write(ByteWriter& w, const Frame& m) {
    const FrameHeader& h = m.header;
    w.u32(h.frameId);
    w.u32(h.cameraId);
    w.u16(h.width);
    w.u16(h.height);
    w.u8(std::uint8_t(h.codec));
    w.u8(h.level);
    w.boolean(h.refined);
    w.boolean(h.keyframe);
    w.f32(h.queueMs);
    w.f32(h.renderMs);
    w.f32(h.encodeMs);
    w.u64(h.samples);
    w.u32(h.bricksDrawn);
    w.u32(h.bricksSkipped);
    w.u64(h.bytesUploaded);
    w.boolean(h.occlusionUsed);
    w.boolean(h.cached);
    w.u8(h.scale);
    w.u8(h.estimatedPsnrDb);
    w.u32(static_cast<std::uint32_t>(m.image.size()));
    w.bytes(m.image);
}

void write(ByteWriter& w, const Stats& m) {
    w.u16(static_cast<std::uint16_t>(m.counters.size()));
    for (const auto& [name, value] : m.counters) {
        w.str(name);
        w.f64(value);
    }
}

void write(ByteWriter& w, const Error& m) {
    w.u16(std::uint16_t(m.code));
    w.boolean(m.fatal);
    w.u8(m.offendingType);
    w.str(m.message);
}

void write(ByteWriter& w, const Bye& m) {
    w.u16(std::uint16_t(m.reason));
}

void write(ByteWriter& w, const Histogram& m) {
    w.f64(m.valueMin);
    w.f64(m.valueMax);
    w.u16(static_cast<std::uint16_t>(m.counts.size()));
    for (std::uint64_t c : m.counts)
        w.u64(c);
}

void write(ByteWriter& w, const SetFrameBudget& m) {
    w.u16(m.interactiveMs);
    w.u8(m.restPsnrDb);
}

void write(ByteWriter& w, const SetModeAndClip& m) {
    w.u8(std::uint8_t(m.mode));
    w.f64(m.isoValue);
    w.boolean(m.cropped);
    for (double v : m.cropMin)
        w.f64(v);
    for (double v : m.cropMax)
        w.f64(v);
    w.u8(std::uint8_t(m.planes.size()));
    for (const ClipPlane& p : m.planes) {
        for (double v : p.normal)
            w.f64(v);
        w.f64(p.offset);
    }
    // cutFlags, written only when not 0: uncapped messages keep the layout servers before
    // capping read.
    if (m.cap) w.u8(kCutCap);
}

void write(ByteWriter&, const AuthOk&) {}
void write(ByteWriter&, const RequestHistogram&) {}
void write(ByteWriter&, const ListVolumes&) {}
void write(ByteWriter&, const RequestStats&) {}

/// Throws unless PROTOCOL.md can carry m; returns its encoded size when it is a Frame, else 0.
std::size_t checkEncodable(const Message& m) {
    if (auto violation = detail::firstViolation(m)) throw ProtocolError(violation->text);
    const auto* frame = std::get_if<Frame>(&m);
    if (!frame) return 0;
    const std::size_t payload = kFrameHeaderBytes + frame->image.size();
    if (payload > kDefaultMaxServerPayloadBytes)
        throw ProtocolError("Frame.imageBytes: a payload of " + std::to_string(payload) +
                            " bytes is over the server limit of " +
                            std::to_string(kDefaultMaxServerPayloadBytes));
    return kHeaderBytes + payload;
}

} // namespace

MessageType typeOf(const Message& m) {
    return MessageType(m.index() + 1);
}

void encode(const Message& m, std::uint32_t request, std::vector<std::uint8_t>& out) {
    const std::size_t frameBytes = checkEncodable(m);
    const std::size_t start = out.size();
    try {
        // One allocation for a large image, growing geometrically so appends stay linear.
        if (start + frameBytes > out.capacity())
            out.reserve(std::max(start + frameBytes, 2 * out.capacity()));
        ByteWriter w(out);
        w.u32(kMagic);
        w.u8(kVersion);
        w.u8(std::uint8_t(typeOf(m)));
        w.u16(0); // flags: no type defines any
        w.u32(0); // length, patched below
        w.u32(request);
        std::visit([&](const auto& alternative) { write(w, alternative); }, m);
        w.patchU32(start + 8, static_cast<std::uint32_t>(out.size() - start - kHeaderBytes));
    } catch (...) {
        out.resize(start);
        throw;
    }
}

std::vector<std::uint8_t> encode(const Message& m, std::uint32_t request) {
    std::vector<std::uint8_t> out;
    encode(m, request, out);
    return out;
}

std::string fitText(std::string_view text, std::size_t maxBytes) {
    std::string out;
    out.reserve(std::min(text.size(), maxBytes));
    for (std::size_t i = 0; i < text.size();) {
        const std::size_t n = detail::utf8CharBytes(text, i);
        const std::size_t take = n == 0 ? 1 : n;
        if (out.size() + take > maxBytes) break;
        if (n == 0)
            out += '?';
        else
            out.append(text, i, n);
        i += take;
    }
    return out;
}

} // namespace bc::protocol
