#pragma once
// Exceptions of bc::client.
#include "protocol/Wire.h"

#include <stdexcept>
#include <string>

namespace bc::client {

/// The connection failed: cannot connect, the peer closed, a timeout, bytes that do not
/// decode. The text names the server address and what happened.
class ClientError : public std::runtime_error {
  public:
    using std::runtime_error::runtime_error;
};

/// The server answered a request with an Error message.
class ServerError : public std::runtime_error {
  public:
    ServerError(protocol::ErrorCode code, bool fatal, const std::string& message)
        : std::runtime_error(std::string(protocol::errorName(std::uint16_t(code))) + ": " +
                             message),
          mCode(code), mFatal(fatal) {}
    protocol::ErrorCode code() const { return mCode; }
    bool fatal() const { return mFatal; }

  private:
    protocol::ErrorCode mCode;
    bool mFatal;
};

} // namespace bc::client
