// NRRD volumes (teem's format): a text header, attached (.nrrd, data after the blank line) or
// detached (.nhdr naming a data file beside it), raw or gzip data. The header is parsed here,
// bounded in size; the data streams through detail/RawStream.h and detail/GzipStream.h.
#include "brickstore/Error.h"
#include "brickstore/Readers.h"
#include "brickstore/detail/RegularFile.h"
#include "brickstore/readers/detail/FolderPath.h"
#include "brickstore/readers/detail/GzipStream.h"
#include "brickstore/readers/detail/HeaderFields.h"
#include "brickstore/readers/detail/RawStream.h"

#include <algorithm>
#include <cerrno>
#include <charconv>
#include <climits>
#include <cmath>
#include <cstring>
#include <filesystem>
#include <fstream>
#include <map>
#include <new>
#include <vector>

namespace bc::brickstore {

namespace {

using detail::parseDouble;
using detail::parseUnsigned;
using detail::trim;
using detail::words;

namespace fs = std::filesystem;

/// The header's fields by name, aliases folded ("datafile" -> "data file").
struct HeaderText {
    std::map<std::string, std::string> fields;
    bool endsWithBlankLine = false;    ///< false: the header ran to the end of its file
    std::uint64_t dataOffsetBytes = 0; ///< first byte after the blank line
};

/// What the header says about the data, once interpreted.
struct NrrdHeader {
    VolumeInfo info;
    Endian endian = Endian::Little;
    bool gzip = false;
    std::string dataFile; ///< empty: data attached
    std::uint64_t lineSkip = 0;
};

std::string canonicalKey(const std::string& key) {
    static const std::map<std::string, std::string> kAliases = {{"datafile", "data file"},
                                                                {"lineskip", "line skip"},
                                                                {"byteskip", "byte skip"},
                                                                {"centerings", "centers"}};
    auto it = kAliases.find(key);
    return it == kAliases.end() ? key : it->second;
}

bool readLine(std::istream& in, std::string& line, std::uint64_t& offset, const std::string& path) {
    return detail::readHeaderLine(in, line, offset, path, "NRRD", "end of header (a blank line)");
}

void checkMagic(const std::string& line, const std::string& path) {
    bool ok =
        line.size() == 8 && line.compare(0, 7, "NRRD000") == 0 && line[7] >= '1' && line[7] <= '5';
    if (!ok)
        throw FormatError(path, "magic",
                          "file does not start with NRRD0001..NRRD0005; not a NRRD file");
}

HeaderText readHeaderText(const std::string& path) {
    std::ifstream in(path, std::ios::binary);
    if (!in) throw FormatError(path, "path", std::string("cannot open: ") + std::strerror(errno));
    HeaderText text;
    std::string line;
    std::uint64_t offset = 0;
    if (!readLine(in, line, offset, path)) throw FormatError(path, "magic", "file is empty");
    checkMagic(trim(line), path);
    for (int number = 2; readLine(in, line, offset, path); ++number) {
        if (!line.empty() && line.back() == '\r') line.pop_back();
        if (line.empty()) {
            text.endsWithBlankLine = true;
            text.dataOffsetBytes = offset;
            break;
        }
        if (line[0] == '#') continue;
        std::size_t colon = line.find(':');
        if (colon == std::string::npos)
            throw FormatError(path, "header",
                              "line " + std::to_string(number) +
                                  " is neither a field, a comment nor a key/value pair");
        if (colon + 1 < line.size() && line[colon + 1] == '=') continue; // key:=value, not ours
        std::string key = canonicalKey(trim(line.substr(0, colon)));
        if (!text.fields.emplace(key, trim(line.substr(colon + 1))).second)
            throw FormatError(path, key, "field given twice");
    }
    return text;
}

/// "(1.5,0,-2)" -> {1.5, 0, -2}.
std::vector<double> parseVector(const std::string& s, const std::string& path,
                                const std::string& field) {
    if (s.size() < 2 || s.front() != '(' || s.back() != ')')
        throw FormatError(path, field, "'" + s + "' is not a vector like (1,0,0)");
    std::vector<double> v;
    std::string inner = s.substr(1, s.size() - 2);
    for (std::size_t b = 0, e; b <= inner.size(); b = e + 1) {
        e = std::min(inner.find(',', b), inner.size());
        v.push_back(parseDouble(trim(inner.substr(b, e - b)), path, field));
    }
    return v;
}

/// Splits "(a,b,c) (d,e,f) none" into its vectors and words; spaces inside "( )" are allowed.
std::vector<std::string> vectorTokens(const std::string& s) {
    std::vector<std::string> out;
    for (std::size_t i = s.find_first_not_of(" \t"); i != std::string::npos;
         i = s.find_first_not_of(" \t", i)) {
        std::size_t e = s[i] == '(' ? s.find(')', i) : s.find_first_of(" \t", i);
        e = e == std::string::npos ? s.size() : e + (s[i] == '(' ? 1 : 0);
        out.push_back(s.substr(i, e - i));
        i = e;
    }
    return out;
}

VoxelType parseType(const std::string& name, const std::string& path) {
    static const std::map<std::string, VoxelType> kStored = {{"uchar", VoxelType::U8},
                                                             {"unsigned char", VoxelType::U8},
                                                             {"uint8", VoxelType::U8},
                                                             {"uint8_t", VoxelType::U8},
                                                             {"short", VoxelType::I16},
                                                             {"short int", VoxelType::I16},
                                                             {"signed short", VoxelType::I16},
                                                             {"signed short int", VoxelType::I16},
                                                             {"int16", VoxelType::I16},
                                                             {"int16_t", VoxelType::I16},
                                                             {"ushort", VoxelType::U16},
                                                             {"unsigned short", VoxelType::U16},
                                                             {"unsigned short int", VoxelType::U16},
                                                             {"uint16", VoxelType::U16},
                                                             {"uint16_t", VoxelType::U16},
                                                             {"float", VoxelType::F32}};
    static const char* kKnownOthers[] = {"signed char",
                                         "int8",
                                         "int8_t",
                                         "int",
                                         "signed int",
                                         "int32",
                                         "int32_t",
                                         "uint",
                                         "unsigned int",
                                         "uint32",
                                         "uint32_t",
                                         "longlong",
                                         "long long",
                                         "long long int",
                                         "signed long long",
                                         "signed long long int",
                                         "int64",
                                         "int64_t",
                                         "ulonglong",
                                         "unsigned long long",
                                         "unsigned long long int",
                                         "uint64",
                                         "uint64_t",
                                         "double",
                                         "block"};
    if (auto it = kStored.find(name); it != kStored.end()) return it->second;
    for (const char* other : kKnownOthers)
        if (name == other)
            throw FormatError(path, "type",
                              "'" + name + "' is not supported; brickcast reads " +
                                  "uchar, short, ushort and float");
    throw FormatError(path, "type", "unknown type '" + name + "'");
}

const std::string& requireField(const HeaderText& text, const std::string& key,
                                const std::string& path) {
    auto it = text.fields.find(key);
    if (it == text.fields.end()) throw FormatError(path, key, "required field is missing");
    return it->second;
}

const std::string* findField(const HeaderText& text, const std::string& key) {
    auto it = text.fields.find(key);
    return it == text.fields.end() ? nullptr : &it->second;
}

std::array<std::uint64_t, 3> parseSizes(const HeaderText& text, const std::string& path) {
    const std::string& dimension = requireField(text, "dimension", path);
    if (dimension != "3")
        throw FormatError(path, "dimension",
                          "is " + dimension + "; brickcast reads 3-D volumes only");
    std::vector<std::string> sizes = words(requireField(text, "sizes", path));
    if (sizes.size() != 3)
        throw FormatError(path, "sizes", "needs 3 sizes, has " + std::to_string(sizes.size()));
    return {parseUnsigned(sizes[0], path, "sizes"), parseUnsigned(sizes[1], path, "sizes"),
            parseUnsigned(sizes[2], path, "sizes")};
}

/// Spacing from "space directions" (vector lengths) or "spacings"; 1 mm when neither is given.
std::array<double, 3> parseSpacing(const HeaderText& text, const std::string& path) {
    std::array<double, 3> spacing{1, 1, 1};
    const std::string* directions = findField(text, "space directions");
    const std::string* spacings = findField(text, "spacings");
    if (!directions && !spacings) return spacing;
    const std::string field = directions ? "space directions" : "spacings";
    std::vector<std::string> tokens = directions ? vectorTokens(*directions) : words(*spacings);
    if (tokens.size() != 3)
        throw FormatError(path, field, "needs 3 entries, has " + std::to_string(tokens.size()));
    for (int a = 0; a < 3; ++a) {
        if (directions && tokens[a] == "none")
            throw FormatError(path, field,
                              "axis " + std::to_string(a) +
                                  " is 'none'; all 3 axes must be spatial");
        if (directions) {
            double sum = 0;
            for (double c : parseVector(tokens[a], path, field))
                sum += c * c;
            spacing[a] = std::sqrt(sum);
        } else {
            spacing[a] = parseDouble(tokens[a], path, field);
        }
        if (!std::isfinite(spacing[a]) || spacing[a] <= 0)
            throw FormatError(path, field,
                              "spacing of axis " + std::to_string(a) + " is " +
                                  std::to_string(spacing[a]) + "; it must be finite and positive");
    }
    return spacing;
}

std::array<double, 3> parseOrigin(const HeaderText& text, const std::string& path) {
    const std::string* origin = findField(text, "space origin");
    if (!origin) return {0, 0, 0};
    std::vector<double> v = parseVector(*origin, path, "space origin");
    if (v.size() != 3 ||
        !std::all_of(v.begin(), v.end(), [](double c) { return std::isfinite(c); }))
        throw FormatError(path, "space origin", "'" + *origin + "' is not 3 finite numbers");
    return {v[0], v[1], v[2]};
}

bool parseGzip(const HeaderText& text, const std::string& path) {
    const std::string& encoding = requireField(text, "encoding", path);
    if (encoding == "raw") return false;
    if (encoding == "gzip" || encoding == "gz") return true;
    throw FormatError(path, "encoding", "'" + encoding + "' is not supported; use raw or gzip");
}

Endian parseEndian(const HeaderText& text, VoxelType type, const std::string& path) {
    const std::string* endian = findField(text, "endian");
    if (!endian) {
        if (voxelBytes(type) > 1)
            throw FormatError(path, "endian", "required for a multi-byte type (little or big)");
        return Endian::Little;
    }
    if (*endian == "little") return Endian::Little;
    if (*endian == "big") return Endian::Big;
    throw FormatError(path, "endian", "'" + *endian + "' is neither little nor big");
}

void checkByteSkip(const HeaderText& text, const std::string& path) {
    const std::string* skip = findField(text, "byte skip");
    if (skip && *skip != "0")
        throw FormatError(path, "byte skip", "'" + *skip + "' is not supported; only 0 is");
}

NrrdHeader interpret(const HeaderText& text, const std::string& path) {
    NrrdHeader h;
    h.info.type = parseType(requireField(text, "type", path), path);
    h.info.dims = parseSizes(text, path);
    h.info.spacingMm = parseSpacing(text, path);
    h.info.originMm = parseOrigin(text, path);
    h.gzip = parseGzip(text, path);
    h.endian = parseEndian(text, h.info.type, path);
    checkByteSkip(text, path);
    if (const std::string* skip = findField(text, "line skip"))
        h.lineSkip = parseUnsigned(*skip, path, "line skip");
    if (const std::string* file = findField(text, "data file")) {
        if (file->empty()) throw FormatError(path, "data file", "is empty");
        h.dataFile = *file;
    }
    return h;
}

/// The data file named by the header, which must lie in the header's folder (a header from an
/// untrusted upload must not make the server read /etc/shadow).
std::string resolveDataFile(const std::string& headerPath, const std::string& name) {
    std::vector<std::string> parts = words(name);
    if (parts[0] == "LIST" || (parts.size() >= 4 && parts[0].find('%') != std::string::npos))
        throw FormatError(headerPath, "data file",
                          "lists of data files are not supported; give one file");
    return detail::resolveInFolder(headerPath, name, "data file");
}

/// Skips `lines` lines of the data file (before any decompression, as teem does).
std::uint64_t skipLines(detail::ByteStream& data, std::uint64_t lines, const std::string& file) {
    std::uint64_t skipped = 0;
    for (std::uint64_t seen = 0; seen < lines;) {
        std::byte b{};
        if (data.read({&b, 1}) == 0)
            throw FormatError(file, "line skip",
                              "file ends before " + std::to_string(lines) + " lines");
        ++skipped;
        if (b == std::byte{'\n'}) ++seen;
    }
    return skipped;
}

std::string describeNrrd(const std::string& path, const NrrdHeader& h) {
    return "NRRD " + fs::path(path).filename().string() + ", " +
           std::string(voxelTypeName(h.info.type)) + (h.gzip ? ", gzip" : ", raw") +
           (h.dataFile.empty() ? "" : ", data in " + h.dataFile);
}

} // namespace

std::unique_ptr<VolumeSource> openNrrd(const std::string& path) {
    detail::requireRegularFile(path);
    HeaderText text = readHeaderText(path);
    NrrdHeader h = interpret(text, path);
    h.info.description = describeNrrd(path, h);
    validateVolumeInfo(h.info, path);
    if (h.dataFile.empty() && !text.endsWithBlankLine)
        throw FormatError(path, "data file",
                          "the header names no data file and has no blank line "
                          "before attached data");
    const std::string dataPath = h.dataFile.empty() ? path : resolveDataFile(path, h.dataFile);
    std::uint64_t offset = h.dataFile.empty() ? text.dataOffsetBytes : 0;
    auto data = detail::openFileStream(dataPath, offset);
    offset += skipLines(*data, h.lineSkip, dataPath);
    const std::uint64_t expected = h.info.voxelCount() * voxelBytes(h.info.type);
    const std::string claim = "header " + fs::path(path).filename().string() + " promises";
    std::uint64_t fileBytes = detail::fileBytes(dataPath);
    std::uint64_t held = fileBytes > offset ? fileBytes - offset : 0;
    if (h.gzip) {
        checkCompressedPayload(h.info, expected, held, "gzip", kMaxGzipRatio, dataPath);
        return detail::makeRawVoxelSource(detail::openGzipStream(std::move(data), dataPath), h.info,
                                          h.endian, dataPath, claim);
    }
    if (held != expected)
        throw FormatError(dataPath, "size",
                          claim + " " + std::to_string(expected) + " bytes, file holds " +
                              std::to_string(held));
    return detail::makeRawVoxelSource(std::move(data), h.info, h.endian, dataPath, claim);
}

} // namespace bc::brickstore
