#pragma once
// TLS for the daemon's addresses (private to server/): one server context, loaded once from
// the config's tls_cert and tls_key (PEM), TLS 1.2 or later, through Asio's SSL streams on
// Debian's OpenSSL. A connection shakes hands before anything else reads it, within the
// handshake deadline; the protocol and HTTP then run on the encrypted stream unchanged.
#include "server/detail/Asio.h"
#include "server/detail/Transport.h"

#include <cstdint>
#include <functional>
#include <memory>

namespace boost::asio::ssl {
class context;
}

namespace bc::server {
class Log;
struct DaemonConfig;
} // namespace bc::server

namespace bc::server::detail {

using TlsContext = asio::ssl::context;

/// The config's certificate chain and key as a server context; null when tls_cert is not
/// set. @throw ConfigError naming the file and OpenSSL's reason (unreadable, not PEM, a key
/// that does not match the certificate).
std::shared_ptr<TlsContext> makeTlsContext(const DaemonConfig& config);

/// Shakes hands as the server on `socket` within `timeoutMs`, then hands `onReady` the
/// protocol's byte stream over TLS. A handshake that fails or comes late closes the socket
/// (logged) and hands `onReady` null.
void acceptTls(asio::ip::tcp::socket socket, std::shared_ptr<TlsContext> tls,
               std::uint32_t timeoutMs, Log& log,
               std::function<void(std::unique_ptr<Transport>)> onReady);

} // namespace bc::server::detail
