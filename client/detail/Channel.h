#pragma once
// The client's connection to brickcastd (private to client/): a TCP socket, or TLS over it
// (OpenSSL) when the server has a certificate. Blocking, with poll-based timeouts.
#include "client/Client.h"

#include <cstdint>
#include <memory>
#include <span>
#include <string>

namespace bc::client::detail {

class Channel {
  public:
    virtual ~Channel() = default;
    /// Sends every byte. @throw ClientError naming `where` and the reason.
    virtual void sendAll(std::span<const std::uint8_t> bytes) = 0;
    /// Reads what arrives within `timeoutMs` into `buffer`; returns the byte count (0: nothing
    /// yet, call again). @throw ClientError when the server closed the connection or time ran
    /// out.
    virtual std::size_t receive(std::span<std::uint8_t> buffer, std::uint32_t timeoutMs) = 0;
};

/// Connects to config.host:port, then shakes hands over TLS when config.tls (verifying the
/// server's certificate and name unless config.tlsVerify is off). @throw ClientError.
std::unique_ptr<Channel> openChannel(const ClientConfig& config, const std::string& where);

} // namespace bc::client::detail
