// decodePayload (Decoder.h): the payload readers of every message type. Structure (sizes,
// declared lengths and counts against the bytes left, bools) is checked while
// reading; values are then checked by the rules the encoder shares (detail/MessageRules.h).
#include "protocol/Decoder.h"

#include "protocol/detail/ByteIo.h"
#include "protocol/detail/MessageRules.h"

#include <optional>

namespace bc::protocol {
namespace {

using detail::Field;
using detail::Rules;

constexpr std::size_t kVolumeInfoMinBytes = 64; // with an empty name
constexpr std::size_t kTfPointBytes = 25;
constexpr std::size_t kClipPlaneBytes = 32; ///< f64 normal[3], f64 offset
constexpr std::size_t kStatMinBytes = 10;   // with an empty name
constexpr std::size_t kSetCameraBytes = 93;

/// Reads fields in order; the first short read or malformed field fails `rules` and every
/// later read returns zero.
class PayloadReader {
  public:
    PayloadReader(std::span<const std::uint8_t> payload, Rules& rules)
        : mIn(payload), mRules(rules) {}

    std::uint8_t u8(Field f) { return need(f, 1) ? mIn.u8() : 0; }
    std::uint16_t u16(Field f) { return need(f, 2) ? mIn.u16() : 0; }
    std::uint32_t u32(Field f) { return need(f, 4) ? mIn.u32() : 0; }
    std::uint64_t u64(Field f) { return need(f, 8) ? mIn.u64() : 0; }
    float f32(Field f) { return need(f, 4) ? mIn.f32() : 0; }
    double f64(Field f) { return need(f, 8) ? mIn.f64() : 0; }
    template <typename E> E enumU8(Field f) { return static_cast<E>(u8(f)); }
    void f64s(const char* f, std::array<double, 3>& v) {
        for (std::size_t i = 0; i < v.size(); ++i)
            v[i] = f64({f, i});
    }
    bool boolean(Field f);
    std::string str(Field f);
    std::size_t count(Field f, std::size_t countBytes, std::size_t maxEntries,
                      std::size_t minEntryBytes);
    std::span<const std::uint8_t> rest() { return mIn.take(mIn.remaining()); }
    std::size_t remaining() const { return mIn.remaining(); }
    Rules& rules() { return mRules; }

  private:
    bool need(Field f, std::size_t bytes);
    detail::ByteReader mIn;
    Rules& mRules;
};

bool PayloadReader::need(Field f, std::size_t bytes) {
    if (!mRules.ok()) return false;
    if (bytes <= mIn.remaining()) return true;
    mRules.fail(ErrorCode::BadPayload, f,
                "the payload ends inside this field (" + std::to_string(bytes) +
                    " bytes needed at offset " + std::to_string(mIn.offset()) + ", " +
                    std::to_string(mIn.remaining()) + " left)");
    return false;
}

bool PayloadReader::boolean(Field f) {
    const std::uint8_t v = u8(f);
    if (v > 1) mRules.fail(ErrorCode::OutOfRange, f, std::to_string(v) + " is not a bool (0 or 1)");
    return v == 1;
}

std::string PayloadReader::str(Field f) {
    const std::uint16_t n = u16(f);
    if (!mRules.ok()) return {};
    if (n > mIn.remaining()) {
        mRules.fail(ErrorCode::BadPayload, f,
                    "declared length " + std::to_string(n) + " exceeds the " +
                        std::to_string(mIn.remaining()) + " bytes left");
        return {};
    }
    const auto bytes = mIn.take(n);
    return std::string(bytes.begin(), bytes.end());
}

/// A count of countBytes (1 or 2), checked before anything is allocated for it.
std::size_t PayloadReader::count(Field f, std::size_t countBytes, std::size_t maxEntries,
                                 std::size_t minEntryBytes) {
    const std::size_t n = countBytes == 1 ? u8(f) : u16(f);
    mRules.count(f, n, maxEntries);
    if (mRules.ok() && n * minEntryBytes > mIn.remaining())
        mRules.fail(ErrorCode::BadPayload, f,
                    "count " + std::to_string(n) + " needs at least " +
                        std::to_string(n * minEntryBytes) + " bytes, " +
                        std::to_string(mIn.remaining()) + " left");
    return mRules.ok() ? n : 0;
}

// ---- per message ----------------------------------------------------------------------

Message readHello(PayloadReader& r) {
    Hello m;
    m.versionMin = r.u16("versionMin");
    m.versionMax = r.u16("versionMax");
    m.capabilities = r.u32("capabilities");
    const std::size_t n = r.count("codecs", 1, kMaxCodecs, 1);
    for (std::size_t i = 0; i < n; ++i)
        m.codecs.push_back(r.enumU8<Codec>({"codecs", i}));
    m.software = r.str("software");
    return m;
}

Message readAuth(PayloadReader& r) {
    return Auth{r.str("token")};
}

VolumeInfo readVolumeInfo(PayloadReader& r) {
    VolumeInfo v;
    v.name = r.str("name");
    for (std::size_t i = 0; i < 3; ++i)
        v.dims[i] = r.u32({"dims", i});
    r.f64s("spacingMm", v.spacingMm);
    v.voxelType = r.enumU8<VoxelType>("voxelType");
    v.levels = r.u8("levels");
    v.valueMin = r.f64("valueMin");
    v.valueMax = r.f64("valueMax");
    v.storedBytes = r.u64("storedBytes");
    return v;
}

Message readVolumeList(PayloadReader& r) {
    VolumeList m;
    const std::size_t n = r.count("volumes", 2, kMaxVolumes, kVolumeInfoMinBytes);
    m.volumes.reserve(n);
    for (std::size_t i = 0; i < n && r.rules().ok(); ++i) {
        r.rules().item("volumes", std::ptrdiff_t(i));
        m.volumes.push_back(readVolumeInfo(r));
    }
    return m;
}

Message readOpenVolume(PayloadReader& r) {
    return OpenVolume{r.str("name")};
}

Message readVolumeOpened(PayloadReader& r) {
    r.rules().item("info");
    return VolumeOpened{readVolumeInfo(r)};
}

Message readSetCamera(PayloadReader& r) {
    SetCamera m;
    m.cameraId = r.u32("cameraId");
    r.f64s("eye", m.eye);
    r.f64s("target", m.target);
    r.f64s("up", m.up);
    m.fovYDeg = r.f64("fovYDeg");
    m.orthographic = r.boolean("orthographic");
    m.orthoHeight = r.f64("orthoHeight");
    return m;
}

TfPoint readTfPoint(PayloadReader& r) {
    TfPoint p;
    p.placement = r.enumU8<Placement>("placement");
    p.position = r.f64("position");
    for (std::size_t c = 0; c < 4; ++c)
        p.rgba[c] = r.f32({"rgba", c});
    return p;
}

Message readSetTransferFunction(PayloadReader& r) {
    SetTransferFunction m;
    m.kind = r.enumU8<TfKind>("kind");
    m.shading = r.boolean("shading");
    m.shadingSource = r.enumU8<ShadingSource>("shadingSource");
    r.rules().enumValue("kind", std::uint8_t(m.kind), 1);
    if (m.kind == TfKind::Preset) {
        m.preset = r.str("preset");
        return m;
    }
    const std::size_t n = r.count("points", 2, kMaxTfPoints, kTfPointBytes);
    m.points.reserve(n);
    for (std::size_t i = 0; i < n && r.rules().ok(); ++i) {
        r.rules().item("points", std::ptrdiff_t(i));
        m.points.push_back(readTfPoint(r));
    }
    return m;
}

Message readSetRenderOptions(PayloadReader& r) {
    RenderOptions o;
    o.width = r.u16("width");
    o.height = r.u16("height");
    o.stepVoxels = r.f32("stepVoxels");
    o.techniques = r.u32("techniques");
    o.ertThreshold = r.f32("ertThreshold");
    o.renderer = r.enumU8<Renderer>("renderer");
    o.quality = r.enumU8<Quality>("quality");
    o.codec = r.enumU8<Codec>("codec");
    o.codecQuality = r.u8("codecQuality");
    o.level = r.u8("level");
    if (const std::uint8_t refined = r.u8("refinedCodec"))
        o.refinedCodec = Codec(refined - 1); // checked with the other enums (MessageRules)
    o.flags = r.u16("flags");
    return SetRenderOptions{o};
}

Message readRequestFrame(PayloadReader& r) {
    return RequestFrame{r.enumU8<FrameMode>("mode")};
}

FrameHeader readFrameHeader(PayloadReader& r) {
    FrameHeader h;
    h.frameId = r.u32("frameId");
    h.cameraId = r.u32("cameraId");
    h.width = r.u16("width");
    h.height = r.u16("height");
    h.codec = r.enumU8<Codec>("codec");
    h.level = r.u8("level");
    h.refined = r.boolean("refined");
    h.keyframe = r.boolean("keyframe");
    h.queueMs = r.f32("queueMs");
    h.renderMs = r.f32("renderMs");
    h.encodeMs = r.f32("encodeMs");
    h.samples = r.u64("samples");
    h.bricksDrawn = r.u32("bricksDrawn");
    h.bricksSkipped = r.u32("bricksSkipped");
    h.bytesUploaded = r.u64("bytesUploaded");
    h.occlusionUsed = r.boolean("occlusionUsed");
    h.cached = r.boolean("cached");
    h.scale = r.u8("scale");
    h.estimatedPsnrDb = r.u8("estimatedPsnrDb");
    return h;
}

Message readFrame(PayloadReader& r) {
    Frame m;
    m.header = readFrameHeader(r);
    const std::uint32_t imageBytes = r.u32("imageBytes");
    if (!r.rules().ok()) return m;
    if (imageBytes != r.remaining()) {
        r.rules().fail(ErrorCode::BadPayload, "imageBytes",
                       std::to_string(imageBytes) + " disagrees with the " +
                           std::to_string(r.remaining()) + " bytes left in the payload");
        return m;
    }
    const auto image = r.rest();
    m.image.assign(image.begin(), image.end());
    return m;
}

Message readStats(PayloadReader& r) {
    Stats m;
    const std::size_t n = r.count("counters", 2, kMaxStats, kStatMinBytes);
    m.counters.reserve(n);
    for (std::size_t i = 0; i < n && r.rules().ok(); ++i) {
        r.rules().item("counters", std::ptrdiff_t(i));
        std::string name = r.str("name");
        m.counters.emplace_back(std::move(name), r.f64("value"));
    }
    return m;
}

Message readError(PayloadReader& r) {
    Error m;
    m.code = ErrorCode(r.u16("code"));
    m.fatal = r.boolean("fatal");
    m.offendingType = r.u8("offendingType");
    m.message = r.str("message");
    return m;
}

Message readBye(PayloadReader& r) {
    return Bye{ByeReason(r.u16("reason"))};
}
Message readAuthOk(PayloadReader&) {
    return AuthOk{};
}
Message readListVolumes(PayloadReader&) {
    return ListVolumes{};
}
Message readRequestStats(PayloadReader&) {
    return RequestStats{};
}
Message readRequestHistogram(PayloadReader&) {
    return RequestHistogram{};
}

Message readSetFrameBudget(PayloadReader& r) {
    SetFrameBudget m;
    m.interactiveMs = r.u16("interactiveMs");
    m.restPsnrDb = r.u8("restPsnrDb");
    return m;
}

Message readSetModeAndClip(PayloadReader& r) {
    SetModeAndClip m;
    m.mode = r.enumU8<BlendMode>("mode");
    m.isoValue = r.f64("isoValue");
    m.cropped = r.boolean("cropped");
    r.f64s("cropMin", m.cropMin);
    r.f64s("cropMax", m.cropMax);
    const std::size_t n = r.count("planes", 1, kMaxClipPlanes, kClipPlaneBytes);
    m.planes.resize(n);
    for (std::size_t i = 0; i < n && r.rules().ok(); ++i) {
        r.rules().item("planes", std::ptrdiff_t(i));
        r.f64s("normal", m.planes[i].normal);
        m.planes[i].offset = r.f64("offset");
    }
    r.rules().item(nullptr);
    // cutFlags, optional: absent means 0 (more than one byte left is left over).
    if (r.rules().ok() && r.remaining() == 1) {
        const std::uint8_t flags = r.u8("cutFlags");
        r.rules().bits("cutFlags", flags, kCutCap);
        // One encoding per message: no flags leave the byte out.
        if (flags == 0)
            r.rules().fail(ErrorCode::OutOfRange, "cutFlags",
                           "is 0 (sent by leaving the byte out)");
        m.cap = (flags & kCutCap) != 0;
    }
    return m;
}

Message readHistogram(PayloadReader& r) {
    Histogram m;
    m.valueMin = r.f64("valueMin");
    m.valueMax = r.f64("valueMax");
    const std::size_t n = r.count("counts", 2, kMaxHistogramBins, 8);
    m.counts.reserve(n);
    for (std::size_t i = 0; i < n && r.rules().ok(); ++i)
        m.counts.push_back(r.u64("counts"));
    return m;
}

struct PayloadKind {
    Message (*read)(PayloadReader&);
    std::optional<std::size_t> fixedBytes; ///< nullopt for variable-size payloads
};

/// Indexed by type - 1, in the order of MessageType.
constexpr PayloadKind kKinds[] = {
    {readHello, {}},
    {readAuth, {}},
    {readAuthOk, 0},
    {readListVolumes, 0},
    {readVolumeList, {}},
    {readOpenVolume, {}},
    {readVolumeOpened, {}},
    {readSetCamera, kSetCameraBytes},
    {readSetTransferFunction, {}},
    {readSetRenderOptions, kRenderOptionsBytes},
    {readRequestFrame, 1},
    {readFrame, {}},
    {readRequestStats, 0},
    {readStats, {}},
    {readError, {}},
    {readBye, 2},
    {readRequestHistogram, 0},
    {readHistogram, {}},
    {readSetFrameBudget, 3},
    {readSetModeAndClip, {}},
};
static_assert(std::size(kKinds) == std::size_t(MessageType::SetModeAndClip));

DecodeError decodeError(detail::Violation v, std::uint8_t type) {
    return DecodeError{v.code, false, type, 0, std::move(v.text)};
}

/// Flags and fixed size, checked before anything is read.
void checkEnvelope(Rules& rules, const PayloadKind& kind, std::uint16_t flags, std::size_t bytes) {
    if (flags != 0) // no type defines a flag yet
        rules.fail(ErrorCode::BadPayload, "flags",
                   detail::hex(flags) + " sets bits the type does not define");
    if (kind.fixedBytes && bytes != *kind.fixedBytes)
        rules.fail(ErrorCode::BadPayload, "",
                   "payload is " + std::to_string(bytes) + " bytes, expected " +
                       std::to_string(*kind.fixedBytes));
}

} // namespace

std::variant<Message, DecodeError> decodePayload(std::uint8_t type, std::uint16_t flags,
                                                 std::span<const std::uint8_t> payload) {
    if (type == 0 || type > std::size(kKinds))
        return DecodeError{ErrorCode::UnknownType, false, type, 0,
                           "header.type: " + detail::hex(type) + " is not a message type"};
    const PayloadKind& kind = kKinds[type - 1];
    Rules rules(typeName(type));
    checkEnvelope(rules, kind, flags, payload.size());
    if (!rules.ok()) return decodeError(*rules.take(), type);
    PayloadReader reader(payload, rules);
    Message m = kind.read(reader);
    rules.item(nullptr);
    if (rules.ok() && reader.remaining() != 0)
        rules.fail(ErrorCode::BadPayload, "",
                   std::to_string(reader.remaining()) + " bytes left over after the last field");
    if (!rules.ok()) return decodeError(*rules.take(), type);
    if (auto violation = detail::firstViolation(m)) return decodeError(std::move(*violation), type);
    return m;
}

} // namespace bc::protocol
