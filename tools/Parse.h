#pragma once
// Command-line text to values, for the programs (tools/) and the benchmarks (bench/). Errors
// name the option at fault (`what`) and the part of the text that is wrong.
#include <algorithm>
#include <array>
#include <charconv>
#include <cmath>
#include <cstdint>
#include <cstdio>
#include <sstream>
#include <stdexcept>
#include <string>
#include <vector>

namespace bc::tools {
namespace detail {

/// "a,,b" -> {"a", "", "b"}: every part, empty ones included.
inline std::vector<std::string> splitComma(const std::string& text) {
    std::vector<std::string> parts;
    std::stringstream ss(text);
    for (std::string p; std::getline(ss, p, ',');)
        parts.push_back(p);
    return parts;
}

} // namespace detail

/// "a,b,c" -> numbers, each finite; between minCount and maxCount of them.
/// @throw std::invalid_argument naming `what` and the part at fault.
inline std::vector<double> parseNumbers(const std::string& text, const std::string& what,
                                        std::size_t minCount, std::size_t maxCount) {
    std::vector<double> out;
    std::size_t pos = 0;
    while (pos <= text.size()) {
        const std::size_t comma = std::min(text.find(',', pos), text.size());
        const std::string part = text.substr(pos, comma - pos);
        std::size_t used = 0;
        double v = 0;
        try {
            v = std::stod(part, &used);
        } catch (const std::exception&) {
            used = 0;
        }
        if (used == 0 || used != part.size() || !std::isfinite(v))
            throw std::invalid_argument(what + ": '" + part + "' is not a finite number");
        out.push_back(v);
        pos = comma + 1;
    }
    if (out.size() < minCount || out.size() > maxCount)
        throw std::invalid_argument(what + ": expected " + std::to_string(minCount) +
                                    (maxCount > minCount ? " to " + std::to_string(maxCount) : "") +
                                    " numbers, got '" + text + "'");
    return out;
}

/// "256,256,113" -> {256,256,113}. @throw std::invalid_argument naming `what`.
inline std::array<std::uint64_t, 3> parseTriple(const std::string& text, const std::string& what) {
    auto parts = detail::splitComma(text);
    if (parts.size() != 3)
        throw std::invalid_argument(what + ": expected X,Y,Z, got '" + text + "'");
    std::array<std::uint64_t, 3> out{};
    for (int i = 0; i < 3; ++i) {
        const auto& p = parts[i];
        auto [end, ec] = std::from_chars(p.data(), p.data() + p.size(), out[i]);
        if (ec != std::errc() || end != p.data() + p.size())
            throw std::invalid_argument(what + ": '" + p + "' is not a non-negative integer");
    }
    return out;
}

/// "1,1,2.5" -> {1,1,2.5}. @throw std::invalid_argument naming `what`.
inline std::array<double, 3> parseTripleDouble(const std::string& text, const std::string& what) {
    auto parts = detail::splitComma(text);
    if (parts.size() != 3)
        throw std::invalid_argument(what + ": expected A,B,C, got '" + text + "'");
    std::array<double, 3> out{};
    for (int i = 0; i < 3; ++i) {
        std::size_t used = 0;
        try {
            out[i] = std::stod(parts[i], &used);
        } catch (const std::exception&) {
            used = 0;
        }
        if (used == 0 || used != parts[i].size())
            throw std::invalid_argument(what + ": '" + parts[i] + "' is not a number");
    }
    return out;
}

/// "a,b,,c" -> {"a", "b", "c"}: a comma-separated list, empty items left out.
inline std::vector<std::string> splitList(const std::string& text) {
    std::vector<std::string> out;
    std::stringstream in(text);
    for (std::string item; std::getline(in, item, ',');)
        if (!item.empty()) out.push_back(item);
    return out;
}

/// Human-readable byte count ("1.50 GiB").
inline std::string formatBytes(double bytes) {
    const char* units[] = {"B", "KiB", "MiB", "GiB", "TiB"};
    int u = 0;
    while (std::fabs(bytes) >= 1024.0 && u < 4) {
        bytes /= 1024.0;
        ++u;
    }
    char buf[64];
    std::snprintf(buf, sizeof buf, u == 0 ? "%.0f %s" : "%.2f %s", bytes, units[u]);
    return buf;
}

} // namespace bc::tools
