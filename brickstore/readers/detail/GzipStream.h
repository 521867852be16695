#pragma once
// A gzip (or zlib) stream inflated on the fly, over any ByteStream (GzipStream.cpp).
#include "brickstore/readers/detail/RawStream.h"

#include <memory>
#include <string>

namespace bc::brickstore::detail {

/// Inflates `compressed` (gzip members, concatenated, or one zlib stream); `file` is named in
/// errors. Truncated or corrupt data throws FormatError(file, "data"); so does data that
/// inflates past what was read when expectEnd() is called.
std::unique_ptr<ByteStream> openGzipStream(std::unique_ptr<ByteStream> compressed,
                                           const std::string& file);

} // namespace bc::brickstore::detail
