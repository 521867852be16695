#include "server/DaemonConfig.h"

#include "brickstore/HostMemory.h"
#include "brickstore/Readers.h"
#include "protocol/Wire.h"
#include "render/Error.h"
#include "render/TransferFunction.h"
#include "server/Error.h"

#include <algorithm>
#include <arpa/inet.h>
#include <cctype>
#include <cerrno>
#include <cstdio>
#include <cstdlib>
#include <cstring>
#include <filesystem>
#include <fstream>
#include <map>
#include <optional>
#include <sstream>
#include <toml++/toml.h>
#include <unistd.h>

namespace bc::server {
namespace {

// The embedded default: the text of configs/brickcastd.toml (DaemonConfigTest checks that
// the two parse to the same configuration).
constexpr std::string_view kDefaultToml = R"toml(
# brickcastd configuration: the built-in default, every key documented.
# Run `brickcastd --config FILE`. Unknown keys are errors (a typo is never ignored); a key
# left out keeps the value shown here. Relative paths are taken against this file's folder.

[server]
# HOST:PORT to accept clients on; IPv6 in brackets ("[::1]:7411"); port 0 = any free port.
listen = "127.0.0.1:7411"
# Shared secret clients send in Auth (1..256 bytes); "" = no authentication. Required
# whenever listen is not loopback (127.0.0.0/8, ::1, localhost).
token = ""
# Clients served at once (1..1024) once they have completed Hello (and Auth); one more is
# answered Busy and closed.
max_clients = 16
# Connections still in their handshake (1..1024), counted apart from max_clients: one more
# cuts the oldest of them, so connections that never authenticate keep nobody out.
max_unauthenticated = 32
# Folder where generated volumes are ingested as brick stores; "" = $XDG_CACHE_HOME/brickcast,
# or /tmp/brickcast-<uid> without XDG_CACHE_HOME.
store_dir = ""
# HOST:PORT of the metrics endpoint: GET /metrics answers with every counter in the
# Prometheus text format (no authentication, so loopback only); "" = no endpoint.
metrics = ""
# HOST:PORT of the browser viewer (HTTP and WebSocket, same token rule as listen); "auto" =
# listen's host and port + 1 (any free port when listen's port is 0); "" = no viewer.
web = "auto"
# Host names the viewer also answers to (in the browser's Host and Origin), besides the
# address it listens on (and localhost when that is loopback): its DNS name, or its name
# behind a reverse proxy, e.g. ["viewer.example.org"]. Any other name is refused (403): a web
# page whose name was rebound to this address cannot reach the daemon.
web_hosts = []
# PEM files of a certificate chain and its private key: with them both addresses speak TLS
# only (the viewer is https://, its WebSocket wss://); "" = plain TCP and HTTP. Both or
# neither. Behind an SSH tunnel or a TLS-terminating reverse proxy, leave them empty.
tls_cert = ""
tls_key = ""

[timeouts]
# Hello (and Auth when required) must arrive within this long of connecting.
handshake_ms = 5000
# A message, once its first byte has arrived, must arrive completely within this long.
read_ms = 10000
# A session with no message for this long is sent Bye (idle timeout) and closed.
idle_ms = 300000
# A client that takes longer than this to accept one message is disconnected.
write_ms = 10000

[budgets]
# Host memory for decompressed bricks, shared by all sessions (MiB, 1..1048576), or "auto":
# a quarter of the memory the daemon may use (physical memory, or its control group's limit
# where lower), at least 256 MiB. The log's first lines say what "auto" came to.
host_mb = "auto"
# GPU memory for the brick atlas (MiB, 1..1048576); bounds the automatic level choice.
gpu_mb = 512

[frames]
# Under adaptive quality, a camera at rest this long (after its last move and after its last
# frame went out) gets one refined frame (0..60000 ms).
rest_ms = 150
# Encoded frames queued per session (1..16); a slow reader gets the newest, older are dropped.
write_queue = 2
# ... and at most this many MiB of them (1..4096): a session that does not read holds no more
# (one frame larger than this still goes out, alone).
write_queue_mb = 16
# A frame's cost is its pixels times the samples of its longest ray (the level's diagonal over
# the step), or for the splatters the level's voxels. A request over this many Gi samples
# (1..65536) is answered OutOfRange naming this key: 64 is about an hour of the CPU reference
# renderer on two cores.
max_frame_gsamples = 64
# The same for a renderer that draws whole frames only and so cannot be sliced (none of the
# built-in ones: gpu, cpu, reference, splat and splat-gpu all draw in slices) (1..65536).
max_unsliced_gsamples = 4
# A frame that would take longer than this is drawn in slices of about this long (10..10000
# ms); sessions take turns between slices, and a frame whose session has gone or whose camera
# has moved on is dropped at the next slice. A refined frame beside sessions whose cameras move
# takes shorter slices: their share of interactive_ms (66 / (n + 1) ms beside n, at least 10).
slice_ms = 50
# While a camera moves, the time a frame should take (0..10000 ms; a session may ask for its
# own, SetFrameBudget): each such frame is drawn at the finest pyramid level whose bricks fit
# the volume's host cache share, then the requested size divided by 1, 2, 3, 4, 6 or 8,
# whichever the frames drawn so far predict to fit (sessions moving at once share it), and
# scaled back up. 66 ms (15 frames/s) is what the measurements chose (docs/benchmarks/
# budgets.md). 0: half size, whatever it takes.
interactive_ms = 66
# While the render thread is idle, upload the bricks of each GPU session's next view (its
# camera's motion extrapolated one frame) that the GPU pool lacks, without evicting any brick
# of its last frame.
prefetch = true
# Encoded frames kept, in MiB (0..1048576; 0 turns the cache off), for any session that asks
# for the same frame again: same store, camera, transfer function, options and codec (a second
# viewer of a view, a client that reconnects). Such a frame is sent without drawing it
# (FrameHeader cached = 1). Least recently used frames go first; a frame over a quarter of
# this is not kept.
cache_mb = 64
# Under mpirun (several ranks): how long rank 0 waits for another rank's part of a frame
# (100..600000 ms). A rank that has not answered by then fails the frame (RenderFailed, naming
# the rank) and every cluster frame after it; restart the job. Ignored by one process.
cluster_timeout_ms = 30000

# The catalog: one [[volume]] per name clients may open. Each has either store (a .bcs brick
# store made by `brickcast ingest`) or generate (a synthetic volume, ingested on first use
# into store_dir), never both.
[[volume]]
# What clients ask for: 1..64 of A-Z a-z 0-9 . _ -, not starting with '.'.
name = "phantom"
# Synthetic kind: "phantom", "vessels" or "checker".
generate = "phantom"
# Size of the generated volume in voxels, x y z, each 8..1024.
dims = [128, 128, 128]
# Free text for people reading the configuration and the daemon's log.
description = "synthetic CT-like head, 16-bit, dense"

[[volume]]
name = "vessels"
generate = "vessels"
dims = [160, 160, 160]
description = "synthetic branching vessel tree, 8-bit, 1-5% occupied"

# An ingested scan is served like this. A store that is missing or fails its header check
# stops the daemon at start, naming it; optional = true accepts a missing one (logged, left
# out until a reload finds it). SIGHUP re-reads this file: volumes added, removed and
# reopened (their store file changed) are logged; sessions on unchanged volumes go on.
# [[volume]]
# name = "cthead"
# store = "stores/cthead.bcs"
# description = "Stanford CT head, 256x256x113"
# optional = false

# Transfer-function presets clients may name in SetTransferFunction, beside the built-in ones
# (ct-bone, ct-skin, mr, smoke, vessels). Each file is read once, at start-up; a client never
# names a file, only a preset.
# [[preset]]
# name = "my-bone"                  # as a volume name; not a built-in preset's
# file = "tf/my-bone.json"          # configs/tf/README.md has the format
)toml";

constexpr std::int64_t kMaxMs = 86'400'000; // a day
constexpr std::int64_t kMaxBudgetMb = 1 << 20;

std::string nodeTypeName(toml::node_type t) {
    std::ostringstream s;
    s << t;
    return s.str();
}

/// Most [[preset]] entries a config may add.
constexpr std::size_t kMaxPresets = 256;

/// Why `name` cannot be a catalog name (PROTOCOL.md "Limits"), or nothing.
std::optional<std::string> volumeNameProblem(const std::string& name) {
    if (name.empty() || name.size() > protocol::kMaxVolumeNameBytes)
        return "'" + name + "' must be 1.." + std::to_string(protocol::kMaxVolumeNameBytes) +
               " bytes";
    for (unsigned char c : name)
        if (!std::isalnum(c) && c != '.' && c != '_' && c != '-')
            return "'" + name + "' has a character outside A-Z a-z 0-9 . _ -";
    if (name.front() == '.') return "'" + name + "' starts with '.'";
    return std::nullopt;
}

bool isHostnameChar(unsigned char c) {
    return std::isalnum(c) || c == '.' || c == '-';
}

/// Why `host` is no IPv4 address or host name, or nothing.
std::optional<std::string> hostProblem(const std::string& host) {
    if (host.empty()) return "the host is empty (0.0.0.0 listens on every interface)";
    if (host.find(':') != std::string::npos)
        return "an IPv6 address goes in brackets, e.g. \"[::1]:7411\"";
    if (!std::all_of(host.begin(), host.end(), isHostnameChar) || host.front() == '-' ||
        host.front() == '.')
        return "'" + host + "' is neither an IPv4 address nor a host name";
    const bool numeric = std::all_of(host.begin(), host.end(),
                                     [](unsigned char c) { return std::isdigit(c) || c == '.'; });
    in_addr v4{};
    if (numeric && inet_pton(AF_INET, host.c_str(), &v4) != 1)
        return "'" + host + "' is not an IPv4 address";
    return std::nullopt;
}

/// Why `host` is no host name, IPv4 address or bracketed IPv6 address, or nothing.
std::optional<std::string> webHostProblem(const std::string& host) {
    if (host.size() > 2 && host.front() == '[' && host.back() == ']') {
        in6_addr v6{};
        if (inet_pton(AF_INET6, host.substr(1, host.size() - 2).c_str(), &v6) == 1)
            return std::nullopt;
        return "'" + host + "' is not an IPv6 address";
    }
    if (host.size() > 253) return "a host name is at most 253 bytes";
    if (host.find(':') != std::string::npos)
        return "'" + host + "': a host name without a port (an IPv6 address in brackets)";
    return hostProblem(host);
}

struct Listen {
    std::string host;
    std::uint16_t port = 0;
};

/// Splits "HOST:PORT" or "[IPV6]:PORT"; returns why not on failure.
std::optional<std::string> splitListen(const std::string& text, Listen& out) {
    const std::string usage = " (expected HOST:PORT, e.g. \"127.0.0.1:7411\" or \"[::1]:7411\")";
    std::size_t colon = 0;
    if (!text.empty() && text.front() == '[') {
        const std::size_t close = text.find(']');
        if (close == std::string::npos) return "'" + text + "' has no closing ']'" + usage;
        out.host = text.substr(1, close - 1);
        in6_addr v6{};
        if (inet_pton(AF_INET6, out.host.c_str(), &v6) != 1)
            return "'" + out.host + "' is not an IPv6 address";
        if (close + 1 >= text.size() || text[close + 1] != ':') return "no port" + usage;
        colon = close + 1;
    } else {
        colon = text.rfind(':');
        if (colon == std::string::npos) return "'" + text + "' has no port" + usage;
        out.host = text.substr(0, colon);
        if (auto why = hostProblem(out.host)) return why;
    }
    const std::string port = text.substr(colon + 1);
    if (port.empty() || port.size() > 5 ||
        !std::all_of(port.begin(), port.end(), [](unsigned char c) { return std::isdigit(c); }) ||
        std::stoul(port) > 65535)
        return "port '" + port + "' is not a number 0..65535";
    out.port = static_cast<std::uint16_t>(std::stoul(port));
    return std::nullopt;
}

/// Reads the sections of one document, throwing ConfigError at the first fault.
class Reader {
  public:
    Reader(const std::string& sourceName, const std::string& baseDir)
        : mSource(sourceName), mBaseDir(baseDir) {}

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

    void readServer(const toml::table& root, DaemonConfig& c) const;
    void readTimeouts(const toml::table& root, DaemonConfig& c) const;
    void readLimits(const toml::table& root, DaemonConfig& c) const;
    void readVolumes(const toml::table& root, DaemonConfig& c) const;
    void readPresets(const toml::table& root, DaemonConfig& c) const;
    PresetEntry readPreset(const toml::table& t, const std::string& prefix) const;
    CatalogEntry readVolume(const toml::table& t, const std::string& prefix) const;
    std::array<std::uint64_t, 3> readDims(const toml::table& t, const std::string& prefix) const;
    std::vector<std::string> readWebHosts(const toml::node& node) const;
    void readTls(const toml::table& server, DaemonConfig& c) const;

    std::string mSource;
    std::string mBaseDir;
};

template <class T> void assign(T& field, std::optional<std::int64_t> value) {
    if (value) field = static_cast<T>(*value);
}

std::string position(const std::string& source, const toml::source_region& at) {
    if (at.begin.line == 0) return source + ": ";
    return source + ":" + std::to_string(at.begin.line) + ":" + std::to_string(at.begin.column) +
           ": ";
}

void Reader::fail(const toml::source_region& at, const std::string& key,
                  const std::string& why) const {
    throw ConfigError(position(mSource, at) + key + ": " + why);
}

void Reader::checkKeys(const toml::table& t, const std::string& prefix,
                       std::initializer_list<std::string_view> known) const {
    for (auto&& [key, node] : t) {
        if (std::find(known.begin(), known.end(), key.str()) != known.end()) continue;
        std::string list;
        for (std::string_view k : known)
            list += (list.empty() ? "" : ", ") + std::string(k);
        fail(key.source(), prefix + std::string(key.str()), "unknown key (known: " + list + ")");
    }
}

const toml::table* Reader::section(const toml::table& root, const char* name) const {
    const toml::node* node = root.get(name);
    if (!node) return nullptr;
    if (!node->is_table())
        fail(node->source(), name,
             "expected a [" + std::string(name) + "] table, got " + nodeTypeName(node->type()));
    return node->as_table();
}

std::optional<std::int64_t> Reader::integer(const toml::table& t, const std::string& prefix,
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

std::optional<std::string> Reader::string(const toml::table& t, const std::string& prefix,
                                          const char* key) const {
    const toml::node* node = t.get(key);
    if (!node) return std::nullopt;
    const auto* v = node->as_string();
    if (!v)
        fail(node->source(), prefix + key, "expected a string, got " + nodeTypeName(node->type()));
    return v->get();
}

std::optional<bool> Reader::boolean(const toml::table& t, const std::string& prefix,
                                    const char* key) const {
    const toml::node* node = t.get(key);
    if (!node) return std::nullopt;
    const auto* v = node->as_boolean();
    if (!v)
        fail(node->source(), prefix + key,
             "expected true or false, got " + nodeTypeName(node->type()));
    return v->get();
}

std::string Reader::resolve(const std::string& path) const {
    std::filesystem::path p(path);
    if (p.is_relative()) p = std::filesystem::path(mBaseDir) / p;
    return p.lexically_normal().string();
}

void Reader::readServer(const toml::table& root, DaemonConfig& c) const {
    const toml::table* t = section(root, "server");
    if (!t) return;
    checkKeys(*t, "server.",
              {"listen", "token", "max_clients", "max_unauthenticated", "store_dir", "metrics",
               "web", "web_hosts", "tls_cert", "tls_key"});
    if (auto listen = string(*t, "server.", "listen")) {
        Listen l;
        if (auto why = splitListen(*listen, l))
            fail(t->get("listen")->source(), "server.listen", *why);
        c.listenHost = l.host;
        c.listenPort = l.port;
    }
    if (auto token = string(*t, "server.", "token")) {
        if (token->size() > protocol::kMaxTokenBytes)
            fail(t->get("token")->source(), "server.token",
                 "longer than " + std::to_string(protocol::kMaxTokenBytes) + " bytes");
        c.token = *token;
    }
    if (auto metrics = string(*t, "server.", "metrics"); metrics && !metrics->empty()) {
        Listen l;
        if (auto why = splitListen(*metrics, l))
            fail(t->get("metrics")->source(), "server.metrics", *why);
        if (!isLoopback(l.host))
            fail(t->get("metrics")->source(), "server.metrics",
                 "'" + l.host + "' is not loopback: the endpoint has no authentication");
        c.metricsHost = l.host;
        c.metricsPort = l.port;
    }
    if (auto web = string(*t, "server.", "web")) {
        Listen l;
        if (*web != "auto" && !web->empty())
            if (auto why = splitListen(*web, l)) fail(t->get("web")->source(), "server.web", *why);
        c.web = *web;
    }
    assign(c.maxClients, integer(*t, "server.", "max_clients", 1, 1024));
    assign(c.maxUnauthenticated, integer(*t, "server.", "max_unauthenticated", 1, 1024));
    if (const toml::node* hosts = t->get("web_hosts")) c.webHosts = readWebHosts(*hosts);
    readTls(*t, c);
    if (auto dir = string(*t, "server.", "store_dir"); dir && !dir->empty())
        c.storeDir = resolve(*dir);
}

std::vector<std::string> Reader::readWebHosts(const toml::node& node) const {
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

void Reader::readTls(const toml::table& t, DaemonConfig& c) const {
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

void Reader::readTimeouts(const toml::table& root, DaemonConfig& c) const {
    const toml::table* t = section(root, "timeouts");
    if (!t) return;
    const std::string p = "timeouts.";
    checkKeys(*t, p, {"handshake_ms", "read_ms", "idle_ms", "write_ms"});
    assign(c.handshakeTimeoutMs, integer(*t, p, "handshake_ms", 1, kMaxMs));
    assign(c.readTimeoutMs, integer(*t, p, "read_ms", 1, kMaxMs));
    assign(c.idleTimeoutMs, integer(*t, p, "idle_ms", 1, kMaxMs));
    assign(c.writeTimeoutMs, integer(*t, p, "write_ms", 1, kMaxMs));
}

void Reader::readLimits(const toml::table& root, DaemonConfig& c) const {
    if (const toml::table* t = section(root, "budgets")) {
        checkKeys(*t, "budgets.", {"host_mb", "gpu_mb"});
        if (const toml::node* node = t->get("host_mb"); node && node->is_string()) {
            if (node->as_string()->get() != "auto")
                fail(node->source(), "budgets.host_mb",
                     "expected an integer (MiB) or \"auto\", got \"" + node->as_string()->get() +
                         "\"");
            c.hostBudgetBytes = autoHostBudgetBytes();
            c.hostBudgetAuto = true;
        } else if (auto mb = integer(*t, "budgets.", "host_mb", 1, kMaxBudgetMb)) {
            c.hostBudgetBytes = std::uint64_t(*mb) << 20;
            c.hostBudgetAuto = false;
        }
        if (auto mb = integer(*t, "budgets.", "gpu_mb", 1, kMaxBudgetMb))
            c.gpuBudgetBytes = std::uint64_t(*mb) << 20;
    }
    if (const toml::table* t = section(root, "frames")) {
        const std::string p = "frames.";
        checkKeys(*t, p,
                  {"rest_ms", "write_queue", "write_queue_mb", "max_frame_gsamples",
                   "max_unsliced_gsamples", "slice_ms", "prefetch", "cluster_timeout_ms",
                   "cache_mb", "interactive_ms"});
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
}

std::array<std::uint64_t, 3> Reader::readDims(const toml::table& t,
                                              const std::string& prefix) const {
    const toml::node* node = t.get("dims");
    if (!node) fail(t.source(), prefix + "dims", "a generated volume needs dims = [X, Y, Z]");
    const toml::array* a = node->as_array();
    if (!a || a->size() != 3)
        fail(node->source(), prefix + "dims",
             "expected an array of 3 integers, e.g. [128, 128, 128]");
    std::array<std::uint64_t, 3> dims{};
    for (std::size_t i = 0; i < 3; ++i) {
        const auto* v = (*a)[i].as_integer();
        if (!v || v->get() < 8 || v->get() > 1024)
            fail((*a)[i].source(), prefix + "dims",
                 "element " + std::to_string(i + 1) + " must be an integer 8..1024");
        dims[i] = std::uint64_t(v->get());
    }
    return dims;
}

CatalogEntry Reader::readVolume(const toml::table& t, const std::string& prefix) const {
    checkKeys(t, prefix, {"name", "store", "generate", "dims", "description", "optional"});
    CatalogEntry e;
    auto name = string(t, prefix, "name");
    if (!name) fail(t.source(), prefix + "name", "missing: every volume needs a name");
    if (auto why = volumeNameProblem(*name)) fail(t.get("name")->source(), prefix + "name", *why);
    e.name = *name;
    auto store = string(t, prefix, "store");
    auto generate = string(t, prefix, "generate");
    if (store && generate)
        fail(t.get("generate")->source(), prefix + "generate",
             "and store are both given: a volume is either a store or generated");
    if (!store && !generate)
        fail(t.source(), prefix + "store",
             "missing: give store (a .bcs path) or generate (a synthetic kind)");
    if (store) {
        if (store->empty()) fail(t.get("store")->source(), prefix + "store", "the path is empty");
        if (t.contains("dims"))
            fail(t.get("dims")->source(), prefix + "dims",
                 "only for generate: a store has its own");
        e.store = resolve(*store);
    } else {
        if (!brickstore::parseSynthKind(*generate))
            fail(t.get("generate")->source(), prefix + "generate",
                 "'" + *generate + "' is not one of phantom, vessels, checker");
        e.generate = *generate;
        e.dims = readDims(t, prefix);
    }
    e.description = string(t, prefix, "description").value_or("");
    if (auto optional = boolean(t, prefix, "optional")) {
        if (!store)
            fail(t.get("optional")->source(), prefix + "optional",
                 "only for store: a generated volume is made when missing");
        e.optional = *optional;
    }
    return e;
}

void Reader::readVolumes(const toml::table& root, DaemonConfig& c) const {
    const toml::node* node = root.get("volume");
    if (!node) fail(root.source(), "[[volume]]", "no volumes: the catalog needs at least one");
    const toml::array* list = node->as_array();
    if (!list || !list->is_array_of_tables())
        fail(node->source(), "volume", "expected [[volume]] tables");
    if (list->size() > protocol::kMaxVolumes)
        fail(node->source(), "[[volume]]",
             "more than " + std::to_string(protocol::kMaxVolumes) + " volumes");
    std::map<std::string, std::size_t> seen;
    for (std::size_t i = 0; i < list->size(); ++i) {
        const toml::table& t = *(*list)[i].as_table();
        const std::string prefix = "[[volume]] " + std::to_string(i + 1) + " .";
        CatalogEntry e = readVolume(t, prefix);
        if (auto [it, fresh] = seen.emplace(e.name, i + 1); !fresh)
            fail(t.get("name")->source(), prefix + "name",
                 "'" + e.name + "' is already [[volume]] " + std::to_string(it->second));
        c.volumes.push_back(std::move(e));
    }
}

/// Preset files are a few kilobytes; the config refuses anything far larger.
constexpr std::uintmax_t kMaxPresetFileBytes = 1u << 20;

PresetEntry Reader::readPreset(const toml::table& t, const std::string& prefix) const {
    checkKeys(t, prefix, {"name", "file"});
    PresetEntry e;
    auto name = string(t, prefix, "name");
    if (!name) fail(t.source(), prefix + "name", "missing: every preset needs a name");
    if (auto why = volumeNameProblem(*name)) fail(t.get("name")->source(), prefix + "name", *why);
    if (render::TransferFunction::isPreset(*name))
        fail(t.get("name")->source(), prefix + "name",
             "'" + *name + "' is a built-in preset; give yours another name");
    e.name = *name;
    auto file = string(t, prefix, "file");
    if (!file || file->empty())
        fail(file ? t.get("file")->source() : t.source(), prefix + "file",
             "missing: a transfer-function JSON file (configs/tf/README.md)");
    e.file = resolve(*file);
    const auto at = t.get("file")->source();
    std::error_code ec;
    if (!std::filesystem::is_regular_file(e.file, ec))
        fail(at, prefix + "file", "'" + e.file + "' is not a readable file");
    const auto bytes = std::filesystem::file_size(e.file, ec);
    if (ec || bytes > kMaxPresetFileBytes)
        fail(at, prefix + "file",
             "'" + e.file + "' " +
                 (ec ? ec.message() : "is over " + std::to_string(kMaxPresetFileBytes) + " bytes"));
    std::ifstream in(e.file, std::ios::binary);
    std::ostringstream text;
    text << in.rdbuf();
    if (!in) fail(at, prefix + "file", "'" + e.file + "' cannot be read");
    e.json = text.str();
    try { // placed for a stand-in volume: every placement works, so only the text can fail
        render::TransferFunction::parse(e.json, e.file, render::VolumeValueStats{0.0, 1.0, {1, 1}});
    } catch (const render::RenderInputError& err) {
        fail(at, prefix + "file", err.what());
    }
    return e;
}

void Reader::readPresets(const toml::table& root, DaemonConfig& c) const {
    const toml::node* node = root.get("preset");
    if (!node) return;
    const toml::array* list = node->as_array();
    if (!list || !list->is_array_of_tables())
        fail(node->source(), "preset", "expected [[preset]] tables");
    if (list->size() > kMaxPresets)
        fail(node->source(), "[[preset]]", "more than " + std::to_string(kMaxPresets) + " presets");
    std::map<std::string, std::size_t> seen;
    for (std::size_t i = 0; i < list->size(); ++i) {
        const toml::table& t = *(*list)[i].as_table();
        const std::string prefix = "[[preset]] " + std::to_string(i + 1) + " .";
        PresetEntry e = readPreset(t, prefix);
        if (auto [it, fresh] = seen.emplace(e.name, i + 1); !fresh)
            fail(t.get("name")->source(), prefix + "name",
                 "'" + e.name + "' is already [[preset]] " + std::to_string(it->second));
        c.presets.push_back(std::move(e));
    }
}

DaemonConfig Reader::read(const toml::table& root) const {
    checkKeys(root, "", {"server", "timeouts", "budgets", "frames", "volume", "preset"});
    DaemonConfig c;
    c.source = mSource;
    c.storeDir = defaultStoreDir();
    readServer(root, c);
    readTimeouts(root, c);
    readLimits(root, c);
    readVolumes(root, c);
    readPresets(root, c);
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
    return c;
}

} // namespace

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
    return kDefaultToml.substr(1);
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
        throw ConfigError(position(sourceName, e.source()) +
                          "syntax: " + std::string(e.description()));
    }
    return Reader(sourceName, baseDir).read(root);
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
