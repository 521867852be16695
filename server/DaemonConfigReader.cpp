#include "server/detail/DaemonConfigReader.h"

#include "protocol/Wire.h"
#include "server/Error.h"
#include "server/detail/DaemonConfigChecks.h"

#include <algorithm>
#include <cctype>
#include <filesystem>
#include <sstream>

namespace bc::server::detail {
namespace {

constexpr std::int64_t kMaxMs = 86'400'000; // a day
constexpr std::int64_t kMaxBudgetMb = 1 << 20;

std::string nodeTypeName(toml::node_type t) {
    std::ostringstream s;
    s << t;
    return s.str();
}

template <class T> void assign(T& field, std::optional<std::int64_t> value) {
    if (value) field = static_cast<T>(*value);
}

} // namespace

std::string position(const std::string& source, const toml::source_region& at) {
    if (at.begin.line == 0) return source + ": ";
    return source + ":" + std::to_string(at.begin.line) + ":" + std::to_string(at.begin.column) +
           ": ";
}

void ConfigReader::fail(const toml::source_region& at, const std::string& key,
                        const std::string& why) const {
    throw ConfigError(position(mSource, at) + key + ": " + why);
}

void ConfigReader::checkKeys(const toml::table& t, const std::string& prefix,
                             std::initializer_list<std::string_view> known) const {
    for (auto&& [key, node] : t) {
        if (std::find(known.begin(), known.end(), key.str()) != known.end()) continue;
        std::string list;
        for (std::string_view k : known)
            list += (list.empty() ? "" : ", ") + std::string(k);
        fail(key.source(), prefix + std::string(key.str()), "unknown key (known: " + list + ")");
    }
}

const toml::table* ConfigReader::section(const toml::table& root, const char* name) const {
    const toml::node* node = root.get(name);
    if (!node) return nullptr;
    if (!node->is_table())
        fail(node->source(), name,
             "expected a [" + std::string(name) + "] table, got " + nodeTypeName(node->type()));
    return node->as_table();
}

std::optional<std::int64_t> ConfigReader::integer(const toml::table& t, const std::string& prefix,
                                                  const char* key, std::int64_t min,
                                                  std::int64_t max) const {
    const toml::node* node = t.get(key);
    if (!node) return std::nullopt;
    const auto* v = node->as_integer();
    if (!v)
        fail(node->source(), prefix + key,
             "expected an integer, got " + nodeTypeName(node->type()));
    if (v->get() < min || v->get() > max)
        fail(node->source(), prefix + key,
             std::to_string(v->get()) + " is outside " + std::to_string(min) + ".." +
                 std::to_string(max));
    return v->get();
}

std::optional<std::string> ConfigReader::string(const toml::table& t, const std::string& prefix,
                                                const char* key) const {
    const toml::node* node = t.get(key);
    if (!node) return std::nullopt;
    const auto* v = node->as_string();
    if (!v)
        fail(node->source(), prefix + key, "expected a string, got " + nodeTypeName(node->type()));
    return v->get();
}

std::optional<bool> ConfigReader::boolean(const toml::table& t, const std::string& prefix,
                                          const char* key) const {
    const toml::node* node = t.get(key);
    if (!node) return std::nullopt;
    const auto* v = node->as_boolean();
    if (!v)
        fail(node->source(), prefix + key,
             "expected true or false, got " + nodeTypeName(node->type()));
    return v->get();
}

std::string ConfigReader::resolve(const std::string& path) const {
    std::filesystem::path p(path);
    if (p.is_relative()) p = std::filesystem::path(mBaseDir) / p;
    return p.lexically_normal().string();
}

void ConfigReader::readServer(const toml::table& root, DaemonConfig& c) const {
    const toml::table* t = section(root, "server");
    if (!t) return;
    checkKeys(*t, "server.",
              {"listen", "token", "max_clients", "max_unauthenticated", "store_dir", "metrics",
               "web", "web_hosts", "tls_cert", "tls_key"});
    readListen(*t, c);
    readToken(*t, c);
    readMetrics(*t, c);
    readWeb(*t, c);
    assign(c.maxClients, integer(*t, "server.", "max_clients", 1, 1024));
    assign(c.maxUnauthenticated, integer(*t, "server.", "max_unauthenticated", 1, 1024));
    if (const toml::node* hosts = t->get("web_hosts")) c.webHosts = readWebHosts(*hosts);
    readTls(*t, c);
    if (auto dir = string(*t, "server.", "store_dir"); dir && !dir->empty())
        c.storeDir = resolve(*dir);
}

void ConfigReader::readListen(const toml::table& t, DaemonConfig& c) const {
    auto listen = string(t, "server.", "listen");
    if (!listen) return;
    Listen l;
    if (auto why = splitListen(*listen, l)) fail(t.get("listen")->source(), "server.listen", *why);
    c.listenHost = l.host;
    c.listenPort = l.port;
}

void ConfigReader::readToken(const toml::table& t, DaemonConfig& c) const {
    auto token = string(t, "server.", "token");
    if (!token) return;
    if (token->size() > protocol::kMaxTokenBytes)
        fail(t.get("token")->source(), "server.token",
             "longer than " + std::to_string(protocol::kMaxTokenBytes) + " bytes");
    c.token = *token;
}

void ConfigReader::readMetrics(const toml::table& t, DaemonConfig& c) const {
    auto metrics = string(t, "server.", "metrics");
    if (!metrics || metrics->empty()) return;
    Listen l;
    if (auto why = splitListen(*metrics, l))
        fail(t.get("metrics")->source(), "server.metrics", *why);
    if (!isLoopback(l.host))
        fail(t.get("metrics")->source(), "server.metrics",
             "'" + l.host + "' is not loopback: the endpoint has no authentication");
    c.metricsHost = l.host;
    c.metricsPort = l.port;
}

void ConfigReader::readWeb(const toml::table& t, DaemonConfig& c) const {
    auto web = string(t, "server.", "web");
    if (!web) return;
    Listen l;
    if (*web != "auto" && !web->empty())
        if (auto why = splitListen(*web, l)) fail(t.get("web")->source(), "server.web", *why);
    c.web = *web;
}

std::vector<std::string> ConfigReader::readWebHosts(const toml::node& node) const {
    constexpr std::size_t kMaxWebHosts = 64;
    const toml::array* a = node.as_array();
    if (!a || a->size() > kMaxWebHosts)
        fail(node.source(), "server.web_hosts",
             "expected an array of at most " + std::to_string(kMaxWebHosts) +
                 " host names, e.g. [\"viewer.example.org\"]");
    std::vector<std::string> hosts;
    for (std::size_t i = 0; i < a->size(); ++i) {
        const auto* v = (*a)[i].as_string();
        if (!v)
            fail((*a)[i].source(), "server.web_hosts",
                 "element " + std::to_string(i + 1) + " is not a string");
        std::string host = v->get();
        if (auto why = webHostProblem(host))
            fail((*a)[i].source(), "server.web_hosts",
                 "element " + std::to_string(i + 1) + ": " + *why);
        std::transform(host.begin(), host.end(), host.begin(),
                       [](unsigned char ch) { return char(std::tolower(ch)); });
        hosts.push_back(std::move(host));
    }
    return hosts;
}

void ConfigReader::readTls(const toml::table& t, DaemonConfig& c) const {
    const auto cert = string(t, "server.", "tls_cert"), key = string(t, "server.", "tls_key");
    const bool withCert = cert && !cert->empty(), withKey = key && !key->empty();
    if (withCert != withKey)
        fail(t.get(withCert ? "tls_cert" : "tls_key")->source(),
             withCert ? "server.tls_key" : "server.tls_cert",
             "tls_cert and tls_key go together (a PEM certificate chain and its private key)");
    if (!withCert) return;
    c.tlsCert = resolve(*cert);
    c.tlsKey = resolve(*key);
}

void ConfigReader::readTimeouts(const toml::table& root, DaemonConfig& c) const {
    const toml::table* t = section(root, "timeouts");
    if (!t) return;
    const std::string p = "timeouts.";
    checkKeys(*t, p, {"handshake_ms", "read_ms", "idle_ms", "write_ms"});
    assign(c.handshakeTimeoutMs, integer(*t, p, "handshake_ms", 1, kMaxMs));
    assign(c.readTimeoutMs, integer(*t, p, "read_ms", 1, kMaxMs));
    assign(c.idleTimeoutMs, integer(*t, p, "idle_ms", 1, kMaxMs));
    assign(c.writeTimeoutMs, integer(*t, p, "write_ms", 1, kMaxMs));
}

void ConfigReader::readBudgets(const toml::table& root, DaemonConfig& c) const {
    const toml::table* t = section(root, "budgets");
    if (!t) return;
    checkKeys(*t, "budgets.", {"host_mb", "gpu_mb"});
    if (const toml::node* node = t->get("host_mb"); node && node->is_string()) {
        if (node->as_string()->get() != "auto")
            fail(node->source(), "budgets.host_mb",
                 "expected an integer (MiB) or \"auto\", got \"" + node->as_string()->get() + "\"");
        c.hostBudgetBytes = autoHostBudgetBytes();
        c.hostBudgetAuto = true;
    } else if (auto mb = integer(*t, "budgets.", "host_mb", 1, kMaxBudgetMb)) {
        c.hostBudgetBytes = std::uint64_t(*mb) << 20;
        c.hostBudgetAuto = false;
    }
    if (auto mb = integer(*t, "budgets.", "gpu_mb", 1, kMaxBudgetMb))
        c.gpuBudgetBytes = std::uint64_t(*mb) << 20;
}

void ConfigReader::readFrames(const toml::table& root, DaemonConfig& c) const {
    const toml::table* t = section(root, "frames");
    if (!t) return;
    const std::string p = "frames.";
    checkKeys(*t, p,
              {"rest_ms", "write_queue", "write_queue_mb", "max_frame_gsamples",
               "max_unsliced_gsamples", "slice_ms", "prefetch", "cluster_timeout_ms", "cache_mb",
               "interactive_ms"});
    assign(c.restMs, integer(*t, p, "rest_ms", 0, 60000));
    assign(c.writeQueueFrames, integer(*t, p, "write_queue", 1, 16));
    if (auto mb = integer(*t, p, "write_queue_mb", 1, 4096))
        c.writeQueueBytes = std::uint64_t(*mb) << 20;
    if (auto g = integer(*t, p, "max_frame_gsamples", 1, 65536))
        c.maxFrameSamples = std::uint64_t(*g) << 30;
    if (auto g = integer(*t, p, "max_unsliced_gsamples", 1, 65536))
        c.maxUnslicedSamples = std::uint64_t(*g) << 30;
    assign(c.sliceMs, integer(*t, p, "slice_ms", 10, 10000));
    assign(c.interactiveMs, integer(*t, p, "interactive_ms", 0, 10000));
    if (auto b = boolean(*t, "frames.", "prefetch")) c.prefetch = *b;
    assign(c.clusterTimeoutMs, integer(*t, p, "cluster_timeout_ms", 100, 600000));
    if (auto mb = integer(*t, p, "cache_mb", 0, kMaxBudgetMb))
        c.frameCacheBytes = std::uint64_t(*mb) << 20;
}

void ConfigReader::checkToken(const toml::table& root, const DaemonConfig& c) const {
    if (c.token.empty() && !c.loopbackOnly()) {
        const toml::node* at = root.at_path("server.token").node();
        if (!at) at = root.at_path("server.listen").node();
        fail(at ? at->source() : root.source(), "server.token",
             "required when listening on '" + c.listenHost +
                 "' (not loopback): clients from other machines must authenticate");
    }
    if (const auto web = c.webListen(); web && c.token.empty() && !isLoopback(web->first)) {
        const toml::node* at = root.at_path("server.web").node();
        fail(at ? at->source() : root.source(), "server.token",
             "required when serving the viewer on '" + web->first +
                 "' (not loopback): clients from other machines must authenticate");
    }
}

DaemonConfig ConfigReader::read(const toml::table& root) const {
    checkKeys(root, "", {"server", "timeouts", "budgets", "frames", "volume", "preset"});
    DaemonConfig c;
    c.source = mSource;
    c.storeDir = defaultStoreDir();
    readServer(root, c);
    readTimeouts(root, c);
    readBudgets(root, c);
    readFrames(root, c);
    readVolumes(root, c);
    readPresets(root, c);
    checkToken(root, c);
    return c;
}

} // namespace bc::server::detail
