#include "brickstore/readers/detail/FolderPath.h"

#include "brickstore/Error.h"

#include <algorithm>
#include <filesystem>

namespace bc::brickstore::detail {

namespace fs = std::filesystem;

std::string resolveInside(const std::string& root, const std::string& name, const std::string& file,
                          const std::string& field) {
    const fs::path rel(name);
    if (name.empty()) throw FormatError(file, field, "is empty");
    if (rel.is_absolute() || rel.has_root_path())
        throw FormatError(file, field,
                          "'" + name + "' is an absolute path; it must lie in the folder " + root);
    for (const fs::path& part : rel)
        if (part == "..")
            throw FormatError(file, field,
                              "'" + name + "' has a '..' component; it must lie in the folder " +
                                  root);
    std::error_code ec;
    const fs::path real = fs::weakly_canonical(fs::path(root) / rel, ec);
    if (ec) throw FormatError(file, field, "cannot resolve '" + name + "': " + ec.message());
    if (fs::is_symlink(fs::symlink_status(real, ec)))
        throw FormatError(file, field, "'" + name + "' is a symlink to a missing file");
    const fs::path base(root);
    const auto [baseEnd, realIt] =
        std::mismatch(base.begin(), base.end(), real.begin(), real.end());
    if (baseEnd != base.end())
        throw FormatError(file, field,
                          "'" + name + "' resolves to " + real.string() + ", outside the folder " +
                              root + " (symlink?)");
    return real.string();
}

std::string resolveInFolder(const std::string& headerPath, const std::string& name,
                            const std::string& field) {
    fs::path dir = fs::path(headerPath).parent_path();
    if (dir.empty()) dir = ".";
    std::error_code ec;
    const fs::path realDir = fs::canonical(dir, ec);
    if (ec) throw FormatError(headerPath, field, "cannot resolve its folder: " + ec.message());
    const std::string real = resolveInside(realDir.string(), name, headerPath, field);
    if (fs::path(real) == realDir)
        throw FormatError(headerPath, field,
                          "'" + name + "' names the header's folder, not a file");
    return real;
}

} // namespace bc::brickstore::detail
