#pragma once
// Turns a parsed brickcastd.toml into a DaemonConfig, section by section, throwing ConfigError at
// the first fault: server/DaemonConfigReader.cpp reads [server], [timeouts], [budgets], [frames]
// and checks the token rule; server/DaemonConfigCatalog.cpp reads [[volume]] and [[preset]].
#include "server/DaemonConfig.h"

#include <array>
#include <cstdint>
#include <initializer_list>
#include <optional>
#include <string>
#include <string_view>
#include <toml++/toml.h>
#include <vector>

namespace bc::server::detail {

/// How every ConfigError begins: "SOURCE:LINE:COLUMN: ", or "SOURCE: " where `at` has no line.
std::string position(const std::string& source, const toml::source_region& at);

/// Reads the sections of one document, throwing ConfigError at the first fault.
class ConfigReader {
  public:
    /// Relative paths of the document are taken against baseDir.
    ConfigReader(const std::string& sourceName, const std::string& baseDir)
        : mSource(sourceName), mBaseDir(baseDir) {}

    /// @throw ConfigError naming the source, line:column and the key (DaemonConfig::parse)
    DaemonConfig read(const toml::table& root) const;

  private:
    [[noreturn]] void fail(const toml::source_region& at, const std::string& key,
                           const std::string& why) const;
    void checkKeys(const toml::table& t, const std::string& prefix,
                   std::initializer_list<std::string_view> known) const;
    const toml::table* section(const toml::table& root, const char* name) const;
    std::optional<std::int64_t> integer(const toml::table& t, const std::string& prefix,
                                        const char* key, std::int64_t min, std::int64_t max) const;
    std::optional<std::string> string(const toml::table& t, const std::string& prefix,
                                      const char* key) const;
    std::optional<bool> boolean(const toml::table& t, const std::string& prefix,
                                const char* key) const;
    std::string resolve(const std::string& path) const;

    // [server]
    void readServer(const toml::table& root, DaemonConfig& c) const;
    void readListen(const toml::table& server, DaemonConfig& c) const;
    void readToken(const toml::table& server, DaemonConfig& c) const;
    void readMetrics(const toml::table& server, DaemonConfig& c) const;
    void readWeb(const toml::table& server, DaemonConfig& c) const;
    std::vector<std::string> readWebHosts(const toml::node& node) const;
    void readTls(const toml::table& server, DaemonConfig& c) const;
    // [timeouts], [budgets], [frames]
    void readTimeouts(const toml::table& root, DaemonConfig& c) const;
    void readBudgets(const toml::table& root, DaemonConfig& c) const;
    void readFrames(const toml::table& root, DaemonConfig& c) const;
    // Off loopback, clients authenticate: a token is required.
    void checkToken(const toml::table& root, const DaemonConfig& c) const;
    // [[volume]] and [[preset]] (DaemonConfigCatalog.cpp)
    void readVolumes(const toml::table& root, DaemonConfig& c) const;
    CatalogEntry readVolume(const toml::table& t, const std::string& prefix) const;
    void readVolumeSource(const toml::table& t, const std::string& prefix, CatalogEntry& e) const;
    std::array<std::uint64_t, 3> readDims(const toml::table& t, const std::string& prefix) const;
    void readPresets(const toml::table& root, DaemonConfig& c) const;
    PresetEntry readPreset(const toml::table& t, const std::string& prefix) const;
    std::string readPresetFile(const toml::source_region& at, const std::string& prefix,
                               const std::string& file) const;

    std::string mSource;
    std::string mBaseDir;
};

} // namespace bc::server::detail
