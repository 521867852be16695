#pragma once
// The browser viewer's address (private to server/; PROTOCOL.md "WebSocket"): HTTP/1.1 on the
// daemon's network thread that serves the viewer's embedded files (WebAssets.h: an exact path
// or 404, nothing read from disk) and upgrades GET /ws to a WebSocket carrying the protocol,
// whose sessions the daemon runs as it runs TCP ones. Requests are bounded: headers 8 KiB, no
// bodies, each complete within the handshake timeout; at most kMaxConnections at once and
// kMaxConnectionsPerAddress from one address, where a newer connection takes the place of the
// one that has waited longest for its request. Every request's Host names this server
// (WebHosts.h), or is answered 403.
// Boost.Beast parses HTTP; this header keeps it out of the daemon.
#include "server/detail/Asio.h"
#include "server/detail/Transport.h"

#include <cstdint>
#include <functional>
#include <memory>
#include <string>

namespace boost::asio::ssl {
class context;
}

namespace bc::server {
class Log;
class MetricSet;
struct DaemonConfig;
} // namespace bc::server

namespace bc::server::detail {

class WebListener {
  public:
    static constexpr std::size_t kMaxHeaderBytes = 8 * 1024;
    static constexpr std::size_t kMaxConnections = 512;
    static constexpr std::size_t kMaxConnectionsPerAddress = 128;

    /// Binds host:port (0 = any free port). `onOpen` runs for each completed WebSocket
    /// handshake. With `tls`, every connection shakes hands over TLS first (HTTPS, wss).
    /// @throw ConfigError naming the address.
    WebListener(asio::io_context& io, const std::string& host, std::uint16_t port,
                const DaemonConfig& config, Log& log,
                std::function<void(std::unique_ptr<Transport>)> onOpen,
                std::shared_ptr<asio::ssl::context> tls = nullptr);
    ~WebListener();
    WebListener(const WebListener&) = delete;
    WebListener& operator=(const WebListener&) = delete;

    void start();
    /// Stops accepting; open HTTP connections end with the daemon's loop.
    void stop();
    std::uint16_t port() const;
    /// "http://HOST:PORT/" or "https://..." (IPv6 in brackets).
    std::string url() const;
    void collect(MetricSet& metrics) const;

    struct Impl; ///< opaque; shared with the open connections (WebListener.cpp)

  private:
    std::shared_ptr<Impl> mImpl;
};

} // namespace bc::server::detail
