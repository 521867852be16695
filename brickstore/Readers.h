#pragma once
// Every way a volume enters brickcast. Each function opens its input, validates the header
// (validateVolumeInfo plus format-specific checks) and returns a forward-only slice stream.
// All throw FormatError naming the file and field at fault; none allocates from a size it
// has not checked against the file.
#include "brickstore/VolumeSource.h"

#include <array>
#include <cstdint>
#include <functional>
#include <memory>
#include <optional>
#include <string>

namespace bc::brickstore {

enum class Endian { Little, Big };

/// What a headerless raw file cannot say about itself.
struct RawLayout {
    std::array<std::uint64_t, 3> dims{};
    VoxelType type = VoxelType::U8;
    std::array<double, 3> spacingMm{1, 1, 1};
    Endian endian = Endian::Little;
};

/// Raw voxels, x fastest; `path` ending in ".zst" is a zstd stream of the same bytes.
/// The (decompressed) size must be exactly dims*type bytes.
std::unique_ptr<VolumeSource> openRaw(const std::string& path, const RawLayout& layout);

/// NRRD with an attached (.nrrd) or detached (.nhdr) header; raw or gzip encoding. A detached
/// data file must lie in the header's folder: no absolute path, no "..", no symlink out.
std::unique_ptr<VolumeSource> openNrrd(const std::string& path);

/// NIfTI-1 (.nii, .nii.gz); scl_slope/scl_inter applied when they are not the identity.
std::unique_ptr<VolumeSource> openNifti(const std::string& path);

/// A folder holding one DICOM series: slices sorted along the slice normal, rescale
/// slope/intercept applied, spacing from the headers. Mixed series or missing slices throw.
/// GDCM (built with assertions by Debian) reads the headers and decodes the pixels in a
/// child process under ParserSandboxLimits, as openVdb does: a file that makes it abort,
/// crash or exceed a limit is a FormatError naming that file, under 1 kB. Call it before
/// the caller starts threads of its own (fork).
std::unique_ptr<VolumeSource> openDicomSeries(const std::string& folder);

/// A scalar grid (float, double, half on disk) of an OpenVDB file, by name (empty = the
/// only/first scalar grid). The volume is the grid's active bounding box; inactive voxels
/// read as the background value, so empty bricks compress to nothing and are not stored.
/// The file is parsed in a child process (OpenVDB's parser may hang or exhaust memory on a
/// hostile file) under ParserSandboxLimits; the child streams the slices back over a pipe, so
/// memory stays bounded. A child that fails, is killed or exceeds a limit is a FormatError
/// naming the file, under 1 kB. Call it before the caller starts threads of its own (fork).
std::unique_ptr<VolumeSource> openVdb(const std::string& path, const std::string& gridName);

/// Limits of the child process that parses an OpenVDB file or a DICOM series (one set for
/// both: what they bound, a hostile file, is the same).
struct ParserSandboxLimits {
    std::uint64_t addressSpaceBytes = 2ull << 30; ///< RLIMIT_AS of the child
    /// Wall clock of the parse: from fork until the volume is described, restarted at each
    /// file the parser reads (a DICOM series: every header, every slice's decoding).
    std::uint32_t parseSeconds = 10;
    std::uint32_t cpuSeconds = 600; ///< RLIMIT_CPU of the child, streaming included
};
/// Sets the limits of later openVdb and openDicomSeries calls (process-wide; the command
/// line's --parser-memory-mb and --parser-parse-s).
void setParserSandboxLimits(const ParserSandboxLimits& limits);
ParserSandboxLimits parserSandboxLimits();

/// The names these limits had when only OpenVDB was sandboxed.
using VdbSandboxLimits = ParserSandboxLimits;
inline void setVdbSandboxLimits(const VdbSandboxLimits& limits) {
    setParserSandboxLimits(limits);
}
inline VdbSandboxLimits vdbSandboxLimits() {
    return parserSandboxLimits();
}

enum class SynthKind { Phantom, Vessels, Checker };
/// Edge of one checkerboard cell of the Checker generator.
constexpr std::uint64_t kCheckerPeriodVoxels = 8;
std::optional<SynthKind> parseSynthKind(const std::string& name);

/// Deterministic generators, any size, produced slice by slice:
///  Phantom: dense CT-like head (u16); Vessels: sparse branching tree, 1-5% occupied (u8);
///  Checker: 3D checkerboard of kCheckerPeriodVoxels-voxel cells (u8), for aliasing tests.
std::unique_ptr<VolumeSource>
makeSynthetic(SynthKind kind, const std::array<std::uint64_t, 3>& dims, std::uint64_t seed);

/// Tiles the volume that `open` returns tiles[0] x tiles[1] x tiles[2] times. `open` is called
/// once per repetition along z (a reader streams forwards only).
std::unique_ptr<VolumeSource> makeMosaic(std::function<std::unique_ptr<VolumeSource>()> open,
                                         const std::array<std::uint64_t, 3>& tiles);

/// Everything the `ingest` command line can say about its input.
struct SourceSpec {
    std::string input; ///< path, folder, or "synth:KIND"
    std::optional<std::array<std::uint64_t, 3>> dims;
    std::optional<VoxelType> type;
    std::optional<std::array<double, 3>> spacingMm;
    Endian endian = Endian::Little;
    std::string gridName;
    std::uint64_t seed = 1;
    std::array<std::uint64_t, 3> mosaic{1, 1, 1};
};

/// Picks the reader from the input (folder -> DICOM, .vdb, .nii[.gz], .nrrd/.nhdr, synth:KIND,
/// anything else raw [.zst]) and wraps it in a mosaic when asked. Raw dims and type may come
/// from a name like "frog_500x470x136_uint8.raw" when not given.
std::unique_ptr<VolumeSource> openSource(const SourceSpec& spec);

} // namespace bc::brickstore
