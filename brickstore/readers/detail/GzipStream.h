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

/// The one place zlib's return codes of a stream inflated piece by piece become exceptions:
/// returns `code` when it is Z_OK, Z_STREAM_END or Z_BUF_ERROR (no progress: not fatal);
/// throws std::bad_alloc on Z_MEM_ERROR, else FormatError(file, "data", "what: message")
/// with the stream's message (z_stream::msg, may be null) or zlib's text for the code.
int zlibCheck(int code, const char* message, const std::string& file, const std::string& what);

} // namespace bc::brickstore::detail
