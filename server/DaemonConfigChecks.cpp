#include "server/detail/DaemonConfigChecks.h"

#include "protocol/Wire.h"

#include <algorithm>
#include <arpa/inet.h>
#include <cctype>

namespace bc::server::detail {
namespace {

bool isHostnameChar(unsigned char c) {
    return std::isalnum(c) || c == '.' || c == '-';
}

/// Why `host` is no IPv4 address or host name, or nothing.
std::optional<std::string> hostProblem(const std::string& host) {
    if (host.empty()) return "the host is empty (0.0.0.0 listens on every interface)";
    if (host.find(':') != std::string::npos)
        return "an IPv6 address goes in brackets, e.g. \"[::1]:7411\"";
    if (!std::all_of(host.begin(), host.end(), isHostnameChar) || host.front() == '-' ||
        host.front() == '.')
        return "'" + host + "' is neither an IPv4 address nor a host name";
    const bool numeric = std::all_of(host.begin(), host.end(),
                                     [](unsigned char c) { return std::isdigit(c) || c == '.'; });
    in_addr v4{};
    if (numeric && inet_pton(AF_INET, host.c_str(), &v4) != 1)
        return "'" + host + "' is not an IPv4 address";
    return std::nullopt;
}

/// Why `port`, the text after HOST:, is no port number, or nothing.
std::optional<std::string> portProblem(const std::string& port) {
    if (port.empty() || port.size() > 5 ||
        !std::all_of(port.begin(), port.end(), [](unsigned char c) { return std::isdigit(c); }) ||
        std::stoul(port) > 65535)
        return "port '" + port + "' is not a number 0..65535";
    return std::nullopt;
}

} // namespace

std::optional<std::string> volumeNameProblem(const std::string& name) {
    if (name.empty() || name.size() > protocol::kMaxVolumeNameBytes)
        return "'" + name + "' must be 1.." + std::to_string(protocol::kMaxVolumeNameBytes) +
               " bytes";
    for (unsigned char c : name)
        if (!std::isalnum(c) && c != '.' && c != '_' && c != '-')
            return "'" + name + "' has a character outside A-Z a-z 0-9 . _ -";
    if (name.front() == '.') return "'" + name + "' starts with '.'";
    return std::nullopt;
}

std::optional<std::string> webHostProblem(const std::string& host) {
    if (host.size() > 2 && host.front() == '[' && host.back() == ']') {
        in6_addr v6{};
        if (inet_pton(AF_INET6, host.substr(1, host.size() - 2).c_str(), &v6) == 1)
            return std::nullopt;
        return "'" + host + "' is not an IPv6 address";
    }
    if (host.size() > 253) return "a host name is at most 253 bytes";
    if (host.find(':') != std::string::npos)
        return "'" + host + "': a host name without a port (an IPv6 address in brackets)";
    return hostProblem(host);
}

std::optional<std::string> splitListen(const std::string& text, Listen& out) {
    const std::string usage = " (expected HOST:PORT, e.g. \"127.0.0.1:7411\" or \"[::1]:7411\")";
    std::size_t colon = 0;
    if (!text.empty() && text.front() == '[') {
        const std::size_t close = text.find(']');
        if (close == std::string::npos) return "'" + text + "' has no closing ']'" + usage;
        out.host = text.substr(1, close - 1);
        in6_addr v6{};
        if (inet_pton(AF_INET6, out.host.c_str(), &v6) != 1)
            return "'" + out.host + "' is not an IPv6 address";
        if (close + 1 >= text.size() || text[close + 1] != ':') return "no port" + usage;
        colon = close + 1;
    } else {
        colon = text.rfind(':');
        if (colon == std::string::npos) return "'" + text + "' has no port" + usage;
        out.host = text.substr(0, colon);
        if (auto why = hostProblem(out.host)) return why;
    }
    const std::string port = text.substr(colon + 1);
    if (auto why = portProblem(port)) return why;
    out.port = static_cast<std::uint16_t>(std::stoul(port));
    return std::nullopt;
}

} // namespace bc::server::detail
