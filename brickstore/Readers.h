#pragma once
// Every way a volume enters brickcast. Each function opens its input, validates the header
// (validateVolumeInfo plus format-specific checks) and returns a forward-only slice stream.
// All throw FormatError naming the file and field at fault; none allocates from a size it
// has not checked against the file, nor takes on more work than inputLimits() lets a header
// ask for (VolumeSource.h: voxels against the bytes that back them, chunk counts). A path that
// is not a regular file (a FIFO, whose open would wait for a writer) is refused unopened.
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

/// A TIFF volume: a folder of one-slice files (.tif/.tiff, natural sort: "s2" before "s10",
/// each file's first page a slice) or one multi-page classic or BigTIFF file (each page a
/// z-slice). 8/16-bit unsigned, 16-bit signed and 32-bit float greyscale, strips or tiles,
/// uncompressed, LZW, deflate or zstd, with predictors (libtiff decodes). Spacing from the
/// resolution tags (x, y; z from an ImageJ "spacing=" description, in its "unit=") unless
/// `spacingMm` is given. Every page must have the first page's size and type; ImageJ
/// hyperstacks of several channels or frames are refused. libtiff runs in the parser sandbox,
/// as GDCM does; its own message ends the FormatError. Call it before starting threads (fork).
std::unique_ptr<VolumeSource> openTiff(const std::string& path,
                                       const std::optional<std::array<double, 3>>& spacingMm);

/// A Zarr v2 array (a folder with .zarray), or an OME-Zarr image (a folder whose .zattrs holds
/// NGFF 0.1-0.4 "multiscales": `level` picks the dataset, 0 the finest; spacing and origin from
/// its scale and translation, converted to mm). dtypes |u1, <u2/>u2, <i2/>i2, <f4/>f4; chunks in
/// C order, 3D (or 5D/4D arrays whose leading axes have one element), no filters, compressors
/// zlib, gzip, zstd, blosc or none; a missing chunk reads as the fill value. A dataset path,
/// .zarray or chunk that leads outside the folder throws. Chunks are read a z-row of chunks at
/// a time (at most 256 MiB of slices held; a deeper row is decoded again per read), so a store
/// larger than memory ingests.
std::unique_ptr<VolumeSource> openZarr(const std::string& path, std::uint32_t level);

/// A named 3D dataset of an HDF5 file (C order [z][y][x]; contiguous, compact or chunked with
/// filters this libhdf5 decodes, plugins included): u8, u16, i16, f32 in either byte order, i8
/// and f16 widened to i16 and f32. Spacing from its "element_size_um" attribute (z, y, x in
/// micrometres; ilastik, Fiji) when present, else 1 mm. An empty or missing `dataset` is a
/// FormatError listing the file's 3D datasets. External links, external storage and virtual
/// datasets (voxels in other files) are refused. Parsed in the parser sandbox (libhdf5 on a
/// hostile file), as openVdb is: call it before the caller starts threads of its own (fork).
std::unique_ptr<VolumeSource> openHdf5(const std::string& path, const std::string& dataset);

/// MetaImage: .mha (header and data in one file, ElementDataFile = LOCAL) or .mhd (data in
/// ElementDataFile, which must lie in the header's folder, as NRRD's detached data must; lists
/// and %d patterns of files are refused); MET_UCHAR, MET_USHORT, MET_SHORT or MET_FLOAT, one
/// channel, either byte order; raw, or one zlib stream (CompressedData); HeaderSize honoured.
std::unique_ptr<VolumeSource> openMetaImage(const std::string& path);

/// VTK XML image data (.vti): one piece covering the WholeExtent, one scalar point-data array
/// (the Scalars one, else the only one) of UInt8, UInt16, Int16 or Float32; appended (raw or
/// base64) or inline base64 data, whole or in vtkZLibDataCompressor blocks, UInt32 or UInt64
/// headers, either byte order; a Direction other than the identity is refused. The markup is
/// parsed by expat under a 1 MiB cap; the data then stream, block by block.
std::unique_ptr<VolumeSource> openVti(const std::string& path);

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
    std::string dataset;     ///< HDF5: the dataset's path in the file
    std::uint32_t level = 0; ///< OME-Zarr: the multiscale level (0: the finest)
    std::uint64_t seed = 1;
    std::array<std::uint64_t, 3> mosaic{1, 1, 1};
};

/// Picks the reader from the input and wraps it in a mosaic when asked: a folder is a Zarr
/// array or OME-Zarr image (it holds .zarray, .zattrs or .zgroup), a TIFF stack (it holds .tif
/// or .tiff files) or else a DICOM series; files by extension, any case: .vdb, .nii[.gz],
/// .nrrd/.nhdr, .tif/.tiff/.btf/.tf8, .h5/.hdf5/.hdf/.he5/.ims, .mha/.mhd, .vti; synth:KIND;
/// anything else raw [.zst]. Raw dims and type may come from a name like
/// "frog_500x470x136_uint8.raw" when not given.
std::unique_ptr<VolumeSource> openSource(const SourceSpec& spec);

} // namespace bc::brickstore
