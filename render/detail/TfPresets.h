#pragma once
// The transfer-function presets of configs/tf, embedded at build time by bc_embed_text
// (cmake/EmbedText.cmake; the generated TfPresets.cpp lives in the build tree).
#include <cstddef>

namespace bc::render::detail {

struct TfPresetText {
    const char* name; ///< file name without ".json"
    const char* json; ///< the file's text
};

/// The embedded presets, sorted by name.
extern const TfPresetText kTfPresets[];
extern const std::size_t kTfPresetCount;

} // namespace bc::render::detail
