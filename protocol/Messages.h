#pragma once
// The messages of protocol/PROTOCOL.md as plain structs, and their encoding. One struct per
// message type, fields in wire order; a Message is any of them. Decoding lives in Decoder.h.
#include "protocol/Wire.h"

#include <array>
#include <cstddef>
#include <cstdint>
#include <optional>
#include <string>
#include <string_view>
#include <utility>
#include <variant>
#include <vector>

namespace bc::protocol {

struct Hello {
    std::uint16_t versionMin = kVersion, versionMax = kVersion;
    std::uint32_t capabilities = 0; ///< Capability bits
    std::vector<Codec> codecs;      ///< the client's decoders; the server's encoders
    std::string software;           ///< free text, <= kMaxSoftwareBytes
    bool operator==(const Hello&) const = default;
};

struct Auth {
    std::string token; ///< 1 .. kMaxTokenBytes
    bool operator==(const Auth&) const = default;
};

struct AuthOk {
    bool operator==(const AuthOk&) const = default;
};

struct ListVolumes {
    bool operator==(const ListVolumes&) const = default;
};

struct VolumeInfo {
    std::string name; ///< a catalog name: 1..64 of A-Z a-z 0-9 . _ -, not starting with '.'
    std::array<std::uint32_t, 3> dims{}; ///< level 0, voxels
    std::array<double, 3> spacingMm{};
    VoxelType voxelType = VoxelType::U8;
    std::uint8_t levels = 1;
    double valueMin = 0, valueMax = 0;
    std::uint64_t storedBytes = 0;
    bool operator==(const VolumeInfo&) const = default;
};

struct VolumeList {
    std::vector<VolumeInfo> volumes;
    bool operator==(const VolumeList&) const = default;
};

struct OpenVolume {
    std::string name;
    bool operator==(const OpenVolume&) const = default;
};

struct VolumeOpened {
    VolumeInfo info;
    bool operator==(const VolumeOpened&) const = default;
};

struct SetCamera {
    std::uint32_t cameraId = 0; ///< the client's; echoed by the Frame that draws it
    std::array<double, 3> eye{}, target{}, up{0, 0, 1};
    double fovYDeg = 30;
    bool orthographic = false;
    double orthoHeight = 1;
    bool operator==(const SetCamera&) const = default;
};

struct TfPoint {
    Placement placement = Placement::Value;
    double position = 0;
    std::array<float, 4> rgba{}; ///< straight colour and opacity per unit step, each in [0, 1]
    bool operator==(const TfPoint&) const = default;
};

/// kind Preset carries `preset` and no points; kind Points carries points and no preset.
struct SetTransferFunction {
    TfKind kind = TfKind::Preset;
    bool shading = true;
    ShadingSource shadingSource = ShadingSource::Preset;
    std::string preset;
    std::vector<TfPoint> points;
    bool operator==(const SetTransferFunction&) const = default;
};

struct RenderOptions {
    std::uint16_t width = 256, height = 256;
    float stepVoxels = 1;
    std::uint32_t techniques = kTechAll; ///< Technique bits
    float ertThreshold = 0.99f;
    Renderer renderer = Renderer::Auto;
    Quality quality = Quality::Adaptive;
    Codec codec = Codec::Zstd;
    std::uint8_t codecQuality = 0; ///< JPEG 1..100, zstd 1..19, 0 for the codec's default
    std::uint8_t level = kLevelAutomatic;
    /// The codec of refined frames under adaptive quality (lossless at rest, JPEG while the
    /// camera moves); none: `codec`. On the wire: 0 for none, else the codec's value + 1.
    std::optional<Codec> refinedCodec;
    std::uint16_t flags = 0; ///< RenderFlag bits
    bool operator==(const RenderOptions&) const = default;
};

struct SetRenderOptions {
    RenderOptions options;
    bool operator==(const SetRenderOptions&) const = default;
};

struct RequestFrame {
    FrameMode mode = FrameMode::Once;
    bool operator==(const RequestFrame&) const = default;
};

struct FrameHeader {
    std::uint32_t frameId = 0, cameraId = 0;
    std::uint16_t width = 0, height = 0;
    Codec codec = Codec::Raw;
    std::uint8_t level = 0;
    bool refined = false, keyframe = false;
    float queueMs = 0, renderMs = 0, encodeMs = 0;
    std::uint64_t samples = 0;
    std::uint32_t bricksDrawn = 0, bricksSkipped = 0;
    std::uint64_t bytesUploaded = 0;
    bool occlusionUsed = false;
    /// Answered from the server's frame cache: drawn before for an identical request (this or
    /// another session's); samples, bricks and bytesUploaded are then 0 (nothing was drawn).
    bool cached = false;
    /// Drawn at width and height over this (rounded up): 1 refined; an interactive frame's
    /// divisor; 0 from servers before 2026-12-06.
    std::uint8_t scale = 0;
    /// The server's estimate of the frame's PSNR against the converged image, whole dB rounded
    /// down (<= kMaxRestPsnrDb); 0: none.
    std::uint8_t estimatedPsnrDb = 0;
    bool operator==(const FrameHeader&) const = default;
};

/// `image` is the encoded image; FrameHeader's imageBytes on the wire is its size.
struct Frame {
    FrameHeader header;
    std::vector<std::uint8_t> image;
    bool operator==(const Frame&) const = default;
};

struct RequestStats {
    bool operator==(const RequestStats&) const = default;
};

struct Stats {
    std::vector<std::pair<std::string, double>> counters; ///< names <= kMaxStatNameBytes
    bool operator==(const Stats&) const = default;
};

struct Error {
    ErrorCode code = ErrorCode::Internal;
    bool fatal = false;
    std::uint8_t offendingType = 0; ///< the type of the message that caused it, 0 for none
    std::string message;            ///< <= kMaxErrorMessageBytes (see fitText)
    bool operator==(const Error&) const = default;
};

struct Bye {
    ByeReason reason = ByeReason::Normal;
    bool operator==(const Bye&) const = default;
};

struct RequestHistogram {
    bool operator==(const RequestHistogram&) const = default;
};

/// The session's frame-time target and error bound at rest (PROTOCOL.md, SetFrameBudget).
struct SetFrameBudget {
    std::uint16_t interactiveMs = 0; ///< 0: the server's frames.interactive_ms; else 1..10000
    std::uint8_t restPsnrDb = 0;     ///< 0: none; else kMinRestPsnrDb..kMaxRestPsnrDb
    bool operator==(const SetFrameBudget&) const = default;
};

/// A half-space kept: the world points x (mm) with dot(normal, x) + offset >= 0.
struct ClipPlane {
    std::array<double, 3> normal{0, 0, 1};
    double offset = 0;
    bool operator==(const ClipPlane&) const = default;
};

/// What a ray makes of its samples and what of the volume is drawn (PROTOCOL.md,
/// SetModeAndClip): the mode, the iso value, a crop box (world mm) and up to six clip planes.
struct SetModeAndClip {
    BlendMode mode = BlendMode::Composite;
    double isoValue = 0; ///< BlendMode::Isosurface: the surface's value, in the volume's units
    bool cropped = false;
    std::array<double, 3> cropMin{}, cropMax{}; ///< all 0 unless cropped
    std::vector<ClipPlane> planes;              ///< at most kMaxClipPlanes
    /// cutFlags bit 0 (kCutCap): draw the faces the cuts make (composite and isosurface only).
    bool cap = false;
    bool operator==(const SetModeAndClip&) const = default;
};

/// The open volume's level-0 voxels in equal bins over [valueMin, valueMax].
struct Histogram {
    double valueMin = 0, valueMax = 0;
    std::vector<std::uint64_t> counts; ///< 1 .. kMaxHistogramBins bins
    bool operator==(const Histogram&) const = default;
};

using Message =
    std::variant<Hello, Auth, AuthOk, ListVolumes, VolumeList, OpenVolume, VolumeOpened, SetCamera,
                 SetTransferFunction, SetRenderOptions, RequestFrame, Frame, RequestStats, Stats,
                 Error, Bye, RequestHistogram, Histogram, SetFrameBudget, SetModeAndClip>;

inline constexpr std::size_t kRenderOptionsBytes = 24;
inline constexpr std::size_t kFrameHeaderBytes = 60;

/// The wire type of the alternative `m` holds.
MessageType typeOf(const Message& m);

/// Appends the 16-byte header and the payload of `m` to `out`; `out` is unchanged on throw.
/// @throw ProtocolError naming the field when PROTOCOL.md cannot carry `m` (a string over its
/// limit, too many points, an image edge of 0 or over 4096, a frame over the default server
/// payload limit...): the same rules the decoder applies. Senders encode only valid messages.
void encode(const Message& m, std::uint32_t request, std::vector<std::uint8_t>& out);
/// The header and payload of `m` as a new buffer. @throw ProtocolError as above.
std::vector<std::uint8_t> encode(const Message& m, std::uint32_t request = 0);

/// `text` as valid UTF-8 of at most maxBytes (cut at a character boundary, invalid bytes
/// replaced by '?'): what a sender does to arbitrary text before it goes into a str field.
std::string fitText(std::string_view text, std::size_t maxBytes);

} // namespace bc::protocol
