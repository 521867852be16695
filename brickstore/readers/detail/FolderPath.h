#pragma once
// Files named inside an input (NRRD's detached data, MetaImage's ElementDataFile, OME-Zarr's
// dataset paths and a Zarr array's chunk files) resolved so that they cannot lead out of the
// input's folder: a header from an untrusted upload must not make the server read
// /etc/shadow. Defined in FolderPath.cpp.
#include <string>

namespace bc::brickstore::detail {

/// The canonical path of `name` inside the canonical folder `root`, which it must not leave:
/// no absolute path, no ".." component, no symlink that resolves outside it (nor one to a
/// missing file). It may be `root` itself. `file` and `field` name what named it in errors.
/// @throw FormatError(file, field) saying which rule `name` breaks.
std::string resolveInside(const std::string& root, const std::string& name, const std::string& file,
                          const std::string& field);

/// A data file `name` relative to the folder of the header at `headerPath`: resolveInside that
/// folder, and not the folder itself. @throw FormatError(headerPath, field).
std::string resolveInFolder(const std::string& headerPath, const std::string& name,
                            const std::string& field);

} // namespace bc::brickstore::detail
