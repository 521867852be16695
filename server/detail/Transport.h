#pragma once
// How a session's bytes travel (private to server/): a TCP connection carrying the protocol's
// byte stream (plain, or TLS: Tls.h), or a WebSocket connection (the browser viewer) whose
// binary messages carry it.
// A session sees one interface, so both have one decoder, one set of limits and deadlines.
// Every call and handler runs on the daemon's network thread.
#include "server/detail/Asio.h"

#include <cstdint>
#include <functional>
#include <memory>
#include <span>
#include <string>

namespace bc::server::detail {

class Transport {
  public:
    /// `error` is empty on success, else says why the connection ended ("peer closed").
    /// `bytes` stay valid until the next read.
    using ReadHandler =
        std::function<void(const std::string& error, std::span<const std::uint8_t>)>;
    using WriteHandler = std::function<void(const std::string& error, std::size_t bytes)>;

    virtual ~Transport() = default;
    /// The executor the session's timers run on (the transport's socket's).
    virtual asio::any_io_executor executor() = 0;
    /// Reads what arrives next; one read at a time.
    virtual void read(ReadHandler handler) = 0;
    /// Writes one whole protocol message; `bytes` stay alive until the handler runs. One
    /// write at a time.
    virtual void write(std::span<const std::uint8_t> bytes, WriteHandler handler) = 0;
    /// Ends the connection now (pending reads and writes complete with an error). Idempotent.
    virtual void close() = 0;
    /// "ADDRESS:PORT" of the peer, "?" when unknown.
    virtual std::string peer() const = 0;
    /// "tcp", "tls", "websocket" or "websocket+tls", for the log.
    virtual const char* kind() const = 0;
};

/// The protocol's byte stream on a TCP connection.
std::unique_ptr<Transport> makeTcpTransport(asio::ip::tcp::socket socket);

/// "ADDRESS:PORT" of a socket's peer (a TCP socket, or the one under a TLS stream), "?" when
/// unknown.
std::string peerOf(const asio::ip::tcp::socket::lowest_layer_type& socket);

/// The address of a peer "ADDRESS:PORT" (as peerOf gives it): its part before the last ':'.
std::string addressOf(const std::string& peer);

} // namespace bc::server::detail
