#pragma once
// Opening a file that must be a regular one, without blocking: open() of a FIFO waits for a
// writer (forever, for a store a daemon starts on), and a device may act on being opened. The
// path is stat()ed first, so a FIFO, socket or device is never opened, and what is opened is
// checked again (fstat, under O_NONBLOCK) in case the path changed in between.
#include <cstdint>
#include <optional>
#include <string>

#include <sys/types.h>

namespace bc::brickstore::detail {

/// "a FIFO", "a socket", "a character device", "a block device", "a folder", "a symbolic
/// link", "an unknown kind of file": what a file of st_mode `mode` is, as errors say it.
std::string fileKindText(mode_t mode);

/// Why `path` is no regular file to read: "not a regular file (a FIFO)", or the text of
/// stat's errno ("No such file or directory"); nullopt when it is one. Never opens it.
std::optional<std::string> notRegularFile(const std::string& path);

/// Opens `path` read-only and close-on-exec (its reads block as usual) when it is a regular
/// file. Returns the descriptor, or -1 with `why` set as notRegularFile sets it.
int openRegularFile(const std::string& path, std::string& why);

/// For the readers' inputs: @throw FormatError(path, "path", "not a regular file (a FIFO)")
/// when notRegularFile says so; a path stat() cannot see is left to the reader's own open.
void requireRegularFile(const std::string& path);

/// st_mode of `path` (links followed); 0 when stat() fails.
mode_t fileMode(const std::string& path);

/// Bytes of the file at `path`, or of the regular files directly in the folder at `path` (a
/// DICOM series, a TIFF stack): what an input holds. 0 when it cannot be stat()ed.
std::uint64_t fileOrFolderBytes(const std::string& path);

} // namespace bc::brickstore::detail
