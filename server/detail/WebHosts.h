#pragma once
// Which names the browser viewer answers to (private to server/). A page whose DNS name an
// attacker rebinds to the daemon's address (DNS rebinding) is same-origin with it in the
// browser, so Origin checks alone let it in; its requests still carry the attacker's name in
// Host. Every HTTP request must therefore name the daemon in Host: the address it listens on
// (any IP address when it listens on all of them: a page reached by IP has that IP as its
// origin), localhost when that address is loopback, or a name of web_hosts. A WebSocket
// upgrade that carries an Origin must come from that same origin, over http or https.
#include "server/detail/Asio.h"

#include <optional>
#include <string>
#include <string_view>
#include <vector>

namespace bc::server::detail {

class WebHosts {
  public:
    /// `listenHost` as configured ("127.0.0.1", "::1", "viewer.lan"), `bound` the address the
    /// listener got, `extra` the configured web_hosts (lower case; IPv6 in brackets).
    WebHosts(const std::string& listenHost, const asio::ip::address& bound,
             std::vector<std::string> extra);
    /// Why a request's Host header value is refused, or nothing when it names this server.
    std::optional<std::string> hostProblem(std::string_view host) const;
    /// Why a WebSocket upgrade's Origin is refused (given its Host, already accepted).
    static std::optional<std::string> originProblem(std::string_view origin, std::string_view host);
    /// The names accepted besides IP addresses (for the log).
    const std::vector<std::string>& names() const { return mNames; }

  private:
    std::vector<std::string> mNames; ///< lower case, IPv6 in brackets
    bool mAnyAddress = false;        ///< listening on 0.0.0.0 or ::
};

} // namespace bc::server::detail
