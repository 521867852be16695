// The markup of a .vti file (detail/VtiXml.h), parsed by expat in 64 KiB pieces. Expat is C:
// its callbacks must not throw, so a callback that finds a fault records it and stops the
// parser, and parseVtiXml throws once expat has returned.
#include "brickstore/readers/detail/VtiXml.h"
#include "brickstore/Error.h"

#include <array>
#include <cerrno>
#include <charconv>
#include <cmath>
#include <cstring>
#include <filesystem>
#include <fstream>
#include <map>
#include <optional>
#include <vector>

#include <expat.h>

namespace bc::brickstore::detail {

namespace {

/// File bytes handed to expat at a time.
constexpr std::size_t kFeedBytes = std::size_t(1) << 16;
/// Deeper nesting than this is no .vti (ImageData's arrays sit at depth 4).
constexpr std::size_t kMaxDepth = 32;
/// Point-data arrays a Piece may declare.
constexpr std::size_t kMaxArrays = 256;

struct ParserFree {
    void operator()(XML_Parser p) const { XML_ParserFree(p); }
};

/// A point-data DataArray as its start tag and text describe it.
struct ArrayTag {
    std::string name, type, format, components, offset;
    std::optional<std::uint64_t> textBegin; ///< inline text: its first byte in the file
    std::uint64_t textEnd = 0;
};

const char* attribute(const XML_Char** atts, const char* key) {
    for (; atts[0]; atts += 2)
        if (std::strcmp(atts[0], key) == 0) return atts[1];
    return nullptr;
}

/// `count` numbers of type T, white-space separated; nullopt when the text is not that.
template <class T, std::size_t N> std::optional<std::array<T, N>> parseNumbers(const char* text) {
    std::array<T, N> out{};
    const char* p = text;
    const char* end = text + std::strlen(text);
    for (std::size_t i = 0; i < N; ++i) {
        while (p < end && std::strchr(" \t\r\n", *p))
            ++p;
        auto [next, ec] = std::from_chars(p, end, out[i]);
        if (ec != std::errc() || next == p) return std::nullopt;
        p = next;
    }
    while (p < end && std::strchr(" \t\r\n", *p))
        ++p;
    if (p != end) return std::nullopt;
    return out;
}

bool isBase64Text(unsigned char c) {
    return (c >= 'A' && c <= 'Z') || (c >= 'a' && c <= 'z') || (c >= '0' && c <= '9') || c == '+' ||
           c == '/' || c == '=' || c == ' ' || c == '\t' || c == '\r' || c == '\n';
}

class VtiParser {
  public:
    VtiParser(const std::string& path, std::uint64_t fileBytes)
        : mPath(path), mFileBytes(fileBytes), mParser(XML_ParserCreate(nullptr)) {
        if (!mParser) throw std::bad_alloc();
        XML_SetUserData(mParser.get(), this);
        XML_SetElementHandler(mParser.get(), &VtiParser::onStart, &VtiParser::onEnd);
        XML_SetCharacterDataHandler(mParser.get(), &VtiParser::onText);
        XML_SetStartDoctypeDeclHandler(mParser.get(), &VtiParser::onDoctype);
    }

    VtiLayout parse() {
        feed();
        return layout();
    }

  private:
    static void XMLCALL onStart(void* self, const XML_Char* name, const XML_Char** atts) {
        static_cast<VtiParser*>(self)->start(name, atts);
    }
    static void XMLCALL onEnd(void* self, const XML_Char*) {
        static_cast<VtiParser*>(self)->mStack.pop_back();
    }
    static void XMLCALL onText(void* self, const XML_Char* s, int len) {
        static_cast<VtiParser*>(self)->text(s, len);
    }
    static void XMLCALL onDoctype(void* self, const XML_Char*, const XML_Char*, const XML_Char*,
                                  int) {
        // Entity declarations are how XML bombs work; a .vti has no use for a DTD.
        static_cast<VtiParser*>(self)->fail("XML", "a DOCTYPE declaration is not allowed");
    }

    /// Records the first fault and stops expat; feed() throws it.
    void fail(const std::string& field, const std::string& why) {
        if (!mError) mError.emplace(mPath, field, why);
        XML_StopParser(mParser.get(), XML_FALSE);
    }

    std::uint64_t byteIndex() const {
        return std::uint64_t(XML_GetCurrentByteIndex(mParser.get()));
    }

    void feed() {
        std::ifstream in(mPath, std::ios::binary);
        if (!in)
            throw FormatError(mPath, "path", std::string("cannot open: ") + std::strerror(errno));
        std::vector<char> buf(kFeedBytes);
        for (std::uint64_t fed = 0;;) {
            in.read(buf.data(), std::streamsize(buf.size()));
            const std::size_t n = std::size_t(in.gcount());
            const bool last = n < buf.size();
            const XML_Status status = XML_Parse(mParser.get(), buf.data(), int(n), last);
            fed += n;
            if (mError) throw *mError;
            if (mAppendedTagEnd) return;
            if (status != XML_STATUS_OK) throwXmlError();
            if (fed - mInlineTextBytes > kMaxVtiMarkupBytes)
                throw FormatError(mPath, "header",
                                  "more than 1 MiB of XML markup (inline array data aside); "
                                  "not a .vti header");
            if (last) return;
        }
    }

    [[noreturn]] void throwXmlError() const {
        throw FormatError(
            mPath, "XML",
            "not well-formed at line " + std::to_string(XML_GetCurrentLineNumber(mParser.get())) +
                ", column " + std::to_string(XML_GetCurrentColumnNumber(mParser.get())) + ": " +
                XML_ErrorString(XML_GetErrorCode(mParser.get())));
    }

    void start(const std::string& name, const XML_Char** atts) {
        const std::string parent = mStack.empty() ? "" : mStack.back();
        mStack.push_back(name); // before any return: onEnd pops it
        if (mError) return;
        if (mStack.size() > kMaxDepth)
            return fail("XML", "elements nested deeper than " + std::to_string(kMaxDepth));
        if (parent.empty() && name != "VTKFile")
            return fail("VTKFile", "the root element is <" + name + ">; not a VTK XML file");
        if (name == "DataArray") return startArray(parent == "PointData", atts);
        if (parent == "VTKFile" && name == "ImageData") return startImage(atts);
        if (parent == "VTKFile" && name == "AppendedData") return startAppended(atts);
        if (parent == "ImageData" && name == "Piece") return startPiece(atts);
        if (parent == "Piece" && name == "PointData") {
            if (const char* scalars = attribute(atts, "Scalars")) mScalars = scalars;
            return;
        }
        if (name == "VTKFile") startFile(atts);
    }

    void startFile(const XML_Char** atts) {
        const char* type = attribute(atts, "type");
        if (!type || std::strcmp(type, "ImageData") != 0)
            return fail("type", std::string("VTKFile type is '") + (type ? type : "") +
                                    "'; brickcast reads ImageData (.vti) only");
        const char* order = attribute(atts, "byte_order");
        if (!order || (std::strcmp(order, "LittleEndian") && std::strcmp(order, "BigEndian")))
            return fail("byte_order", std::string("'") + (order ? order : "") +
                                          "' is neither LittleEndian nor BigEndian");
        mLayout.endian = std::strcmp(order, "BigEndian") == 0 ? Endian::Big : Endian::Little;
        const char* header = attribute(atts, "header_type");
        if (header && std::strcmp(header, "UInt32") && std::strcmp(header, "UInt64"))
            return fail("header_type",
                        std::string("'") + header + "' is neither UInt32 nor UInt64");
        mLayout.headerBytes = header && std::strcmp(header, "UInt64") == 0 ? 8 : 4;
        const char* compressor = attribute(atts, "compressor");
        if (compressor && std::strcmp(compressor, "vtkZLibDataCompressor") != 0)
            return fail("compressor", std::string("'") + compressor +
                                          "' is not supported; brickcast reads uncompressed "
                                          "data and vtkZLibDataCompressor");
        mLayout.zlib = compressor != nullptr;
    }

    void startImage(const XML_Char** atts) {
        if (mSawImage) return fail("ImageData", "given twice");
        mSawImage = true;
        const char* extent = attribute(atts, "WholeExtent");
        auto whole = extent ? parseNumbers<std::int64_t, 6>(extent) : std::nullopt;
        if (!whole) return fail("WholeExtent", "missing or not 6 integers");
        mWholeExtent = *whole;
        std::array<double, 3> spacing{1, 1, 1}, origin{0, 0, 0};
        if (!readTriple(atts, "Spacing", spacing) || !readTriple(atts, "Origin", origin)) return;
        if (const char* direction = attribute(atts, "Direction")) {
            auto d = parseNumbers<double, 9>(direction);
            if (!d || *d != std::array<double, 9>{1, 0, 0, 0, 1, 0, 0, 0, 1})
                return fail("Direction", std::string("'") + direction +
                                             "' is not the identity; rotated or flipped "
                                             "volumes are not supported");
        }
        for (int a = 0; a < 3; ++a) {
            const std::int64_t lo = mWholeExtent[2 * a], hi = mWholeExtent[2 * a + 1];
            if (hi < lo) return fail("WholeExtent", std::string("'") + extent + "' is empty");
            mLayout.info.dims[a] = std::uint64_t(hi) - std::uint64_t(lo) + 1;
            mLayout.info.originMm[a] = origin[a] + double(lo) * spacing[a];
        }
        mLayout.info.spacingMm = spacing;
    }

    bool readTriple(const XML_Char** atts, const char* key, std::array<double, 3>& out) {
        const char* text = attribute(atts, key);
        if (!text) return true;
        auto v = parseNumbers<double, 3>(text);
        if (!v || !std::isfinite((*v)[0]) || !std::isfinite((*v)[1]) || !std::isfinite((*v)[2])) {
            fail(key, std::string("'") + text + "' is not 3 finite numbers");
            return false;
        }
        out = *v;
        return true;
    }

    /// The piece's Extent is checked once the markup is read, so that a file of several
    /// pieces (each with part of the extent) is refused for that.
    void startPiece(const XML_Char** atts) {
        if (++mPieces > 1)
            return fail("Piece", "the file has more than one piece; brickcast reads one piece "
                                 "covering the WholeExtent");
        const char* extent = attribute(atts, "Extent");
        mPieceExtent = extent ? extent : "";
    }

    void startArray(bool pointData, const XML_Char** atts) {
        const char* format = attribute(atts, "format");
        mInlineArray = format && std::strcmp(format, "binary") == 0;
        mCurrent.reset();
        if (!pointData || mPieces != 1) return;
        if (mArrays.size() == kMaxArrays)
            return fail("PointData", "more than " + std::to_string(kMaxArrays) + " arrays");
        ArrayTag& tag = mArrays.emplace_back();
        for (auto [key, field] :
             {std::pair{"Name", &tag.name}, std::pair{"type", &tag.type},
              std::pair{"format", &tag.format}, std::pair{"NumberOfComponents", &tag.components},
              std::pair{"offset", &tag.offset}})
            if (const char* v = attribute(atts, key)) *field = v;
        mCurrent = mArrays.size() - 1;
    }

    /// The base64 text of an inline array: checked and located, not kept (it is the volume).
    void text(const XML_Char* s, int len) {
        if (mError || mStack.empty() || mStack.back() != "DataArray" || !mInlineArray) return;
        const std::uint64_t at = byteIndex(),
                            count = std::uint64_t(XML_GetCurrentByteCount(mParser.get()));
        bool blank = true;
        for (int i = 0; i < len; ++i) {
            const auto c = static_cast<unsigned char>(s[i]);
            if (!isBase64Text(c))
                return fail("DataArray", "inline data holds '" + std::string(1, char(c)) +
                                             "' at byte " + std::to_string(at) +
                                             "; it must be base64");
            blank = blank && std::strchr(" \t\r\n", c);
        }
        mInlineTextBytes += count;
        if (!mCurrent) return;
        ArrayTag& tag = mArrays[*mCurrent];
        if (count != std::uint64_t(len) && !blank)
            return fail("DataArray", "inline data holds a character reference at byte " +
                                         std::to_string(at) + "; it must be plain base64");
        if (tag.textBegin && at != tag.textEnd)
            return fail("DataArray", "inline data is broken by markup (a comment or CDATA) at "
                                     "byte " +
                                         std::to_string(tag.textEnd));
        if (!tag.textBegin) tag.textBegin = at;
        tag.textEnd = at + count;
    }

    void startAppended(const XML_Char** atts) {
        const char* encoding = attribute(atts, "encoding");
        if (!encoding || (std::strcmp(encoding, "raw") && std::strcmp(encoding, "base64")))
            return fail("encoding", std::string("AppendedData encoding '") +
                                        (encoding ? encoding : "") + "' is neither raw nor base64");
        mAppendedBase64 = std::strcmp(encoding, "base64") == 0;
        mAppendedTagEnd = byteIndex() + std::uint64_t(XML_GetCurrentByteCount(mParser.get()));
        // The appended bytes are no XML: expat must not see them.
        XML_StopParser(mParser.get(), XML_FALSE);
    }

    VtiLayout layout();
    const ArrayTag& chooseArray() const;
    void locateAppended(const ArrayTag& tag);

    std::string mPath;
    std::uint64_t mFileBytes;
    std::unique_ptr<XML_ParserStruct, ParserFree> mParser;
    std::optional<FormatError> mError;
    std::vector<std::string> mStack;
    VtiLayout mLayout;
    bool mSawImage = false;
    std::array<std::int64_t, 6> mWholeExtent{};
    int mPieces = 0;
    std::string mPieceExtent;
    std::optional<std::string> mScalars;
    std::vector<ArrayTag> mArrays;
    /// Index in mArrays of the point-data array whose start tag was seen last, if it was one.
    std::optional<std::size_t> mCurrent;
    bool mInlineArray = false; ///< the innermost DataArray is format="binary"
    std::uint64_t mInlineTextBytes = 0;
    std::optional<std::uint64_t> mAppendedTagEnd;
    bool mAppendedBase64 = false;
};

VoxelType arrayType(const std::string& type, const std::string& path) {
    static const std::map<std::string, VoxelType> kStored = {{"UInt8", VoxelType::U8},
                                                             {"UInt16", VoxelType::U16},
                                                             {"Int16", VoxelType::I16},
                                                             {"Float32", VoxelType::F32}};
    if (auto it = kStored.find(type); it != kStored.end()) return it->second;
    for (const char* other :
         {"Int8", "Int32", "UInt32", "Int64", "UInt64", "Float64", "Bit", "String", "IdType"})
        if (type == other)
            throw FormatError(path, "type",
                              "DataArray type '" + type + "' is not supported; brickcast " +
                                  "reads UInt8, UInt16, Int16 and Float32");
    throw FormatError(path, "type", "unknown DataArray type '" + type + "'");
}

VtiLayout VtiParser::layout() {
    if (!mSawImage) throw FormatError(mPath, "ImageData", "no ImageData element before the data");
    if (mPieces == 0) throw FormatError(mPath, "Piece", "ImageData has no Piece");
    auto extent = parseNumbers<std::int64_t, 6>(mPieceExtent.c_str());
    if (!extent || *extent != mWholeExtent)
        throw FormatError(mPath, "Extent",
                          "'" + mPieceExtent + "' is not the WholeExtent; the piece must cover it");
    const ArrayTag& tag = chooseArray();
    mLayout.arrayName = tag.name;
    mLayout.info.type = arrayType(tag.type, mPath);
    if (!tag.components.empty() && tag.components != "1")
        throw FormatError(mPath, "NumberOfComponents",
                          "array '" + tag.name + "' has " + tag.components +
                              " components; brickcast reads scalars (1 component)");
    if (tag.format == "appended") {
        locateAppended(tag);
    } else if (tag.format == "binary") {
        if (!tag.textBegin)
            throw FormatError(mPath, "DataArray", "array '" + tag.name + "' holds no data");
        mLayout.encoding = VtiEncoding::InlineBase64;
        mLayout.dataBegin = *tag.textBegin;
        mLayout.dataEnd = tag.textEnd;
    } else {
        throw FormatError(mPath, "format",
                          "DataArray format '" + tag.format + "' is not supported; brickcast " +
                              "reads appended and binary");
    }
    return mLayout;
}

/// The Scalars array of PointData, else its only array.
const ArrayTag& VtiParser::chooseArray() const {
    if (mScalars) {
        for (const ArrayTag& tag : mArrays)
            if (tag.name == *mScalars) return tag;
        throw FormatError(mPath, "Scalars",
                          "PointData names '" + *mScalars +
                              "' as its scalars, but has no "
                              "DataArray of that name");
    }
    if (mArrays.size() != 1)
        throw FormatError(mPath, "PointData",
                          "has " + std::to_string(mArrays.size()) +
                              " arrays and no Scalars attribute naming one; brickcast reads "
                              "one scalar array");
    return mArrays.front();
}

/// The array's first byte: its offset past AppendedData's "_" marker.
void VtiParser::locateAppended(const ArrayTag& tag) {
    if (!mAppendedTagEnd)
        throw FormatError(mPath, "AppendedData",
                          "array '" + tag.name +
                              "' is appended, but the file has no "
                              "AppendedData element");
    std::ifstream in(mPath, std::ios::binary);
    in.seekg(std::streamoff(*mAppendedTagEnd));
    std::uint64_t at = *mAppendedTagEnd;
    int c;
    while ((c = in.get()) != std::char_traits<char>::eof() && std::strchr(" \t\r\n", c) &&
           at - *mAppendedTagEnd < kFeedBytes)
        ++at;
    if (c != '_')
        throw FormatError(mPath, "AppendedData",
                          "no '_' marker after <AppendedData> (byte " + std::to_string(at) + ")");
    const std::uint64_t base = at + 1;
    std::uint64_t offset = 0;
    auto [end, ec] =
        std::from_chars(tag.offset.data(), tag.offset.data() + tag.offset.size(), offset);
    if (tag.offset.empty() || ec != std::errc() || end != tag.offset.data() + tag.offset.size())
        throw FormatError(mPath, "offset",
                          "array '" + tag.name + "' has offset '" + tag.offset +
                              "'; an appended array needs a non-negative integer offset");
    if (offset > mFileBytes - base)
        throw FormatError(mPath, "offset",
                          "array '" + tag.name + "' starts at byte " + std::to_string(offset) +
                              " of the appended data, past the end of the file (" +
                              std::to_string(mFileBytes - base) + " bytes of appended data)");
    mLayout.encoding = mAppendedBase64 ? VtiEncoding::AppendedBase64 : VtiEncoding::AppendedRaw;
    mLayout.dataBegin = base + offset;
    mLayout.dataEnd = mFileBytes;
}

} // namespace

VtiLayout parseVtiXml(const std::string& path, std::uint64_t fileBytes) {
    return VtiParser(path, fileBytes).parse();
}

} // namespace bc::brickstore::detail
