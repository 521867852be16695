#pragma once
// The daemon's default configuration, configs/brickcastd.toml, embedded at build time by
// bc_embed_text (cmake/EmbedText.cmake; the generated DaemonConfigDefault.cpp lives in the build
// tree). DaemonConfig::defaultToml() is its text.
#include <cstddef>

namespace bc::server::detail {

struct DefaultConfigText {
    const char* name; ///< "brickcastd.toml"
    const char* toml; ///< the file's text, byte for byte
};

/// The embedded file: one, configs/brickcastd.toml.
extern const DefaultConfigText kDefaultConfigFiles[];
extern const std::size_t kDefaultConfigFileCount;

} // namespace bc::server::detail
