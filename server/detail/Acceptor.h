#pragma once
// Binding the daemon's listening sockets (the protocol's, the viewer's, the metrics'): one way
// to resolve, bind and listen, and one error for an address that cannot be had.
#include "server/detail/Asio.h"

#include <cstdint>
#include <string>

namespace bc::server::detail {

/// Opens `acceptor` on host:port (numeric port; 0 = any free one), address reuse on, listening.
/// @throw ConfigError "<what>: HOST:PORT: <reason>" (what: "config.toml: listen").
void listenOn(asio::ip::tcp::acceptor& acceptor, const std::string& host, std::uint16_t port,
              const std::string& what);

} // namespace bc::server::detail
