// Picks the reader for an ingest input and wraps it in a mosaic when asked.
#include "brickstore/Error.h"
#include "brickstore/Readers.h"

#include <algorithm>
#include <cctype>
#include <filesystem>
#include <regex>

namespace bc::brickstore {
namespace {

bool endsWith(const std::string& s, const std::string& suffix) {
    return s.size() >= suffix.size() &&
           s.compare(s.size() - suffix.size(), suffix.size(), suffix) == 0;
}

/// "frog_500x470x136_uint8.raw" -> dims and type, the naming the shared data uses.
void layoutFromName(const std::string& path, RawLayout& layout, bool& haveDims, bool& haveType) {
    static const std::regex kPattern(
        R"((\d+)x(\d+)x(\d+)_(u?int8|u?int16|float32|u8|u16|i16|f32))");
    std::smatch m;
    std::string name = std::filesystem::path(path).filename().string();
    if (!std::regex_search(name, m, kPattern)) return;
    if (!haveDims) {
        layout.dims = {std::stoull(m[1]), std::stoull(m[2]), std::stoull(m[3])};
        haveDims = true;
    }
    if (!haveType) {
        std::string t = m[4];
        if (t == "int8") return; // not a stored type; let the caller say so
        if (auto vt = parseVoxelType(t)) {
            layout.type = *vt;
            haveType = true;
        }
    }
}

std::unique_ptr<VolumeSource> openRawFromSpec(const SourceSpec& spec) {
    RawLayout layout;
    bool haveDims = spec.dims.has_value(), haveType = spec.type.has_value();
    if (haveDims) layout.dims = *spec.dims;
    if (haveType) layout.type = *spec.type;
    layoutFromName(spec.input, layout, haveDims, haveType);
    if (!haveDims)
        throw FormatError(
            spec.input, "dims",
            "a raw file needs --dims X,Y,Z (or a name like vol_256x256x113_uint16.raw)");
    if (!haveType) throw FormatError(spec.input, "type", "a raw file needs --type u8|u16|i16|f32");
    if (spec.spacingMm) layout.spacingMm = *spec.spacingMm;
    layout.endian = spec.endian;
    return openRaw(spec.input, layout);
}

std::string lowerCase(std::string s) {
    std::transform(s.begin(), s.end(), s.begin(),
                   [](unsigned char c) { return char(std::tolower(c)); });
    return s;
}

enum class FolderKind { Zarr, Tiff, Dicom };

/// A folder is a Zarr array or OME-Zarr image when it holds Zarr metadata, a TIFF stack when
/// it holds .tif/.tiff files, and a DICOM series otherwise (DICOM files need no extension).
FolderKind folderKind(const std::string& folder) {
    const std::filesystem::path p(folder);
    std::error_code ec;
    for (const char* meta : {".zarray", ".zattrs", ".zgroup"})
        if (std::filesystem::exists(p / meta, ec)) return FolderKind::Zarr;
    for (const auto& entry : std::filesystem::directory_iterator(p, ec)) {
        const std::string name = lowerCase(entry.path().filename().string());
        if (endsWith(name, ".tif") || endsWith(name, ".tiff")) return FolderKind::Tiff;
    }
    return FolderKind::Dicom;
}

std::unique_ptr<VolumeSource> openOne(const SourceSpec& spec) {
    const std::string& in = spec.input;
    if (in.rfind("synth:", 0) == 0) {
        auto kind = parseSynthKind(in.substr(6));
        if (!kind)
            throw FormatError(
                in, "kind", "unknown generator; use synth:phantom, synth:vessels or synth:checker");
        if (!spec.dims) throw FormatError(in, "dims", "a generator needs --dims X,Y,Z");
        return makeSynthetic(*kind, *spec.dims, spec.seed);
    }
    std::error_code ec;
    if (std::filesystem::is_directory(in, ec)) {
        switch (folderKind(in)) {
        case FolderKind::Zarr:
            return openZarr(in, spec.level);
        case FolderKind::Tiff:
            return openTiff(in, spec.spacingMm);
        case FolderKind::Dicom:
            return openDicomSeries(in);
        }
    }
    if (!std::filesystem::exists(in, ec)) throw FormatError(in, "path", "no such file or folder");
    const std::string lower = lowerCase(in);
    if (endsWith(lower, ".vdb")) return openVdb(in, spec.gridName);
    if (endsWith(lower, ".nii") || endsWith(lower, ".nii.gz")) return openNifti(in);
    if (endsWith(lower, ".nrrd") || endsWith(lower, ".nhdr")) return openNrrd(in);
    if (endsWith(lower, ".tif") || endsWith(lower, ".tiff") || endsWith(lower, ".btf") ||
        endsWith(lower, ".tf8"))
        return openTiff(in, spec.spacingMm);
    if (endsWith(lower, ".h5") || endsWith(lower, ".hdf5") || endsWith(lower, ".hdf") ||
        endsWith(lower, ".he5") || endsWith(lower, ".ims"))
        return openHdf5(in, spec.dataset);
    if (endsWith(lower, ".mha") || endsWith(lower, ".mhd")) return openMetaImage(in);
    if (endsWith(lower, ".vti")) return openVti(in);
    return openRawFromSpec(spec);
}

} // namespace

std::optional<SynthKind> parseSynthKind(const std::string& name) {
    if (name == "phantom") return SynthKind::Phantom;
    if (name == "vessels") return SynthKind::Vessels;
    if (name == "checker") return SynthKind::Checker;
    return std::nullopt;
}

std::unique_ptr<VolumeSource> openSource(const SourceSpec& spec) {
    for (std::uint64_t t : spec.mosaic)
        if (t == 0) throw FormatError(spec.input, "mosaic", "tile counts must be at least 1");
    if (spec.mosaic == std::array<std::uint64_t, 3>{1, 1, 1}) return openOne(spec);
    return makeMosaic([spec] { return openOne(spec); }, spec.mosaic);
}

} // namespace bc::brickstore
