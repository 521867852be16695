#include "server/ClusterOrder.h"

#include "protocol/Decoder.h"

#include <bit>
#include <stdexcept>
#include <variant>

namespace bc::server {

namespace {

/// Little-endian fields appended to a byte vector.
struct Writer {
    std::vector<std::uint8_t>& out;

    void u8(std::uint8_t v) { out.push_back(v); }
    void u32(std::uint32_t v) {
        for (int i = 0; i < 4; ++i)
            out.push_back(std::uint8_t(v >> (8 * i)));
    }
    void u64(std::uint64_t v) {
        for (int i = 0; i < 8; ++i)
            out.push_back(std::uint8_t(v >> (8 * i)));
    }
    void f64(double v) { u64(std::bit_cast<std::uint64_t>(v)); }
    void vec3(const glm::dvec3& v) {
        for (int i = 0; i < 3; ++i)
            f64(v[i]);
    }
    void name(const std::string& s) {
        if (s.size() > 255) throw std::invalid_argument("cluster order: name over 255 bytes");
        u8(std::uint8_t(s.size()));
        out.insert(out.end(), s.begin(), s.end());
    }
};

/// The fields of a byte span in order, each named in the error when it is cut short or out of
/// range.
struct Reader {
    std::span<const std::uint8_t> bytes;
    std::size_t at = 0;

    void need(std::size_t n, const char* field) {
        if (bytes.size() - at < n)
            throw std::runtime_error(std::string("cluster order: truncated at ") + field);
    }
    std::uint8_t u8(const char* field) {
        need(1, field);
        return bytes[at++];
    }
    std::uint64_t uint(int n, const char* field) {
        need(std::size_t(n), field);
        std::uint64_t v = 0;
        for (int i = 0; i < n; ++i)
            v |= std::uint64_t(bytes[at + std::size_t(i)]) << (8 * i);
        at += std::size_t(n);
        return v;
    }
    std::uint32_t u32(const char* field) { return std::uint32_t(uint(4, field)); }
    std::uint64_t u64(const char* field) { return uint(8, field); }
    double f64(const char* field) { return std::bit_cast<double>(uint(8, field)); }
    bool flag(const char* field) {
        const std::uint8_t v = u8(field);
        if (v > 1)
            throw std::runtime_error(std::string("cluster order: ") + field + " is " +
                                     std::to_string(v) + ", not 0 or 1");
        return v == 1;
    }
    glm::dvec3 vec3(const char* field) {
        glm::dvec3 v;
        for (int i = 0; i < 3; ++i)
            v[i] = f64(field);
        return v;
    }
    std::string name(const char* field) {
        const std::size_t n = u8(field);
        need(n, field);
        std::string s(reinterpret_cast<const char*>(bytes.data() + at), n);
        at += n;
        return s;
    }
};

void putOptions(Writer& w, const render::RenderOptions& o) {
    for (std::uint32_t v :
         {o.width, o.height, o.region.x, o.region.y, o.region.width, o.region.height})
        w.u32(v);
    w.f64(o.stepVoxels);
    w.u8(o.earlyTermination);
    w.f64(o.ertThreshold);
    w.u8(std::uint8_t(o.skip));
    w.u8(o.shading);
    w.u32(std::uint32_t(o.level));
    for (bool b : {o.interactive, o.hardwareFilter, o.simd, o.packets, o.jitter, o.preintegrate})
        w.u8(b);
    w.f64(o.octree.ratioThreshold);
    w.u32(o.octree.levelLimit);
    w.u32(o.cellVoxels);
    w.u8(o.occlusionFrustums);
    for (std::uint32_t v : {o.occlusion.blockPixels, o.occlusion.offFrames, o.occlusion.probeEvery})
        w.u32(v);
    w.u8(o.rayGuided);
    w.u32(o.parts);
    w.u32(o.part);
    w.u64(o.hostKeptBefore);
    w.u32(o.stride);
    // The mode and clip only when the frame has them, so that a composite, uncut frame's order
    // stays as small as before: written always, the 62 bytes made a stopped rank's frame fail
    // as "an order's broadcast did not complete" rather than naming the rank that did not
    // answer (MpiDaemon.ARankKilledOrStoppedFailsItsFramesWithinTheTimeout, Open MPI 4.1).
    const bool cut = o.mode != render::BlendMode::Composite || o.clip.any();
    w.u8(cut);
    if (!cut) return;
    w.u8(std::uint8_t(o.mode));
    w.f64(o.isoValue);
    w.u8(o.clip.cropped);
    w.u8(o.clip.cap);
    for (double v : o.clip.cropMin)
        w.f64(v);
    for (double v : o.clip.cropMax)
        w.f64(v);
    w.u32(o.clip.planeCount);
    for (std::uint32_t i = 0; i < o.clip.planeCount; ++i) {
        for (double v : o.clip.planes[i].normal)
            w.f64(v);
        w.f64(o.clip.planes[i].offset);
    }
}

render::RenderOptions getOptions(Reader& r) {
    render::RenderOptions o;
    o.width = r.u32("width");
    o.height = r.u32("height");
    o.region.x = r.u32("region.x");
    o.region.y = r.u32("region.y");
    o.region.width = r.u32("region.width");
    o.region.height = r.u32("region.height");
    o.stepVoxels = r.f64("stepVoxels");
    o.earlyTermination = r.flag("earlyTermination");
    o.ertThreshold = r.f64("ertThreshold");
    const std::uint8_t skip = r.u8("skip");
    if (skip > std::uint8_t(render::SkipMode::All))
        throw std::runtime_error("cluster order: skip " + std::to_string(skip) +
                                 " is not a skip mode");
    o.skip = render::SkipMode(skip);
    o.shading = r.flag("shading");
    o.level = std::int32_t(r.u32("level"));
    o.interactive = r.flag("interactive");
    o.hardwareFilter = r.flag("hardwareFilter");
    o.simd = r.flag("simd");
    o.packets = r.flag("packets");
    o.jitter = r.flag("jitter");
    o.preintegrate = r.flag("preintegrate");
    o.octree.ratioThreshold = r.f64("octree.ratioThreshold");
    o.octree.levelLimit = r.u32("octree.levelLimit");
    o.cellVoxels = r.u32("cellVoxels");
    o.occlusionFrustums = r.flag("occlusionFrustums");
    o.occlusion.blockPixels = r.u32("occlusion.blockPixels");
    o.occlusion.offFrames = r.u32("occlusion.offFrames");
    o.occlusion.probeEvery = r.u32("occlusion.probeEvery");
    o.rayGuided = r.flag("rayGuided");
    o.parts = r.u32("parts");
    o.part = r.u32("part");
    o.hostKeptBefore = r.u64("hostKeptBefore");
    o.stride = r.u32("stride");
    if (!r.flag("cut")) return o;
    const std::uint8_t mode = r.u8("mode");
    if (mode > std::uint8_t(render::BlendMode::Isosurface))
        throw std::runtime_error("cluster order: mode " + std::to_string(mode) + " is not a mode");
    o.mode = render::BlendMode(mode);
    o.isoValue = r.f64("isoValue");
    o.clip.cropped = r.flag("clip.cropped");
    o.clip.cap = r.flag("clip.cap");
    for (double& v : o.clip.cropMin)
        v = r.f64("clip.cropMin");
    for (double& v : o.clip.cropMax)
        v = r.f64("clip.cropMax");
    o.clip.planeCount = r.u32("clip.planeCount");
    if (o.clip.planeCount > render::Clip::kMaxPlanes)
        throw std::runtime_error("cluster order: " + std::to_string(o.clip.planeCount) +
                                 " clip planes");
    for (std::uint32_t i = 0; i < o.clip.planeCount; ++i) {
        for (double& v : o.clip.planes[i].normal)
            v = r.f64("clip.planes.normal");
        o.clip.planes[i].offset = r.f64("clip.planes.offset");
    }
    return o;
}

} // namespace

std::vector<std::uint8_t> encodeOrder(const ClusterOrder& order) {
    std::vector<std::uint8_t> out;
    Writer w{out};
    w.name(order.volume);
    w.name(order.renderer);
    w.vec3(order.camera.eye);
    w.vec3(order.camera.target);
    w.vec3(order.camera.up);
    w.f64(order.camera.fovYDeg);
    w.u8(order.camera.orthographic);
    w.f64(order.camera.orthoHeight);
    putOptions(w, order.options);
    protocol::encode(order.tf, 0, out);
    return out;
}

ClusterOrder decodeOrder(std::span<const std::uint8_t> bytes) {
    Reader r{bytes};
    ClusterOrder o;
    o.volume = r.name("volume");
    o.renderer = r.name("renderer");
    o.camera.eye = r.vec3("camera.eye");
    o.camera.target = r.vec3("camera.target");
    o.camera.up = r.vec3("camera.up");
    o.camera.fovYDeg = r.f64("camera.fovYDeg");
    o.camera.orthographic = r.flag("camera.orthographic");
    o.camera.orthoHeight = r.f64("camera.orthoHeight");
    o.options = getOptions(r);
    try {
        o.camera.validate();
        o.options.validate();
    } catch (const std::invalid_argument& e) {
        throw std::runtime_error(std::string("cluster order: ") + e.what());
    }
    const render::PixelRect& region = o.options.region;
    if (region.width == 0 || region.height == 0 ||
        std::uint64_t(region.x) + region.width > o.options.width ||
        std::uint64_t(region.y) + region.height > o.options.height)
        throw std::runtime_error("cluster order: region outside the frame");
    protocol::Decoder decoder(protocol::kMaxClientPayloadBytes);
    decoder.feed(bytes.subspan(r.at));
    auto next = decoder.next();
    if (next.status == protocol::Decoder::Status::Error)
        throw std::runtime_error("cluster order: " + next.error.message);
    if (next.status != protocol::Decoder::Status::Message ||
        !std::holds_alternative<protocol::SetTransferFunction>(next.message))
        throw std::runtime_error("cluster order: no SetTransferFunction");
    o.tf = std::get<protocol::SetTransferFunction>(next.message);
    if (decoder.next().status != protocol::Decoder::Status::NeedMore || decoder.buffered() != 0)
        throw std::runtime_error("cluster order: bytes after SetTransferFunction");
    return o;
}

} // namespace bc::server
