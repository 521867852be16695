#pragma once
// The text of "key: value" and "Key = Value" headers (NRRD, MetaImage): white space, words and
// numbers, each refusal a FormatError naming the file and the field.
#include "brickstore/Error.h"

#include <algorithm>
#include <charconv>
#include <cstdint>
#include <string>
#include <vector>

namespace bc::brickstore::detail {

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
