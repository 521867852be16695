#pragma once
// Forward-only byte streams under the raw and NRRD readers (a plain file, a zstd stream), and
// the slice source that turns such a stream of raw voxels into a VolumeSource. Defined in
// RawStream.cpp. A stream never holds more than one bounded input buffer, so the volume never
// sits in memory whole.
#include "brickstore/Readers.h"

#include <cstddef>
#include <cstdint>
#include <memory>
#include <optional>
#include <span>
#include <string>

namespace bc::brickstore::detail {

/// Bytes read front to back, once. Errors name the file the bytes come from.
class ByteStream {
  public:
    virtual ~ByteStream() = default;
    /// Fills `out` as far as the stream reaches; returns fewer bytes than asked only at its end.
    /// @throw FormatError when the bytes are corrupt (a broken or truncated compressed stream).
    virtual std::size_t read(std::span<std::byte> out) = 0;
    /// Called once all declared bytes are read. @throw FormatError when more bytes follow.
    virtual void expectEnd() = 0;
    /// What the bytes are, for messages: "file", "zstd stream", "gzip data".
    virtual const char* kind() const = 0;
};

/// The bytes of `path` from `offsetBytes` on. @throw FormatError(path, "path") if unreadable.
std::unique_ptr<ByteStream> openFileStream(const std::string& path, std::uint64_t offsetBytes);

/// Size of the file at `path`. @throw FormatError(path, "path") if it cannot be read.
std::uint64_t fileBytes(const std::string& path);

/// Decompresses the zstd frames of `compressed` (one or more, concatenated); `file` is named
/// in errors.
std::unique_ptr<ByteStream> openZstdStream(std::unique_ptr<ByteStream> compressed,
                                           const std::string& file);

/// Content size declared by the first zstd frame of `path`, when it declares one. A file may
/// hold further frames, so this is a lower bound of the decompressed size.
/// @throw FormatError(path, "data") when the file does not start with a zstd frame.
std::optional<std::uint64_t> zstdFirstFrameBytes(const std::string& path);

/// What the frames of a zstd file say about it, walked from their frame and block headers
/// without decompressing: the sum of the content sizes they declare (nullopt when a frame
/// declares none) and the file's size.
struct ZstdFrames {
    std::optional<std::uint64_t> contentBytes;
    std::uint64_t fileBytes = 0;
};
/// @throw FormatError(path, "data") when the file is not a sequence of whole zstd frames.
ZstdFrames zstdFrames(const std::string& path);

/// Slices of raw voxels (x fastest, `endian` byte order) read from `voxels`, which must hold
/// exactly info.voxelCount() voxels. Converts to host byte order and rejects non-finite
/// floats. `sizeClaim` starts the message of a stream that ends early ("the header promises").
std::unique_ptr<VolumeSource> makeRawVoxelSource(std::unique_ptr<ByteStream> voxels,
                                                 const VolumeInfo& info, Endian endian,
                                                 const std::string& file,
                                                 const std::string& sizeClaim);

} // namespace bc::brickstore::detail
