#pragma once
// A file named inside an input (NRRD's detached data, MetaImage's ElementDataFile, OME-Zarr's
// dataset paths) resolved so that it cannot lead out of the input's folder: a header from an
// untrusted upload must not make the server read /etc/shadow. Defined in FolderPath.cpp.
#include <string>

namespace bc::brickstore::detail {

/// `name`, relative to the folder of `headerPath`, as a canonical path inside that folder. No
/// absolute path, no ".." component, no symlink that resolves outside it (nor one to a
/// missing file); a name that resolves to the folder itself is refused too.
/// @throw FormatError(headerPath, field) saying which rule `name` breaks.
std::string resolveInFolder(const std::string& headerPath, const std::string& name,
                            const std::string& field);

} // namespace bc::brickstore::detail
