#pragma once
// Transfer functions named on a command line: an embedded preset, or a JSON file. Only the
// programs (tools/, bench/) read transfer-function files; the daemon reads the files its
// config names at start-up (server/DaemonConfig) and nothing a client sends names a file.
#include "render/Error.h"
#include "render/TransferFunction.h"

#include <cstdint>
#include <filesystem>
#include <fstream>
#include <sstream>
#include <string>

namespace bc::tools {

/// Transfer-function files are a few kilobytes; anything far larger is not one.
inline constexpr std::uintmax_t kMaxTfFileBytes = 16u << 20;

/// The text of a transfer-function file. @throw render::RenderInputError naming the file
/// when it is missing, not a regular file, larger than kMaxTfFileBytes or unreadable.
inline std::string readTransferFunctionFile(const std::string& path) {
    std::error_code ec;
    if (!std::filesystem::is_regular_file(path, ec))
        throw render::RenderInputError(path, "(file)", "no such file");
    const auto bytes = std::filesystem::file_size(path, ec);
    if (ec || bytes > kMaxTfFileBytes)
        throw render::RenderInputError(
            path, "(file)",
            ec ? ec.message() : "larger than " + std::to_string(kMaxTfFileBytes) + " bytes");
    std::ifstream in(path, std::ios::binary);
    std::ostringstream text;
    text << in.rdbuf();
    if (!in) throw render::RenderInputError(path, "(file)", "cannot read");
    return text.str();
}

/// A preset name (no '/', no ".json") is the embedded preset; anything else is a file.
/// @throw render::RenderInputError naming the file and field at fault, or an unknown name
/// (listing the presets).
inline render::TransferFunction loadTransferFunction(const std::string& fileOrPreset,
                                                     const render::VolumeValueStats& stats) {
    const bool presetLike =
        fileOrPreset.find('/') == std::string::npos && !fileOrPreset.ends_with(".json");
    if (presetLike && render::TransferFunction::isPreset(fileOrPreset))
        return render::TransferFunction::preset(fileOrPreset, stats);
    std::error_code ec;
    if (presetLike && !std::filesystem::is_regular_file(fileOrPreset, ec)) {
        std::string list;
        for (const auto& name : render::TransferFunction::presetNames())
            list += (list.empty() ? "" : ", ") + name;
        throw render::RenderInputError(fileOrPreset, "(file)",
                                       "no such preset or file; presets: " + list);
    }
    return render::TransferFunction::parse(readTransferFunctionFile(fileOrPreset), fileOrPreset,
                                           stats);
}

} // namespace bc::tools
