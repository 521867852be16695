#pragma once
// The metrics address: a minimal HTTP/1.1 server on the daemon's network thread that answers
// GET /metrics with the Prometheus text exposition (version 0.0.4) and closes. Anything else
// gets a status naming what was wrong (404 path, 405 method, 400 malformed, 431 headers over
// 8 KiB, 408 a request not complete within 2 s, 403 a Host that does not name this server
// (WebHosts.h: DNS rebinding)); at most 8 scrapes at once, more are closed
// unanswered. It never touches the client sessions, so a bad scrape costs them nothing.
#include "server/detail/Asio.h"

#include <cstdint>
#include <functional>
#include <memory>
#include <string>

namespace bc::server {
class Log;
}

namespace bc::server::detail {

class WebHosts;

class MetricsEndpoint {
  public:
    /// Binds host:port (0 = any free port). @throw ConfigError naming the address.
    MetricsEndpoint(asio::io_context& io, const std::string& host, std::uint16_t port, Log& log,
                    std::function<std::string()> body, const std::string& source);
    ~MetricsEndpoint();
    MetricsEndpoint(const MetricsEndpoint&) = delete;
    MetricsEndpoint& operator=(const MetricsEndpoint&) = delete;

    void start();
    void stop();
    std::uint16_t port() const;

    static constexpr std::size_t kMaxRequestBytes = 8192;
    static constexpr int kRequestTimeoutMs = 2000;
    static constexpr int kMaxConnections = 8;

  private:
    class Connection;
    void accept();

    asio::io_context& mIo;
    asio::ip::tcp::acceptor mAcceptor;
    Log& mLog;
    std::function<std::string()> mBody;
    std::shared_ptr<int> mOpen;             ///< connections open; shared with them
    std::shared_ptr<const WebHosts> mHosts; ///< the names a scrape's Host may give
    bool mStopped = false;
};

} // namespace bc::server::detail
