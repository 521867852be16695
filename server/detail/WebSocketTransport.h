#pragma once
// The protocol over WebSocket (private to server/; PROTOCOL.md "WebSocket"): each binary
// message the client sends carries protocol bytes (the session decodes them as one stream, so
// the TCP transport's limits apply), and each protocol message the server sends is one binary
// message. Text messages, messages over the protocol's limit and ping floods end the
// connection. Boost.Beast does the framing (RFC 6455), here and nowhere else.
#include "server/detail/Transport.h"

#include <boost/beast/http/empty_body.hpp>
#include <boost/beast/http/message.hpp>

#include <cstdint>
#include <functional>
#include <memory>
#include <string>

namespace bc::server {
class Log;
}

namespace bc::server::detail {

using UpgradeRequest = boost::beast::http::request<boost::beast::http::empty_body>;

/// A WebSocket peer may send this many pings in one second; one more ends the connection.
inline constexpr unsigned kMaxPingsPerSecond = 50;

/// Completes the WebSocket handshake of `request` (an upgrade the HTTP side routed here)
/// within `timeoutMs`, then hands the connection to `onOpen`. A request Beast finds invalid
/// (no Sec-WebSocket-Key, a version other than 13) is answered 400 or 426 and closed.
/// `Stream`: asio::ip::tcp::socket, or asio::ssl::stream of one after its TLS handshake (the
/// two instantiated in WebSocketTransport.cpp).
template <class Stream>
void acceptWebSocket(Stream stream, UpgradeRequest request, std::uint32_t timeoutMs, Log& log,
                     std::function<void(std::unique_ptr<Transport>)> onOpen);

} // namespace bc::server::detail
