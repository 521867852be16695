#include "brickstore/readers/detail/DicomLengths.h"

#include "brickstore/Error.h"

#include <array>
#include <cerrno>
#include <cstdint>
#include <cstdio>
#include <cstring>
#include <fstream>
#include <string_view>

namespace bc::brickstore::detail {
namespace {

constexpr std::uint32_t kUndefinedLength = 0xFFFFFFFFu;
constexpr int kMaxDepth = 64;

struct Encoding {
    bool explicitVr = true;
    bool bigEndian = false;
};

/// A cursor over the file: reads element headers only, never values.
class LengthWalker {
  public:
    explicit LengthWalker(const std::string& path) : mPath(path), mIn(path, std::ios::binary) {
        if (!mIn)
            throw FormatError(path, "path", std::string("cannot open: ") + std::strerror(errno));
        mIn.seekg(0, std::ios::end);
        mFileBytes = std::uint64_t(mIn.tellg());
    }

    bool walk() {
        std::array<char, 4> magic{};
        if (mFileBytes >= 132 && readAt(128, magic.data(), 4) &&
            std::string_view(magic.data(), 4) == "DICM") {
            mPos = 132;
            const std::string syntax = walkMeta(Encoding{true, false});
            if (syntax == "1.2.840.10008.1.2.1.99") return true; // deflated: GDCM inflates it
            walkDataSet(mFileBytes, encodingOf(syntax), 0, false);
            return true;
        }
        // A bare data set: at least one element, and whole elements to the end.
        mPos = 0;
        if (mFileBytes < 8) return false;
        try {
            walkDataSet(mFileBytes, guessEncoding(), 0, false);
        } catch (const FormatError&) {
            return false;
        }
        return true;
    }

  private:
    bool readAt(std::uint64_t pos, char* out, std::size_t n) {
        if (pos > mFileBytes || n > mFileBytes - pos) return false;
        mIn.clear();
        mIn.seekg(std::streamoff(pos));
        mIn.read(out, std::streamsize(n));
        return std::size_t(mIn.gcount()) == n;
    }

    std::uint32_t number(const unsigned char* b, std::size_t n, bool big) const {
        std::uint32_t v = 0;
        for (std::size_t i = 0; i < n; ++i)
            v |= std::uint32_t(b[big ? n - 1 - i : i]) << (8 * i);
        return v;
    }

    static Encoding encodingOf(const std::string& syntax) {
        if (syntax == "1.2.840.10008.1.2") return {false, false};
        if (syntax == "1.2.840.10008.1.2.2") return {true, true};
        return {true, false}; // explicit little endian, and every encapsulated syntax
    }

    /// A bare data set: explicit VR when the bytes after the first tag look like a VR.
    Encoding guessEncoding() {
        char b[6] = {};
        if (!readAt(0, b, 6)) return {};
        const bool vr = b[4] >= 'A' && b[4] <= 'Z' && b[5] >= 'A' && b[5] <= 'Z';
        return {vr, false};
    }

    static bool longForm(const char* vr) {
        static const char* kLong[] = {"OB", "OD", "OF", "OL", "OV", "OW", "SQ",
                                      "SV", "UC", "UN", "UR", "UT", "UV"};
        for (const char* l : kLong)
            if (vr[0] == l[0] && vr[1] == l[1]) return true;
        return false;
    }

    std::string tagText(std::uint32_t group, std::uint32_t element) const {
        char text[16];
        std::snprintf(text, sizeof(text), "(%04x,%04x)", group, element);
        return text;
    }

    void checkFits(std::uint32_t group, std::uint32_t element, std::uint64_t length,
                   std::uint64_t end) const {
        if (length <= end - mPos) return;
        // The pixel data is named as the other checks of it name it (a slice cut short).
        const bool pixelData = group == 0x7fe0 && element == 0x0010;
        throw FormatError(mPath, pixelData ? "PixelData" : "length",
                          "element " + tagText(group, element) + " at byte " +
                              std::to_string(mPos) + " declares " + std::to_string(length) +
                              " bytes where " + std::to_string(end - mPos) +
                              " remain: corrupt or truncated file");
    }

    /// The file meta group (explicit VR little endian); returns the transfer syntax UID.
    std::string walkMeta(const Encoding& meta) {
        std::string syntax;
        for (;;) {
            unsigned char h[8];
            if (!readAt(mPos, reinterpret_cast<char*>(h), 8)) return syntax;
            if (number(h, 2, false) != 0x0002) return syntax;
            const std::uint32_t element = number(h + 2, 2, false);
            const std::uint64_t length = elementLength(h, meta);
            checkFits(2, element, length, mFileBytes);
            if (element == 0x0010 && length < 128) {
                std::string uid(std::size_t(length), '\0');
                readAt(mPos, uid.data(), uid.size());
                while (!uid.empty() && (uid.back() == '\0' || uid.back() == ' '))
                    uid.pop_back();
                syntax = uid;
            }
            mPos += length;
        }
    }

    static bool knownVr(const char* vr) {
        static const char* kVrs[] = {"AE", "AS", "AT", "CS", "DA", "DS", "DT", "FD", "FL",
                                     "IS", "LO", "LT", "OB", "OD", "OF", "OL", "OV", "OW",
                                     "PN", "SH", "SL", "SQ", "SS", "ST", "SV", "TM", "UC",
                                     "UI", "UL", "UN", "UR", "US", "UT", "UV"};
        for (const char* known : kVrs)
            if (vr[0] == known[0] && vr[1] == known[1]) return true;
        return false;
    }

    /// Reads the rest of an element header whose first 8 bytes are `h`, advancing mPos past
    /// the header; returns the value length. An unknown explicit VR is a fault (GDCM asserts
    /// on some).
    std::uint64_t elementLength(const unsigned char* h, const Encoding& e) {
        const char* vr = reinterpret_cast<const char*>(h + 4);
        if (!e.explicitVr) {
            mPos += 8;
            return number(h + 4, 4, e.bigEndian);
        }
        if (!knownVr(vr)) fault("element at byte " + std::to_string(mPos) + " has no known VR");
        if (!longForm(vr)) {
            mPos += 8;
            return number(h + 6, 2, e.bigEndian);
        }
        unsigned char l[4];
        if (!readAt(mPos + 8, reinterpret_cast<char*>(l), 4)) {
            mPos = mFileBytes;
            return 0;
        }
        mPos += 12;
        mLastVrIsSq = vr[0] == 'S' && vr[1] == 'Q';
        return number(l, 4, e.bigEndian);
    }

    /// The next 8 header bytes of a container ending at `end` (the file's end when
    /// `delimited`); false at `end`. A partial header is a fault.
    bool nextHeader(unsigned char* h, std::uint64_t end, bool delimited) {
        if (mPos == end) {
            if (delimited) fault("the file ends before a sequence or item delimiter");
            return false;
        }
        if (end - mPos < 8 || !readAt(mPos, reinterpret_cast<char*>(h), 8))
            fault("a partial element header at byte " + std::to_string(mPos));
        return true;
    }

    [[noreturn]] void fault(const std::string& why) const {
        throw FormatError(mPath, "length", why + ": corrupt or truncated file");
    }

    void checkDepth(int depth) const {
        if (depth > kMaxDepth) fault("sequences nested deeper than " + std::to_string(kMaxDepth));
    }

    /// Elements up to `end`, or (`delimited`) up to an item delimiter, as GDCM expects them.
    void walkDataSet(std::uint64_t end, const Encoding& e, int depth, bool delimited) {
        checkDepth(depth);
        unsigned char h[8];
        while (nextHeader(h, end, delimited)) {
            const std::uint32_t group = number(h, 2, e.bigEndian),
                                element = number(h + 2, 2, e.bigEndian);
            if (group == 0xFFFE) {
                mPos += 8;
                if (delimited && element == 0xE00D) return;
                fault("item tag " + tagText(group, element) + " at byte " +
                      std::to_string(mPos - 8) + " outside a sequence");
            }
            mLastVrIsSq = false;
            const bool unknown = e.explicitVr && h[4] == 'U' && h[5] == 'N';
            const std::uint64_t length = elementLength(h, e);
            const bool sequence = mLastVrIsSq;
            const bool pixelData = group == 0x7FE0 && element == 0x0010;
            if (length == kUndefinedLength) {
                // A sequence, or encapsulated pixel data: items up to a sequence delimiter.
                const bool fragments = pixelData || (e.explicitVr && !sequence && !unknown);
                walkSequence(end, e, depth + 1, true, fragments);
                continue;
            }
            checkFits(group, element, length, end);
            if (sequence || (!e.explicitVr && !pixelData && startsWithItem(e, mPos + length)))
                walkSequence(mPos + length, e, depth + 1, false, false);
            else
                mPos += length;
        }
    }

    /// Items up to `end`, or (`delimited`) up to a sequence delimiter; an item's value is a
    /// data set, or bytes when `fragments` (encapsulated pixel data).
    void walkSequence(std::uint64_t end, const Encoding& e, int depth, bool delimited,
                      bool fragments) {
        checkDepth(depth);
        unsigned char h[8];
        while (nextHeader(h, end, delimited)) {
            const std::uint32_t group = number(h, 2, e.bigEndian),
                                element = number(h + 2, 2, e.bigEndian);
            const std::uint32_t length = number(h + 4, 4, e.bigEndian);
            mPos += 8;
            if (group == 0xFFFE && element == 0xE0DD && delimited) return;
            if (group != 0xFFFE || element != 0xE000)
                fault("element " + tagText(group, element) + " at byte " +
                      std::to_string(mPos - 8) + " where a sequence needs an item");
            if (length == kUndefinedLength && !fragments) {
                walkDataSet(end, e, depth + 1, true);
                continue;
            }
            checkFits(group, element, length, end);
            if (fragments)
                mPos += length;
            else
                walkDataSet(mPos + length, e, depth + 1, false);
        }
    }

    bool startsWithItem(const Encoding& e, std::uint64_t end) {
        unsigned char h[4];
        if (end - mPos < 8 || !readAt(mPos, reinterpret_cast<char*>(h), 4)) return false;
        return number(h, 2, e.bigEndian) == 0xFFFE && number(h + 2, 2, e.bigEndian) == 0xE000;
    }

    std::string mPath;
    std::ifstream mIn;
    std::uint64_t mFileBytes = 0;
    std::uint64_t mPos = 0;
    bool mLastVrIsSq = false;
};

} // namespace

bool checkDicomLengths(const std::string& path) {
    return LengthWalker(path).walk();
}

} // namespace bc::brickstore::detail
