#pragma once
// The constants and enumerations of the wire format (protocol/PROTOCOL.md): what the header
// carries, the message types, error codes and the enumerated fields of the messages.
// Everything here is serialized, so every enum has an explicit underlying type and its
// values are the ones PROTOCOL.md gives.
#include <cstddef>
#include <cstdint>
#include <optional>
#include <string_view>

namespace bc::protocol {

inline constexpr std::uint32_t kMagic = 0x54534342; ///< the bytes "BCST", little-endian
inline constexpr std::uint8_t kVersion = 1;
inline constexpr std::size_t kHeaderBytes = 16;

inline constexpr std::uint32_t kMaxClientPayloadBytes = 64u << 10;
inline constexpr std::uint32_t kDefaultMaxServerPayloadBytes = 80u << 20;
inline constexpr std::uint32_t kMaxImageEdge = 4096;
inline constexpr std::size_t kMaxVolumeNameBytes = 64;
inline constexpr std::size_t kMaxTokenBytes = 256;
inline constexpr std::size_t kMaxSoftwareBytes = 64;
inline constexpr std::size_t kMaxPresetBytes = 64;
inline constexpr std::size_t kMaxErrorMessageBytes = 1024;
inline constexpr std::size_t kMaxStatNameBytes = 128;
inline constexpr std::size_t kMaxTfPoints = 256;
inline constexpr std::size_t kMaxHistogramBins = 4096;
inline constexpr std::size_t kMaxVolumes = 1024;
inline constexpr std::size_t kMaxStats = 4096;
inline constexpr std::size_t kMaxCodecs = 16;
inline constexpr std::uint8_t kLevelAutomatic = 255;
/// SetFrameBudget's limits: the interactive target's ms, the PSNR bound's dB.
inline constexpr std::uint16_t kMaxInteractiveMs = 10000;
inline constexpr std::uint8_t kMinRestPsnrDb = 20, kMaxRestPsnrDb = 50;
inline constexpr std::uint8_t kMaxLevel = 15;
/// SetModeAndClip's most clip planes.
inline constexpr std::size_t kMaxClipPlanes = 6;

enum class MessageType : std::uint8_t {
    Hello = 0x01,
    Auth = 0x02,
    AuthOk = 0x03,
    ListVolumes = 0x04,
    VolumeList = 0x05,
    OpenVolume = 0x06,
    VolumeOpened = 0x07,
    SetCamera = 0x08,
    SetTransferFunction = 0x09,
    SetRenderOptions = 0x0A,
    RequestFrame = 0x0B,
    Frame = 0x0C,
    RequestStats = 0x0D,
    Stats = 0x0E,
    Error = 0x0F,
    Bye = 0x10,
    RequestHistogram = 0x11,
    Histogram = 0x12,
    SetFrameBudget = 0x13,
    SetModeAndClip = 0x14,
};

enum class ErrorCode : std::uint16_t {
    BadMagic = 1,
    UnsupportedVersion = 2,
    TooLarge = 3,
    UnknownType = 4,
    BadPayload = 5,
    OutOfRange = 6,
    NotAuthenticated = 7,
    AuthFailed = 8,
    UnknownVolume = 9,
    NoVolume = 10,
    Busy = 11,
    Timeout = 12,
    RenderFailed = 13,
    ShuttingDown = 14,
    BadState = 15,
    Internal = 16,
    NotFound = 17,
};

/// Hello.capabilities bits.
enum Capability : std::uint32_t {
    kCapAuthRequired = 1u << 0,
    kCapCpuRenderer = 1u << 1,
    kCapGpuRenderer = 1u << 2,
    kCapContinuous = 1u << 3,
    kCapFrameBudget = 1u << 4,   ///< takes SetFrameBudget (servers since 2026-12-06)
    kCapModesAndClips = 1u << 5, ///< takes SetModeAndClip (servers since 2026-12-07)
    kCapCapping = 1u << 6,       ///< takes SetModeAndClip's cutFlags (servers since 2026-12-08)
};

/// SetModeAndClip.cutFlags bits (the byte is optional; absent means 0).
enum CutFlag : std::uint8_t {
    kCutCap = 1u << 0, ///< draw the faces the cuts make (composite and isosurface only)
};

/// RenderOptions.flags bits.
enum RenderFlag : std::uint16_t {
    /// Interactive frames come at the size they were drawn (half the width and height, rounded
    /// up) for the client to scale, instead of scaled up by pixel replication: a browser's
    /// canvas scales them smoothly, and the frame has a quarter of the pixels to encode and send.
    kFlagUnscaledInteractive = 1u << 0,
    kFlagAll = (1u << 1) - 1,
};

/// RenderOptions.techniques bits.
enum Technique : std::uint32_t {
    kTechBrickSkipping = 1u << 0,
    kTechOctreeSkipping = 1u << 1, ///< needs kTechBrickSkipping
    kTechEarlyTermination = 1u << 2,
    kTechOcclusionFrustums = 1u << 3, ///< needs kTechBrickSkipping
    kTechShading = 1u << 4,
    kTechRayGuided = 1u << 5, ///< raycasters: load no brick behind saturated rays
    /// Raycasters: jittered ray starts (render::RenderOptions::jitter): fine noise instead of a
    /// fixed lattice's wood-grain rings; on by default (bench/frontier/README.md says why).
    kTechJitter = 1u << 6,
    kTechAll = (1u << 7) - 1,
};

enum class Codec : std::uint8_t { Raw = 0, Zstd = 1, ZstdDelta = 2, Jpeg = 3, Png = 4 };
/// SetModeAndClip.mode: what a ray makes of its samples (render/MODES.md).
enum class BlendMode : std::uint8_t {
    Composite = 0,
    Maximum = 1,
    Minimum = 2,
    Average = 3,
    Isosurface = 4,
};

enum class Renderer : std::uint8_t {
    GpuRaycaster = 0,
    CpuRaycaster = 1,
    Reference = 2,
    Splatter = 3,    ///< hybrid forward splatting on the CPU
    GpuSplatter = 4, ///< the same model drawn by OpenGL
    /// The server's choice, made once: the GPU raycaster on a hardware GPU, the CPU raycaster
    /// where its OpenGL is a software rasteriser or it has none. Since 2026-12-03.
    Auto = 5,
};
enum class Quality : std::uint8_t { Adaptive = 0, Refined = 1, Interactive = 2 };
enum class FrameMode : std::uint8_t { Once = 0, ContinuousOn = 1, ContinuousOff = 2 };
enum class TfKind : std::uint8_t { Preset = 0, Points = 1 };
enum class ShadingSource : std::uint8_t { Message = 0, Preset = 1 };
enum class Placement : std::uint8_t { Value = 0, Fraction = 1, Percentile = 2 };
enum class VoxelType : std::uint8_t { U8 = 0, U16 = 1, I16 = 2, F32 = 3 };
enum class ByeReason : std::uint16_t { Normal = 0, ShuttingDown = 1, IdleTimeout = 2 };

/// Name of a message type for logs and errors ("SetCamera"), "unknown" for other values.
const char* typeName(std::uint8_t type);
/// Name of an error code ("OutOfRange"), "unknown" for other values.
const char* errorName(std::uint16_t code);
/// A renderer's name, as the programs' --renderer, the metrics and the renderer registry
/// (render/RendererRegistry.h) spell it: "gpu", "cpu", "reference", "splat", "splat-gpu",
/// "auto"; "unknown" for other values.
std::string_view rendererName(Renderer renderer);
/// The renderer named `name` (rendererName), or nullopt.
std::optional<Renderer> rendererNamed(std::string_view name);
/// A mode's name, as `--mode` and render::parseBlendMode spell it: "composite", "mip",
/// "minip", "average", "iso"; "unknown" for other values.
std::string_view blendModeName(BlendMode mode);
/// The mode named `name` (blendModeName), or nullopt.
std::optional<BlendMode> blendModeNamed(std::string_view name);

} // namespace bc::protocol
