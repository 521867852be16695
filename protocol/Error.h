#pragma once
// Exceptions of bc::protocol. Decoding bytes from a peer never throws: it returns a
// DecodeError (see Decoder.h). These are for programming errors on the sending side (a
// message that cannot be represented) and for frame images that do not decode.
#include <stdexcept>
#include <string>

namespace bc::protocol {

/// A message that PROTOCOL.md cannot carry (a string over its limit, too many points...),
/// or an encoded frame image that does not decode. The text names the field.
class ProtocolError : public std::runtime_error {
  public:
    using std::runtime_error::runtime_error;
};

} // namespace bc::protocol
