#include "brickstore/readers/detail/FolderPath.h"

#include "brickstore/Error.h"

#include <algorithm>
#include <filesystem>

namespace bc::brickstore::detail {

namespace fs = std::filesystem;

std::string resolveInFolder(const std::string& headerPath, const std::string& name,
                            const std::string& field) {
    const fs::path rel(name);
    if (rel.is_absolute() || rel.has_root_path())
        throw FormatError(headerPath, field,
                          "'" + name + "' is an absolute path; it must be relative to the " +
                              "header's folder");
    for (const fs::path& part : rel)
        if (part == "..")
            throw FormatError(headerPath, field,
                              "'" + name + "' has a '..' component; it must lie in the " +
                                  "header's folder");
    fs::path dir = fs::path(headerPath).parent_path();
    if (dir.empty()) dir = ".";
    std::error_code ec;
    const fs::path realDir = fs::canonical(dir, ec);
    const fs::path real = ec ? fs::path() : fs::weakly_canonical(dir / rel, ec);
    if (ec) throw FormatError(headerPath, field, "cannot resolve '" + name + "': " + ec.message());
    if (fs::is_symlink(fs::symlink_status(real, ec)))
        throw FormatError(headerPath, field, "'" + name + "' is a symlink to a missing file");
    const auto [dirEnd, realIt] =
        std::mismatch(realDir.begin(), realDir.end(), real.begin(), real.end());
    if (dirEnd != realDir.end() || realIt == real.end())
        throw FormatError(headerPath, field,
                          "'" + name + "' resolves to " + real.string() +
                              ", outside the header's folder (symlink?)");
    return real.string();
}

} // namespace bc::brickstore::detail
