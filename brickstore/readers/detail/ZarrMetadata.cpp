// The metadata of a Zarr v2 array (.zarray) and of an OME-Zarr image (.zattrs "multiscales",
// NGFF 0.1 to 0.4), read with nlohmann::json and checked field by field: the reader allocates
// nothing from a size here before validateVolumeInfo and the chunk bound have passed.
#include "brickstore/readers/detail/ZarrMetadata.h"
#include "brickstore/Error.h"

#include <algorithm>
#include <cerrno>
#include <cmath>
#include <cstring>
#include <filesystem>
#include <fstream>
#include <limits>
#include <map>
#include <optional>
#include <sstream>

#include <blosc.h>
#include <nlohmann/json.hpp>

namespace bc::brickstore::detail {

namespace {

namespace fs = std::filesystem;
using Json = nlohmann::json;

/// Zarr metadata is a few hundred bytes; a larger file is not metadata.
constexpr std::uint64_t kMaxMetadataBytes = 1 << 20;
/// More axes than any NGFF image has (t, c, z, y, x).
constexpr std::size_t kMaxAxes = 16;

/// The last name of a folder's path, "dir/" included.
std::string folderName(const std::string& path) {
    const fs::path p = fs::path(path).lexically_normal();
    return (p.has_filename() ? p.filename() : p.parent_path().filename()).string();
}

Json readJson(const std::string& real, const std::string& file) {
    std::error_code ec;
    const std::uint64_t bytes = fs::file_size(real, ec);
    if (ec) throw FormatError(file, "path", "cannot read: " + ec.message());
    if (bytes > kMaxMetadataBytes)
        throw FormatError(file, "size",
                          std::to_string(bytes) + " bytes; Zarr metadata is under 1 MiB");
    std::ifstream in(real, std::ios::binary);
    std::ostringstream text;
    text << in.rdbuf();
    if (!in) throw FormatError(file, "path", std::string("cannot read: ") + std::strerror(errno));
    try {
        return Json::parse(text.str());
    } catch (const Json::exception& e) {
        throw FormatError(file, "json", std::string("not JSON: ") + e.what());
    }
}

const Json* member(const Json& object, const char* key) {
    if (!object.is_object()) return nullptr;
    auto it = object.find(key);
    return it == object.end() ? nullptr : &*it;
}

std::vector<std::uint64_t> parseExtents(const Json& meta, const char* key,
                                        const std::string& file) {
    const Json* v = member(meta, key);
    if (!v || !v->is_array()) throw FormatError(file, key, "missing or not a list of extents");
    if (v->size() < 3 || v->size() > kMaxAxes)
        throw FormatError(file, key,
                          std::to_string(v->size()) + " axes; brickcast reads 3D volumes (z, y, " +
                              "x), or more axes whose leading ones have one element");
    std::vector<std::uint64_t> out;
    for (const Json& e : *v) {
        if (!e.is_number_unsigned() || e.get<std::uint64_t>() == 0)
            throw FormatError(file, key, e.dump() + " is not a positive integer below 2^64");
        out.push_back(e.get<std::uint64_t>());
    }
    return out;
}

void parseDtype(const Json& meta, ZarrArray& a) {
    static const std::map<std::string, std::pair<VoxelType, Endian>> kTypes = {
        {"|u1", {VoxelType::U8, Endian::Little}}, {"<u2", {VoxelType::U16, Endian::Little}},
        {">u2", {VoxelType::U16, Endian::Big}},   {"<i2", {VoxelType::I16, Endian::Little}},
        {">i2", {VoxelType::I16, Endian::Big}},   {"<f4", {VoxelType::F32, Endian::Little}},
        {">f4", {VoxelType::F32, Endian::Big}}};
    const Json* v = member(meta, "dtype");
    const std::string name = v && v->is_string() ? v->get<std::string>() : "";
    auto it = kTypes.find(name);
    if (it == kTypes.end())
        throw FormatError(a.metaFile, "dtype",
                          (v ? v->dump() : std::string("missing")) +
                              " is not supported; brickcast reads |u1, <u2, >u2, <i2, >i2, " +
                              "<f4 and >f4");
    a.type = it->second.first;
    a.endian = it->second.second;
}

/// The fill value as one host-order voxel; null is 0. Floats must be finite (the readers
/// reject NaN and infinity, which would poison every min/max the store keeps).
void parseFill(const Json& meta, ZarrArray& a) {
    const Json* v = member(meta, "fill_value");
    if (!v || v->is_null()) return;
    auto refuse = [&](const std::string& why) {
        throw FormatError(a.metaFile, "fill_value", v->dump() + " " + why);
    };
    if (a.type == VoxelType::F32) {
        if (!v->is_number()) refuse("is not finite (or not a number); float volumes must be");
        const double d = v->get<double>();
        if (!std::isfinite(d) || std::abs(d) > std::numeric_limits<float>::max())
            refuse("does not fit a finite float");
        const float f = float(d);
        std::memcpy(a.fillValue.data(), &f, 4);
        return;
    }
    if (!v->is_number_integer()) refuse("is not an integer");
    const double lo = a.type == VoxelType::I16 ? -32768 : 0;
    const double hi = a.type == VoxelType::U8 ? 255 : a.type == VoxelType::U16 ? 65535 : 32767;
    const double d = v->get<double>();
    if (d < lo || d > hi) refuse("is out of the dtype's range");
    const std::int64_t i = v->get<std::int64_t>();
    if (a.type == VoxelType::U8) {
        a.fillValue[0] = std::byte(std::uint8_t(i));
    } else {
        const std::uint16_t u = std::uint16_t(std::int16_t(i));
        std::memcpy(a.fillValue.data(), &u, 2);
    }
}

bool bloscHas(const std::string& cname) {
    std::string list = blosc_list_compressors();
    std::stringstream in(list);
    for (std::string name; std::getline(in, name, ',');)
        if (name == cname) return true;
    return false;
}

/// numcodecs' config shapes: {"id": "zlib", "level": 1}, {"id": "blosc", "cname": "lz4", ...}.
void parseCompressor(const Json& meta, ZarrArray& a) {
    const Json* v = member(meta, "compressor");
    if (!v || v->is_null()) {
        a.codec = ZarrCodec::None;
        a.codecName = "uncompressed";
        return;
    }
    const Json* id = member(*v, "id");
    if (!id || !id->is_string())
        throw FormatError(a.metaFile, "compressor", v->dump() + " names no codec id");
    static const std::map<std::string, ZarrCodec> kCodecs = {{"zlib", ZarrCodec::Zlib},
                                                             {"gzip", ZarrCodec::Gzip},
                                                             {"zstd", ZarrCodec::Zstd},
                                                             {"blosc", ZarrCodec::Blosc}};
    const std::string name = id->get<std::string>();
    auto it = kCodecs.find(name);
    if (it == kCodecs.end())
        throw FormatError(a.metaFile, "compressor",
                          "'" + name + "' is not supported; brickcast decodes zlib, gzip, " +
                              "zstd and blosc chunks, or uncompressed ones");
    a.codec = it->second;
    a.codecName = name;
    if (a.codec != ZarrCodec::Blosc) return;
    const Json* cname = member(*v, "cname");
    if (!cname || !cname->is_string() || !bloscHas(cname->get<std::string>()))
        throw FormatError(a.metaFile, "compressor",
                          "blosc cname " + (cname ? cname->dump() : std::string("missing")) +
                              " is not one of this libblosc's: " + blosc_list_compressors());
    a.codecName += "/" + cname->get<std::string>();
}

void parseLayout(const Json& meta, ZarrArray& a) {
    const Json* format = member(meta, "zarr_format");
    if (!format || *format != 2)
        throw FormatError(a.metaFile, "zarr_format",
                          (format ? format->dump() : std::string("missing")) +
                              "; brickcast reads Zarr v2 arrays");
    const Json* order = member(meta, "order");
    if (!order || *order != "C")
        throw FormatError(a.metaFile, "order",
                          (order ? order->dump() : std::string("missing")) +
                              "; brickcast reads C-order chunks only");
    const Json* filters = member(meta, "filters");
    if (filters && !filters->is_null() && !(filters->is_array() && filters->empty()))
        throw FormatError(a.metaFile, "filters",
                          filters->dump() + "; brickcast reads arrays without filters");
    const Json* sep = member(meta, "dimension_separator");
    if (sep && *sep != "." && *sep != "/")
        throw FormatError(a.metaFile, "dimension_separator",
                          sep->dump() + " is neither \".\" nor \"/\"");
    a.separator = sep && *sep == "/" ? '/' : '.';
}

/// Leading axes must have one element; the chunk of a voxel must fit kZarrMaxChunkBytes.
void checkExtents(ZarrArray& a) {
    if (a.chunks.size() != a.shape.size())
        throw FormatError(a.metaFile, "chunks",
                          std::to_string(a.chunks.size()) + " chunk extents for " +
                              std::to_string(a.shape.size()) + " axes");
    for (std::size_t i = 0; i + 3 < a.shape.size(); ++i)
        if (a.shape[i] != 1)
            throw FormatError(a.metaFile, "shape",
                              "leading axis " + std::to_string(i) + " has " +
                                  std::to_string(a.shape[i]) +
                                  " elements; brickcast reads one time point and channel");
    std::uint64_t bytes = voxelBytes(a.type);
    for (std::uint64_t c : a.chunks)
        if (c > kZarrMaxChunkBytes || (bytes *= c) > kZarrMaxChunkBytes)
            throw FormatError(a.metaFile, "chunks",
                              "one chunk decodes to more than 1 GiB; brickcast decodes whole " +
                                  std::string("chunks and reads chunks up to 1 GiB"));
    a.chunkBytes = bytes;
}

/// The array in `relFolder` of the store at `root` (canonical); `displayFolder` is how errors
/// name that folder.
ZarrArray readArray(const std::string& root, const std::string& relFolder,
                    const std::string& displayFolder) {
    ZarrArray a;
    a.root = root;
    a.displayFolder = displayFolder;
    a.metaFile = (fs::path(displayFolder) / ".zarray").string();
    a.folder = resolveInside(root, relFolder, a.metaFile, "path");
    const std::string rel = (fs::path(relFolder) / ".zarray").lexically_normal().string();
    const Json meta = readJson(resolveInside(root, rel, a.metaFile, "path"), a.metaFile);
    if (!meta.is_object()) throw FormatError(a.metaFile, "json", "not a JSON object");
    parseLayout(meta, a);
    a.shape = parseExtents(meta, "shape", a.metaFile);
    a.chunks = parseExtents(meta, "chunks", a.metaFile);
    parseDtype(meta, a);
    parseCompressor(meta, a);
    parseFill(meta, a);
    checkExtents(a);
    return a;
}

/// Millimetres per unit of the NGFF space units (UDUNITS-2 names).
std::optional<double> millimetresPer(const std::string& unit) {
    static const std::map<std::string, double> kUnits = {
        {"angstrom", 1e-7},    {"attometer", 1e-15},  {"centimeter", 10},
        {"decimeter", 100},    {"exameter", 1e21},    {"femtometer", 1e-12},
        {"foot", 304.8},       {"gigameter", 1e12},   {"hectometer", 1e5},
        {"inch", 25.4},        {"kilometer", 1e6},    {"megameter", 1e9},
        {"meter", 1e3},        {"micrometer", 1e-3},  {"mile", 1609344},
        {"millimeter", 1},     {"nanometer", 1e-6},   {"parsec", 3.0856775814913673e19},
        {"petameter", 1e18},   {"picometer", 1e-9},   {"terameter", 1e15},
        {"yard", 914.4},       {"yoctometer", 1e-21}, {"yottameter", 1e27},
        {"zeptometer", 1e-18}, {"zettameter", 1e24}};
    auto it = kUnits.find(unit);
    if (it == kUnits.end()) return std::nullopt;
    return it->second;
}

/// Checks the axes (0.3: names; 0.4: objects with name and unit) against the array: as many
/// as it has, ending with z, y, x. Returns millimetres per unit along x, y, z (1: no unit).
std::array<double, 3> axesUnits(const Json& multiscale, const ZarrArray& a,
                                const std::string& file) {
    const Json* axes = member(multiscale, "axes");
    if (!axes) return {1, 1, 1}; // NGFF 0.1 and 0.2: the axes are implied (t, c, z, y, x)
    if (!axes->is_array() || axes->size() != a.shape.size())
        throw FormatError(file, "axes",
                          axes->dump() + " does not list one axis per array axis (" +
                              std::to_string(a.shape.size()) + ")");
    std::array<double, 3> mm{1, 1, 1};
    for (int k = 0; k < 3; ++k) {
        const Json& axis = (*axes)[a.shape.size() - 1 - k];
        const Json* name = axis.is_string() ? &axis : member(axis, "name");
        if (!name || *name != std::string(1, "xyz"[k]))
            throw FormatError(file, "axes", axes->dump() + " does not end with the axes z, y, x");
        const Json* unit = member(axis, "unit");
        if (!unit) continue;
        auto factor = unit->is_string() ? millimetresPer(unit->get<std::string>()) : std::nullopt;
        if (!factor)
            throw FormatError(file, "axes", "unit " + unit->dump() + " is not a length unit");
        mm[k] = *factor;
    }
    return mm;
}

/// The spatial part (x, y, z) of a transformation's vector, which has one entry per axis.
std::array<double, 3> spatial(const Json* v, const ZarrArray& a, const std::string& file,
                              const std::string& field) {
    if (!v || !v->is_array() || v->size() != a.shape.size())
        throw FormatError(file, field,
                          (v ? v->dump() : std::string("missing")) + " has not one number per " +
                              "axis (" + std::to_string(a.shape.size()) + ")");
    std::array<double, 3> out{};
    for (int k = 0; k < 3; ++k) {
        const Json& e = (*v)[a.shape.size() - 1 - k];
        if (!e.is_number()) throw FormatError(file, field, v->dump() + " is not all numbers");
        out[k] = e.get<double>();
    }
    return out;
}

/// Applies a list of coordinateTransformations (scale, translation, identity) in order.
void applyTransforms(const Json* list, const ZarrArray& a, const std::string& file,
                     const std::string& field, VolumeInfo& info) {
    if (!list) return;
    if (!list->is_array()) throw FormatError(file, field, "is not a list");
    for (const Json& t : *list) {
        const Json* type = member(t, "type");
        if (type && *type == "identity") continue;
        if (type && *type == "scale") {
            const auto s = spatial(member(t, "scale"), a, file, field);
            for (int k = 0; k < 3; ++k) {
                info.spacingMm[k] *= s[k];
                info.originMm[k] *= s[k];
            }
        } else if (type && *type == "translation") {
            const auto s = spatial(member(t, "translation"), a, file, field);
            for (int k = 0; k < 3; ++k)
                info.originMm[k] += s[k];
        } else {
            throw FormatError(file, field,
                              t.dump() + " is not a scale, translation or identity " +
                                  "transformation given inline");
        }
    }
}

ZarrImage readMultiscales(const std::string& root, const std::string& path, std::uint32_t level) {
    const std::string file = (fs::path(path) / ".zattrs").string();
    const Json attrs = readJson(resolveInside(root, ".zattrs", file, "path"), file);
    const Json* all = member(attrs, "multiscales");
    if (!all)
        throw FormatError(path, ".zarray",
                          "the folder holds no .zarray, and its .zattrs no OME-NGFF multiscales");
    if (!all->is_array() || all->empty() || !(*all)[0].is_object())
        throw FormatError(file, "multiscales", "is not a list of multiscale images");
    const Json& m = (*all)[0];
    const Json* datasets = member(m, "datasets");
    if (!datasets || !datasets->is_array() || datasets->empty())
        throw FormatError(file, "datasets", "missing, or not a list of levels");
    const std::size_t levels = datasets->size();
    if (level >= levels)
        throw FormatError(file, "level",
                          "level " + std::to_string(level) + " asked; the image has " +
                              std::to_string(levels) + " level" + (levels == 1 ? "" : "s") +
                              " (0.." + std::to_string(levels - 1) + ")");
    const Json& ds = (*datasets)[level];
    const std::string dsField = "datasets[" + std::to_string(level) + "]";
    const Json* rel = member(ds, "path");
    if (!rel || !rel->is_string()) throw FormatError(file, dsField + ".path", "missing");
    const std::string relPath = rel->get<std::string>();
    resolveInside(root, relPath, file, dsField + ".path");
    ZarrImage image;
    image.array = readArray(root, relPath, (fs::path(path) / relPath).string());
    const auto units = axesUnits(m, image.array, file);
    applyTransforms(member(ds, "coordinateTransformations"), image.array, file,
                    dsField + ".coordinateTransformations", image.info);
    applyTransforms(member(m, "coordinateTransformations"), image.array, file,
                    "coordinateTransformations", image.info);
    for (int k = 0; k < 3; ++k) {
        image.info.spacingMm[k] *= units[k];
        image.info.originMm[k] *= units[k];
        if (!std::isfinite(image.info.spacingMm[k]) || image.info.spacingMm[k] <= 0 ||
            !std::isfinite(image.info.originMm[k]))
            throw FormatError(file, dsField + ".coordinateTransformations",
                              std::string("scale or translation along ") + "xyz"[k] +
                                  " is not finite and positive");
    }
    image.info.description = "OME-Zarr " + folderName(path) + " level " + std::to_string(level) +
                             " of " + std::to_string(levels);
    return image;
}

/// Bytes of the regular files in the array's folder and below, counted until `enough`: what
/// the store holds of the array. Symlinks are not counted: one could name any file outside.
std::uint64_t arrayFileBytes(const ZarrArray& a, std::uint64_t enough) {
    std::uint64_t bytes = 0;
    std::error_code ec;
    fs::recursive_directory_iterator it(a.folder, fs::directory_options::skip_permission_denied,
                                        ec);
    for (; !ec && it != fs::recursive_directory_iterator() && bytes < enough; it.increment(ec)) {
        std::error_code statError;
        if (it->symlink_status(statError).type() == fs::file_type::regular)
            bytes += it->file_size(statError);
    }
    return bytes;
}

/// The work the array's header asks for, against the limits: its chunks' count, and its
/// voxels against the bytes of its files (a .zarray alone can declare a terabyte).
void checkBacked(const ZarrImage& image) {
    const ZarrArray& a = image.array;
    checkChunkCount(image.info, {a.chunkDim(0), a.chunkDim(1), a.chunkDim(2)}, a.metaFile,
                    "chunks");
    const std::uint64_t declared = image.info.voxelCount() * voxelBytes(a.type);
    if (declared <= kExpansionFreeBytes) return;
    const std::uint64_t enough = declared / inputLimits().maxExpansion + 1;
    checkInputHolds(image.info, arrayFileBytes(a, enough), "the array's files", a.metaFile,
                    "shape");
}

} // namespace

ZarrImage readZarrImage(const std::string& path, std::uint32_t level) {
    std::error_code ec;
    const std::string root = fs::canonical(path, ec).string();
    if (ec) throw FormatError(path, "path", "cannot resolve: " + ec.message());
    if (!fs::is_directory(root, ec)) throw FormatError(path, "path", "is not a folder");
    ZarrImage image;
    if (fs::exists(fs::path(root) / ".zarray", ec) ||
        fs::is_symlink(fs::symlink_status(fs::path(root) / ".zarray", ec))) {
        image.array = readArray(root, ".", path);
        if (level != 0)
            throw FormatError(image.array.metaFile, "level",
                              "level " + std::to_string(level) +
                                  " asked; a plain Zarr array has one level (0)");
        image.info.description = "Zarr " + folderName(path);
    } else {
        image = readMultiscales(root, path, level);
    }
    const ZarrArray& a = image.array;
    image.info.dims = {a.dim(0), a.dim(1), a.dim(2)};
    image.info.type = a.type;
    image.info.description += ", " + std::string(voxelTypeName(a.type)) + ", " + a.codecName;
    validateVolumeInfo(image.info, a.metaFile, "shape");
    checkBacked(image);
    return image;
}

} // namespace bc::brickstore::detail
