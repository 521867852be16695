#pragma once
// The browser viewer's files, embedded at build time (cmake/EmbedWebAssets.cmake): the only
// things the HTTP side serves. A URL is looked up here by exact path; nothing maps to a file.
#include <cstddef>
#include <string_view>

namespace bc::server::detail {

struct WebAsset {
    std::string_view path; ///< "/" for web/index.html, else "/" + the path under web/
    std::string_view contentType;
    std::string_view body;
};

extern const WebAsset kWebAssets[];
extern const std::size_t kWebAssetCount;

/// The asset served at `path` (exact match, no decoding), nullptr for none.
const WebAsset* findWebAsset(std::string_view path);

} // namespace bc::server::detail
