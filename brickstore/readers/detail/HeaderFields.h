#pragma once
// The text of "key: value" and "Key = Value" headers (NRRD, MetaImage): white space, words and
// numbers, each refusal a FormatError naming the file and the field.
#include "brickstore/Error.h"

#include <algorithm>
#include <charconv>
#include <cstdint>
#include <istream>
#include <string>
#include <vector>

namespace bc::brickstore::detail {

/// A header longer than this is not a header (a binary file opened by mistake, say).
constexpr std::uint64_t kMaxHeaderBytes = 1 << 20;

/// Reads one line of a text header (without its end) into `line`, counting its bytes into
/// `offset`; false at the end of the file. `format` names the header ("NRRD") and `end` the
/// line that ends it, for the refusals. @throw FormatError(path, "header") when the header
/// runs past kMaxHeaderBytes or holds a NUL byte (both: not a text header).
inline bool readHeaderLine(std::istream& in, std::string& line, std::uint64_t& offset,
                           const std::string& path, const char* format, const char* end) {
    line.clear();
    int c;
    while ((c = in.get()) != std::char_traits<char>::eof()) {
        if (++offset > kMaxHeaderBytes)
            throw FormatError(path, "header",
                              std::string("no ") + end + " within the first 1 MiB; not a " +
                                  format + " header");
        if (c == '\n') return true;
        if (c == 0)
            throw FormatError(path, "header",
                              "NUL byte at byte " + std::to_string(offset - 1) + "; not a " +
                                  format + " header");
        line.push_back(static_cast<char>(c));
    }
    return !line.empty();
}

/// `s` without leading and trailing blanks, tabs and line ends.
inline std::string trim(const std::string& s) {
    const char* ws = " \t\r\n";
    const std::size_t b = s.find_first_not_of(ws);
    if (b == std::string::npos) return {};
    return s.substr(b, s.find_last_not_of(ws) - b + 1);
}

/// The words of `s`, split at blanks and tabs.
inline std::vector<std::string> words(const std::string& s) {
    std::vector<std::string> out;
    std::size_t i = 0;
    while ((i = s.find_first_not_of(" \t", i)) != std::string::npos) {
        const std::size_t e = std::min(s.find_first_of(" \t", i), s.size());
        out.push_back(s.substr(i, e - i));
        i = e;
    }
    return out;
}

/// `s` as a whole non-negative integer. @throw FormatError(path, field) otherwise.
inline std::uint64_t parseUnsigned(const std::string& s, const std::string& path,
                                   const std::string& field) {
    std::uint64_t v = 0;
    const auto [end, ec] = std::from_chars(s.data(), s.data() + s.size(), v);
    if (ec != std::errc() || end != s.data() + s.size())
        throw FormatError(path, field, "'" + s + "' is not a non-negative integer");
    return v;
}

/// `s` as a whole number (finite or not: the caller decides). @throw FormatError otherwise.
inline double parseDouble(const std::string& s, const std::string& path, const std::string& field) {
    double v = 0;
    const auto [end, ec] = std::from_chars(s.data(), s.data() + s.size(), v);
    if (ec != std::errc() || end != s.data() + s.size())
        throw FormatError(path, field, "'" + s + "' is not a number");
    return v;
}

} // namespace bc::brickstore::detail
