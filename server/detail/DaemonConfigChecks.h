#pragma once
// The checks of the daemon configuration's names and addresses, shared by the TOML reader
// (server/DaemonConfigReader.cpp, server/DaemonConfigCatalog.cpp) and the command-line overrides
// (server/DaemonConfig.cpp). Each returns why a text is refused; the callers say where.
#include <cstdint>
#include <optional>
#include <string>

namespace bc::server::detail {

/// A HOST:PORT address as written, the host without brackets.
struct Listen {
    std::string host;
    std::uint16_t port = 0;
};

/// Splits "HOST:PORT" or "[IPV6]:PORT"; returns why not on failure.
std::optional<std::string> splitListen(const std::string& text, Listen& out);

/// Why `host` is no host name, IPv4 address or bracketed IPv6 address, or nothing.
std::optional<std::string> webHostProblem(const std::string& host);

/// Why `name` cannot be a catalog name (PROTOCOL.md "Limits"), or nothing.
std::optional<std::string> volumeNameProblem(const std::string& name);

} // namespace bc::server::detail
