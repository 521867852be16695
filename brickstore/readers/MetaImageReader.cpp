// MetaImage volumes (ITK's MetaIO format): "Key = Value" header lines up to ElementDataFile,
// which is the last; the data follows the header (.mha, ElementDataFile = LOCAL) or lies in a
// file named there (.mhd), raw or one zlib stream (CompressedData). The header is parsed here,
// bounded in size; the data streams through detail/RawStream.h and detail/GzipStream.h, so
// memory stays at one input buffer (64 KiB of zlib input) and the caller's slices.
#include "brickstore/Error.h"
#include "brickstore/Readers.h"
#include "brickstore/detail/RegularFile.h"
#include "brickstore/readers/detail/FolderPath.h"
#include "brickstore/readers/detail/GzipStream.h"
#include "brickstore/readers/detail/HeaderFields.h"
#include "brickstore/readers/detail/RawStream.h"

#include <algorithm>
#include <array>
#include <cerrno>
#include <charconv>
#include <cmath>
#include <cstring>
#include <filesystem>
#include <fstream>
#include <limits>
#include <map>
#include <optional>
#include <vector>

namespace bc::brickstore {

namespace {

using detail::parseUnsigned;
using detail::trim;
using detail::words;

namespace fs = std::filesystem;

/// The header's fields by key, as written, and where the data of a LOCAL file starts.
struct HeaderText {
    std::map<std::string, std::string> fields;
    std::uint64_t dataOffsetBytes = 0; ///< first byte after the ElementDataFile line
    bool moreAfterDataFile = false;    ///< anything but white space follows that line
};

/// What the header says about the data, once interpreted.
struct MetaHeader {
    VolumeInfo info;
    Endian endian = Endian::Little;
    bool zlib = false;
    std::optional<std::uint64_t> compressedBytes; ///< CompressedDataSize
    std::optional<std::int64_t> headerSize;       ///< HeaderSize (-1: data at the file's end)
    std::string dataFile;                         ///< "LOCAL": data after the header
};

bool readLine(std::istream& in, std::string& line, std::uint64_t& offset, const std::string& path) {
    return detail::readHeaderLine(in, line, offset, path, "MetaImage", "ElementDataFile line");
}

/// Whether anything but white space follows in the (header) file, within the header limit.
bool hasMoreText(std::istream& in, std::uint64_t offset, const std::string& path) {
    std::string line;
    while (readLine(in, line, offset, path))
        if (!trim(line).empty()) return true;
    return false;
}

HeaderText readHeaderText(const std::string& path) {
    std::ifstream in(path, std::ios::binary);
    if (!in) throw FormatError(path, "path", std::string("cannot open: ") + std::strerror(errno));
    HeaderText text;
    std::string line;
    std::uint64_t offset = 0;
    for (int number = 1; readLine(in, line, offset, path); ++number) {
        if (trim(line).empty()) continue;
        std::size_t eq = line.find('=');
        if (eq == std::string::npos)
            throw FormatError(path, "header",
                              "line " + std::to_string(number) +
                                  " is not 'Key = Value'; not a MetaImage header");
        std::string key = trim(line.substr(0, eq));
        if (!text.fields.emplace(key, trim(line.substr(eq + 1))).second)
            throw FormatError(path, key, "field given twice");
        if (key != "ElementDataFile") continue;
        // LOCAL data follows at once; a separate header must end here.
        text.dataOffsetBytes = offset;
        text.moreAfterDataFile =
            trim(line.substr(eq + 1)) != "LOCAL" && hasMoreText(in, offset, path);
        return text;
    }
    throw FormatError(path, "ElementDataFile",
                      text.fields.empty() ? "file is empty; not a MetaImage header"
                                          : "required field is missing (it ends the header)");
}

const std::string* findField(const HeaderText& text, const std::string& key) {
    auto it = text.fields.find(key);
    return it == text.fields.end() ? nullptr : &it->second;
}

const std::string& requireField(const HeaderText& text, const std::string& key,
                                const std::string& path) {
    const std::string* value = findField(text, key);
    if (!value) throw FormatError(path, key, "required field is missing");
    return *value;
}

/// The first of `keys` the header gives (they are synonyms); nullopt when none. Synonyms
/// given with different values throw.
std::optional<std::pair<std::string, std::string>>
findSynonym(const HeaderText& text, const std::vector<std::string>& keys, const std::string& path) {
    std::optional<std::pair<std::string, std::string>> found;
    for (const std::string& key : keys) {
        const std::string* value = findField(text, key);
        if (!value) continue;
        if (found && found->second != *value)
            throw FormatError(
                path, key, "'" + *value + "' contradicts " + found->first + " = " + found->second);
        if (!found) found.emplace(key, *value);
    }
    return found;
}

/// Three finite numbers ("0.5 0.5 1.25").
std::array<double, 3> parseTriple(const std::string& s, const std::string& path,
                                  const std::string& field) {
    std::vector<std::string> parts = words(s);
    if (parts.size() != 3)
        throw FormatError(path, field,
                          "'" + s + "' needs 3 numbers, has " + std::to_string(parts.size()));
    std::array<double, 3> v{};
    for (int a = 0; a < 3; ++a) {
        const std::string& w = parts[a];
        auto [end, ec] = std::from_chars(w.data(), w.data() + w.size(), v[a]);
        if (ec != std::errc() || end != w.data() + w.size() || !std::isfinite(v[a]))
            throw FormatError(path, field, "'" + w + "' is not a finite number");
    }
    return v;
}

bool parseBool(const std::string& s, const std::string& path, const std::string& field) {
    if (s == "True" || s == "true" || s == "TRUE" || s == "T" || s == "1") return true;
    if (s == "False" || s == "false" || s == "FALSE" || s == "F" || s == "0") return false;
    throw FormatError(path, field, "'" + s + "' is neither True nor False");
}

VoxelType parseElementType(const std::string& name, const std::string& path) {
    static const std::map<std::string, VoxelType> kStored = {{"MET_UCHAR", VoxelType::U8},
                                                             {"MET_USHORT", VoxelType::U16},
                                                             {"MET_SHORT", VoxelType::I16},
                                                             {"MET_FLOAT", VoxelType::F32}};
    if (auto it = kStored.find(name); it != kStored.end()) return it->second;
    if (name.rfind("MET_", 0) == 0)
        throw FormatError(path, "ElementType",
                          "'" + name + "' is not supported; brickcast reads MET_UCHAR, " +
                              "MET_USHORT, MET_SHORT and MET_FLOAT");
    throw FormatError(path, "ElementType", "unknown element type '" + name + "'");
}

void checkObject(const HeaderText& text, const std::string& path) {
    const std::string& object = requireField(text, "ObjectType", path);
    if (object != "Image")
        throw FormatError(path, "ObjectType", "is '" + object + "'; brickcast reads Image only");
    const std::string& ndims = requireField(text, "NDims", path);
    if (ndims != "3")
        throw FormatError(path, "NDims", "is " + ndims + "; brickcast reads 3-D volumes only");
    if (const std::string* channels = findField(text, "ElementNumberOfChannels"))
        if (*channels != "1")
            throw FormatError(path, "ElementNumberOfChannels",
                              "is " + *channels + "; brickcast reads one channel (scalars) only");
    if (const std::string* binary = findField(text, "BinaryData"))
        if (!parseBool(*binary, path, "BinaryData"))
            throw FormatError(path, "BinaryData", "is False (ASCII data); only binary is read");
}

std::array<std::uint64_t, 3> parseDims(const HeaderText& text, const std::string& path) {
    std::vector<std::string> sizes = words(requireField(text, "DimSize", path));
    if (sizes.size() != 3)
        throw FormatError(path, "DimSize", "needs 3 sizes, has " + std::to_string(sizes.size()));
    return {parseUnsigned(sizes[0], path, "DimSize"), parseUnsigned(sizes[1], path, "DimSize"),
            parseUnsigned(sizes[2], path, "DimSize")};
}

/// ElementSpacing (the distance between voxel centres), else ElementSize; 1 mm when neither.
std::array<double, 3> parseSpacing(const HeaderText& text, const std::string& path) {
    for (const char* key : {"ElementSpacing", "ElementSize"}) {
        const std::string* value = findField(text, key);
        if (!value) continue;
        std::array<double, 3> spacing = parseTriple(*value, path, key);
        for (double s : spacing)
            if (s <= 0) throw FormatError(path, key, "'" + *value + "': spacing must be positive");
        return spacing;
    }
    return {1, 1, 1};
}

Endian parseEndian(const HeaderText& text, const std::string& path) {
    auto msb = findSynonym(text, {"BinaryDataByteOrderMSB", "ElementByteOrderMSB"}, path);
    return msb && parseBool(msb->second, path, msb->first) ? Endian::Big : Endian::Little;
}

void parseCompression(const HeaderText& text, MetaHeader& h, const std::string& path) {
    if (const std::string* compressed = findField(text, "CompressedData"))
        h.zlib = parseBool(*compressed, path, "CompressedData");
    if (const std::string* size = findField(text, "CompressedDataSize")) {
        if (!h.zlib)
            throw FormatError(path, "CompressedDataSize", "is given for uncompressed data");
        h.compressedBytes = parseUnsigned(*size, path, "CompressedDataSize");
    }
}

void parseHeaderSize(const HeaderText& text, MetaHeader& h, const std::string& path) {
    const std::string* size = findField(text, "HeaderSize");
    if (!size) return;
    if (*size == "-1") {
        if (h.zlib && !h.compressedBytes)
            throw FormatError(path, "HeaderSize",
                              "-1 (data at the file's end) needs CompressedDataSize "
                              "for compressed data");
        h.headerSize = -1;
        return;
    }
    std::uint64_t bytes = parseUnsigned(*size, path, "HeaderSize");
    if (bytes > std::uint64_t(std::numeric_limits<std::int64_t>::max()))
        throw FormatError(path, "HeaderSize", "'" + *size + "' is too large");
    h.headerSize = std::int64_t(bytes);
}

MetaHeader interpret(const HeaderText& text, const std::string& path) {
    checkObject(text, path);
    MetaHeader h;
    h.info.dims = parseDims(text, path);
    h.info.type = parseElementType(requireField(text, "ElementType", path), path);
    h.info.spacingMm = parseSpacing(text, path);
    if (auto origin = findSynonym(text, {"Offset", "Origin", "Position"}, path))
        h.info.originMm = parseTriple(origin->second, path, origin->first);
    h.endian = parseEndian(text, path);
    parseCompression(text, h, path);
    parseHeaderSize(text, h, path);
    h.dataFile = requireField(text, "ElementDataFile", path);
    if (h.dataFile.empty()) throw FormatError(path, "ElementDataFile", "is empty");
    if (h.dataFile == "LOCAL" && h.headerSize && *h.headerSize != 0)
        throw FormatError(path, "HeaderSize",
                          "applies to a separate data file, not to ElementDataFile = LOCAL");
    return h;
}

/// The data file named by the header, which must lie in the header's folder (a header from an
/// untrusted upload must not make the server read /etc/shadow), as NRRD's detached data must.
std::string resolveDataFile(const std::string& headerPath, const std::string& name) {
    const std::vector<std::string> parts = words(name);
    if (parts[0] == "LIST" || name.find('%') != std::string::npos)
        throw FormatError(headerPath, "ElementDataFile",
                          "'" + name + "': lists and patterns of data files (one file per " +
                              "slice) are not supported; give one file");
    return detail::resolveInFolder(headerPath, name, "ElementDataFile");
}

std::string describeMetaImage(const std::string& path, const MetaHeader& h) {
    return "MetaImage " + fs::path(path).filename().string() + ", " +
           std::string(voxelTypeName(h.info.type)) + (h.zlib ? ", zlib" : ", raw") +
           (h.dataFile == "LOCAL" ? "" : ", data in " + h.dataFile);
}

/// Where the data starts in `dataPath`, from HeaderSize (or right after a LOCAL header).
std::uint64_t dataOffset(const MetaHeader& h, const HeaderText& text, std::uint64_t fileBytes,
                         std::uint64_t payloadBytes, const std::string& path,
                         const std::string& dataPath) {
    if (h.dataFile == "LOCAL") return text.dataOffsetBytes;
    if (!h.headerSize) return 0;
    if (*h.headerSize >= 0) return std::uint64_t(*h.headerSize);
    if (payloadBytes > fileBytes)
        throw FormatError(dataPath, "DimSize",
                          "header " + fs::path(path).filename().string() + " promises " +
                              std::to_string(payloadBytes) + " bytes at the end of the file, " +
                              "which holds " + std::to_string(fileBytes));
    return fileBytes - payloadBytes;
}

} // namespace

std::unique_ptr<VolumeSource> openMetaImage(const std::string& path) {
    detail::requireRegularFile(path);
    HeaderText text = readHeaderText(path);
    MetaHeader h = interpret(text, path);
    h.info.description = describeMetaImage(path, h);
    validateVolumeInfo(h.info, path, "DimSize");
    const std::string dataPath = h.dataFile == "LOCAL" ? path : resolveDataFile(path, h.dataFile);
    if (text.moreAfterDataFile)
        throw FormatError(path, "ElementDataFile",
                          "must be the last field; the header goes on after it");
    const std::uint64_t expected = h.info.voxelCount() * voxelBytes(h.info.type);
    const std::uint64_t fileBytes = detail::fileBytes(dataPath);
    const std::uint64_t offset =
        dataOffset(h, text, fileBytes, h.compressedBytes.value_or(expected), path, dataPath);
    const std::uint64_t held = fileBytes > offset ? fileBytes - offset : 0;
    const std::string claim = "header " + fs::path(path).filename().string() + " promises";
    if (h.zlib && h.compressedBytes && held != *h.compressedBytes)
        throw FormatError(path, "CompressedDataSize",
                          "is " + std::to_string(*h.compressedBytes) + " bytes, but " +
                              fs::path(dataPath).filename().string() + " holds " +
                              std::to_string(held) + " bytes of data");
    auto data = detail::openFileStream(dataPath, offset);
    if (h.zlib) {
        checkCompressedPayload(h.info, expected, held, "zlib", kMaxGzipRatio, dataPath, "DimSize");
        return detail::makeRawVoxelSource(detail::openGzipStream(std::move(data), dataPath), h.info,
                                          h.endian, dataPath, claim);
    }
    if (held != expected)
        throw FormatError(dataPath, "DimSize",
                          claim + " " + std::to_string(expected) + " bytes (DimSize " +
                              dimsText(h.info.dims) + "), file holds " + std::to_string(held));
    return detail::makeRawVoxelSource(std::move(data), h.info, h.endian, dataPath, claim);
}

} // namespace bc::brickstore
