#pragma once
// Typed errors of the server module: start-up failures (a bad configuration file). What a
// client sends wrong is answered on the wire (protocol Error messages), never thrown here.
#include <stdexcept>
#include <string>

namespace bc::server {

/// The daemon configuration is unreadable or invalid. what() names the source, the position
/// where there is one and the key: "brickcastd.toml:12:9: [[volume]] 2 .name: why".
class ConfigError : public std::runtime_error {
  public:
    explicit ConfigError(const std::string& what) : std::runtime_error(what) {}
};

} // namespace bc::server
