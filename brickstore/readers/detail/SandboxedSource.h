#pragma once
// A reader run in a forked child process under resource limits, for parsers that may hang,
// exhaust memory or abort on a hostile file (OpenVDB; GDCM, which Debian builds with
// assertions). The child lowers RLIMIT_AS and RLIMIT_CPU, arms an alarm while it parses, opens
// the volume with the caller's opener and streams its description and then slabs of slices
// over a pipe; the parent side is the VolumeSource ingest sees. Whatever ends the child early
// (an exception, an abort or crash, a limit) becomes one FormatError naming the file, under
// 1 kB. The child's stderr goes to a file of its own (a sealed 1 MiB memfd), not the user's:
// the error of a child that died ends with the last 300 characters it printed (GDCM's
// assertion text), escaped into one line.
//
// Why fork is safe here: the child only runs code that the parent never started (the parser's
// library is initialized in the child), glibc resets its malloc locks across fork, and the
// readers are opened before ingest starts its workers (a mosaic reopens its input while they
// run: its child still needs only malloc and the parser's own state); the child leaves with
// _exit, running no parent destructors.
#include "brickstore/Error.h"
#include "brickstore/Readers.h"
#include "brickstore/VolumeSource.h"

#include <cstdint>
#include <functional>
#include <memory>
#include <span>
#include <string>
#include <vector>

namespace bc::brickstore::detail {

/// Called by the parser, in the child, before it reads a file (a header, a slice's pixels):
/// it restarts the parse alarm, and the parent names that file if the child then dies.
using ReadingFile = std::function<void(const std::string& path)>;

/// Opens the volume in the child; `reading` stays valid for the source's whole life there.
using SandboxedOpener = std::function<std::unique_ptr<VolumeSource>(const ReadingFile& reading)>;

/// How the sandbox names the parser in its errors, and the files the parent may read itself.
struct SandboxedParser {
    std::string path;       ///< the file or folder the errors name when no file was reported
    std::string parserName; ///< "OpenVDB", "DICOM"
    std::string alarmWords; ///< what parseSeconds bounds, as errors say it: "to parse"
    /// The files a SliceLocator's extents may name, by index, listed by the parent before the
    /// fork (a TIFF, or a TIFF folder's slices). Empty: the child must send every byte.
    std::vector<std::string> directFiles;
};

/// A run of a slice's bytes as they lie in one of SandboxedParser::directFiles, already as
/// ingest stores them (uncompressed, host byte order, x fastest).
struct FileExtent {
    std::uint32_t file = 0; ///< index into directFiles
    std::uint64_t offset = 0;
    std::uint64_t bytes = 0;
};

/// What a sandboxed source may also be (the TIFF reader): one that can say where a slice's
/// bytes lie instead of reading them. Then the child sends the parent a map of the slice
/// (a few bytes) and the parent reads its voxels itself, straight into the ingest's buffer:
/// no copy through the child and the pipe. The parser still parses every header in the child;
/// the parent trusts none of it beyond "read these bytes of a file the user named", checks
/// every extent against that file and the volume's size, and checks float voxels are finite.
/// The child uses this interface in place of VolumeSource::readSlices once it finds it.
class SliceLocator {
  public:
    virtual ~SliceLocator() = default;
    /// Appends the extents that hold slice `z` (z counts up from 0, each once; the last extent
    /// in `out` grows where the slice's bytes continue it) and returns true; false when the slice
    /// must be decoded (compressed, tiled, byte-swapped), which decodeSlice(z) then does. @throw
    /// FormatError as readSlices would.
    virtual bool locateSlice(std::uint64_t z, std::vector<FileExtent>& out) = 0;
    /// Decodes slice `z`, which locateSlice has just refused, into `out` (one slice).
    virtual void decodeSlice(std::uint64_t z, std::span<std::byte> out) = 0;
};

/// Forks a child that runs `open` under `limits` and returns the parent's side, with the
/// volume's description already received. A FormatError thrown in the child keeps its file
/// and field; any other end names `parser.path` (or the file last reported through
/// ReadingFile) with field "file". The alarm runs from the fork until `open` returns and
/// again during each ReadingFile call's file, never while the child waits on the pipe.
/// Call it before starting threads of your own where you can (fork copies only the calling
/// thread; see the header comment).
/// @throw FormatError when the child cannot be started or ends before the description;
/// FormatError(parser.path, "path") unforked when it is neither a folder nor a regular file;
/// FormatError(parser.path, "dims") when the volume declares more than the file, or the
/// folder's files, hold (checkInputHolds).
std::unique_ptr<VolumeSource> openSandboxed(const SandboxedParser& parser,
                                            const ParserSandboxLimits& limits,
                                            SandboxedOpener open);

/// How a sandboxed parser's child ended, for callers (the fuzz harness) that must tell a
/// contained abort from a finding. Thrown as the FormatError of a child that ended early.
class ParserDied : public FormatError {
  public:
    ParserDied(const std::string& file, const std::string& why, int signal, int exitStatus)
        : FormatError(file, "file", why), mSignal(signal), mExitStatus(exitStatus) {}
    /// The signal that ended the child (SIGABRT for a failed assertion), 0 when it exited.
    int signal() const { return mSignal; }
    /// Its exit status when it exited (a sanitizer's report exits with 1), else -1.
    int exitStatus() const { return mExitStatus; }

  private:
    int mSignal;
    int mExitStatus;
};

} // namespace bc::brickstore::detail
