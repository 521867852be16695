#include "protocol/Wire.h"

#include <utility>

namespace bc::protocol {

const char* typeName(std::uint8_t type) {
    switch (MessageType(type)) {
    case MessageType::Hello:
        return "Hello";
    case MessageType::Auth:
        return "Auth";
    case MessageType::AuthOk:
        return "AuthOk";
    case MessageType::ListVolumes:
        return "ListVolumes";
    case MessageType::VolumeList:
        return "VolumeList";
    case MessageType::OpenVolume:
        return "OpenVolume";
    case MessageType::VolumeOpened:
        return "VolumeOpened";
    case MessageType::SetCamera:
        return "SetCamera";
    case MessageType::SetTransferFunction:
        return "SetTransferFunction";
    case MessageType::SetRenderOptions:
        return "SetRenderOptions";
    case MessageType::RequestFrame:
        return "RequestFrame";
    case MessageType::Frame:
        return "Frame";
    case MessageType::RequestStats:
        return "RequestStats";
    case MessageType::Stats:
        return "Stats";
    case MessageType::Error:
        return "Error";
    case MessageType::Bye:
        return "Bye";
    case MessageType::RequestHistogram:
        return "RequestHistogram";
    case MessageType::Histogram:
        return "Histogram";
    case MessageType::SetFrameBudget:
        return "SetFrameBudget";
    case MessageType::SetModeAndClip:
        return "SetModeAndClip";
    }
    return "unknown";
}

const char* errorName(std::uint16_t code) {
    switch (ErrorCode(code)) {
    case ErrorCode::BadMagic:
        return "BadMagic";
    case ErrorCode::UnsupportedVersion:
        return "UnsupportedVersion";
    case ErrorCode::TooLarge:
        return "TooLarge";
    case ErrorCode::UnknownType:
        return "UnknownType";
    case ErrorCode::BadPayload:
        return "BadPayload";
    case ErrorCode::OutOfRange:
        return "OutOfRange";
    case ErrorCode::NotAuthenticated:
        return "NotAuthenticated";
    case ErrorCode::AuthFailed:
        return "AuthFailed";
    case ErrorCode::UnknownVolume:
        return "UnknownVolume";
    case ErrorCode::NoVolume:
        return "NoVolume";
    case ErrorCode::Busy:
        return "Busy";
    case ErrorCode::Timeout:
        return "Timeout";
    case ErrorCode::RenderFailed:
        return "RenderFailed";
    case ErrorCode::ShuttingDown:
        return "ShuttingDown";
    case ErrorCode::BadState:
        return "BadState";
    case ErrorCode::Internal:
        return "Internal";
    case ErrorCode::NotFound:
        return "NotFound";
    }
    return "unknown";
}

namespace {

constexpr std::pair<Renderer, std::string_view> kRendererNames[] = {
    {Renderer::GpuRaycaster, "gpu"},      {Renderer::CpuRaycaster, "cpu"},
    {Renderer::Reference, "reference"},   {Renderer::Splatter, "splat"},
    {Renderer::GpuSplatter, "splat-gpu"}, {Renderer::Auto, "auto"},
};

constexpr std::pair<BlendMode, std::string_view> kBlendModeNames[] = {
    {BlendMode::Composite, "composite"}, {BlendMode::Maximum, "mip"},
    {BlendMode::Minimum, "minip"},       {BlendMode::Average, "average"},
    {BlendMode::Isosurface, "iso"},
};

} // namespace

std::string_view blendModeName(BlendMode mode) {
    for (const auto& [m, name] : kBlendModeNames)
        if (m == mode) return name;
    return "unknown";
}

std::optional<BlendMode> blendModeNamed(std::string_view name) {
    for (const auto& [m, n] : kBlendModeNames)
        if (n == name) return m;
    return std::nullopt;
}

std::string_view rendererName(Renderer renderer) {
    for (const auto& [r, name] : kRendererNames)
        if (r == renderer) return name;
    return "unknown";
}

std::optional<Renderer> rendererNamed(std::string_view name) {
    for (const auto& [r, n] : kRendererNames)
        if (n == name) return r;
    return std::nullopt;
}

} // namespace bc::protocol
