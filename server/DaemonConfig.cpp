// DaemonConfig's public side: reading a file or text (the sections are read by
// server/DaemonConfigReader.cpp and server/DaemonConfigCatalog.cpp), the embedded default, the
// command-line overrides, addresses and the host budget as the log describes it.
#include "server/DaemonConfig.h"

#include "brickstore/HostMemory.h"
#include "server/Error.h"
#include "server/detail/DaemonConfigChecks.h"
#include "server/detail/DaemonConfigDefault.h"
#include "server/detail/DaemonConfigReader.h"

#include <algorithm>
#include <arpa/inet.h>
#include <cctype>
#include <cerrno>
#include <cstdio>
#include <cstdlib>
#include <cstring>
#include <filesystem>
#include <fstream>
#include <sstream>
#include <unistd.h>

namespace bc::server {

using detail::Listen;
using detail::splitListen;

std::string defaultStoreDir() {
    const char* cache = std::getenv("XDG_CACHE_HOME");
    if (cache && cache[0] == '/') return (std::filesystem::path(cache) / "brickcast").string();
    return "/tmp/brickcast-" + std::to_string(::getuid());
}

void DaemonConfig::setListen(const std::string& text, const std::string& sourceName) {
    Listen l;
    if (auto why = splitListen(text, l)) throw ConfigError(sourceName + ": " + *why);
    DaemonConfig next = *this;
    next.listenHost = l.host;
    next.listenPort = l.port;
    next.listenOverridden = true;
    if (next.token.empty() && !next.loopbackOnly())
        throw ConfigError(sourceName + ": listening on '" + l.host +
                          "' (not loopback) needs server.token in the config");
    *this = std::move(next);
}

bool DaemonConfig::loopbackOnly() const {
    return isLoopback(listenHost);
}

void DaemonConfig::setWeb(const std::string& text, const std::string& sourceName) {
    Listen l;
    if (text != "auto" && !text.empty())
        if (auto why = splitListen(text, l)) throw ConfigError(sourceName + ": " + *why);
    DaemonConfig next = *this;
    next.web = text;
    next.webOverridden = true;
    if (const auto web = next.webListen(); web && next.token.empty() && !isLoopback(web->first))
        throw ConfigError(sourceName + ": the viewer on '" + web->first +
                          "' (not loopback) needs server.token in the config");
    *this = std::move(next);
}

std::optional<std::pair<std::string, std::uint16_t>> DaemonConfig::webListen() const {
    if (web.empty()) return std::nullopt;
    if (web == "auto")
        return std::pair{
            listenHost, std::uint16_t(listenPort == 0 || listenPort == 65535 ? 0 : listenPort + 1)};
    Listen l;
    splitListen(web, l); // checked when it was set
    return std::pair{l.host, l.port};
}

void DaemonConfig::setMetrics(const std::string& text, const std::string& sourceName) {
    Listen l;
    if (auto why = splitListen(text, l)) throw ConfigError(sourceName + ": " + *why);
    if (!isLoopback(l.host))
        throw ConfigError(sourceName + ": metrics on '" + l.host +
                          "' (not loopback): the endpoint has no authentication");
    metricsHost = l.host;
    metricsPort = l.port;
    metricsOverridden = true;
}

bool isLoopback(const std::string& hostText) {
    std::string host = hostText;
    std::transform(host.begin(), host.end(), host.begin(),
                   [](unsigned char ch) { return char(std::tolower(ch)); });
    if (host == "localhost") return true;
    in_addr v4{};
    if (inet_pton(AF_INET, host.c_str(), &v4) == 1) return (ntohl(v4.s_addr) >> 24) == 127;
    in6_addr v6{};
    if (inet_pton(AF_INET6, host.c_str(), &v6) != 1) return false;
    return IN6_IS_ADDR_LOOPBACK(&v6) || (IN6_IS_ADDR_V4MAPPED(&v6) && v6.s6_addr[12] == 127);
}

namespace {

/// The machine's memory as read once: what "auto" came from is what the log describes.
const brickstore::HostMemory& machineMemory() {
    static const brickstore::HostMemory memory = brickstore::hostMemory();
    return memory;
}

} // namespace

std::uint64_t autoHostBudgetBytes() {
    return brickstore::autoHostBudgetBytes(machineMemory().perProcessBytes());
}

std::string describeHostBudget(const DaemonConfig& config) {
    const std::string mib = std::to_string(config.hostBudgetBytes >> 20) + " MiB";
    if (!config.hostBudgetAuto) return mib + " (budgets.host_mb)";
    const brickstore::HostMemory& memory = machineMemory();
    char gib[32];
    std::snprintf(gib, sizeof gib, "%.1f GiB", double(memory.usableBytes()) / double(1ull << 30));
    if (memory.usableBytes() == 0) return mib + " (auto: the machine's memory is unknown)";
    const bool limited = memory.cgroupLimitBytes && *memory.cgroupLimitBytes < memory.physicalBytes;
    return mib + " (auto: a quarter of " + gib +
           (limited ? ", the limit of " + memory.cgroupFile : " of physical memory") +
           (memory.localRanks > 1
                ? " over the job's " + std::to_string(memory.localRanks) + " ranks on this machine"
                : "") +
           (config.hostBudgetBytes == brickstore::kMinAutoHostBudgetBytes ? ", at least 256 MiB"
                                                                          : "") +
           ")";
}

std::string_view DaemonConfig::defaultToml() {
    // configs/brickcastd.toml as built in (DaemonConfigTest checks the two are the same bytes).
    return detail::kDefaultConfigFiles[0].toml;
}

DaemonConfig DaemonConfig::embeddedDefault() {
    return parse(std::string(defaultToml()), "<embedded default>", "");
}

DaemonConfig DaemonConfig::parse(const std::string& tomlText, const std::string& sourceName,
                                 const std::string& baseDir) {
    toml::table root;
    try {
        root = toml::parse(tomlText, sourceName);
    } catch (const toml::parse_error& e) {
        throw ConfigError(detail::position(sourceName, e.source()) +
                          "syntax: " + std::string(e.description()));
    }
    return detail::ConfigReader(sourceName, baseDir).read(root);
}

DaemonConfig DaemonConfig::load(const std::string& path) {
    std::error_code ec;
    if (std::filesystem::is_directory(path, ec))
        throw ConfigError(path + ": is a folder, not a file");
    std::ifstream in(path, std::ios::binary);
    if (!in) throw ConfigError(path + ": cannot read: " + std::strerror(errno));
    std::ostringstream text;
    text << in.rdbuf();
    if (in.bad()) throw ConfigError(path + ": cannot read: " + std::strerror(errno));
    const auto folder = std::filesystem::absolute(path, ec).parent_path();
    DaemonConfig c = parse(text.str(), path, folder.string());
    c.file = path;
    return c;
}

} // namespace bc::server
