#pragma once
// What brickcastd serves and how: listen address, authentication, limits, timeouts, memory
// budgets and the volume catalog. Read from TOML (configs/brickcastd.toml documents every
// key); the daemon's other parts take this struct, never the file.
#include <array>
#include <cstdint>
#include <optional>
#include <string>
#include <string_view>
#include <utility>
#include <vector>

namespace bc::server {

/// One volume a client can open by name.
struct CatalogEntry {
    std::string name;     ///< 1..64 of A-Z a-z 0-9 . _ -, not starting with '.'
    std::string store;    ///< a .bcs brick store, resolved against the config's folder; or empty
    std::string generate; ///< "phantom" | "vessels" | "checker" when store is empty
    std::array<std::uint64_t, 3> dims{}; ///< for generate: each 8..1024
    std::string description;
    /// For store: a missing store is logged and left out instead of stopping the daemon.
    bool optional = false;

    bool operator==(const CatalogEntry&) const = default;
};

/// A transfer-function preset the config adds to the built-in ones: clients name it in
/// SetTransferFunction; its file is read once, when the config is.
struct PresetEntry {
    std::string name; ///< as a volume name; not a built-in preset's
    std::string file; ///< the JSON file it was read from (resolved), for messages
    std::string json; ///< its text, checked to parse
    bool operator==(const PresetEntry&) const = default;
};

/// The "auto" host budget of this machine: brickstore::autoHostBudgetBytes of the memory the
/// process may use (brickstore::hostMemory(), read once and kept).
std::uint64_t autoHostBudgetBytes();

struct DaemonConfig {
    std::string source = "<embedded default>"; ///< what it was read from
    std::string file; ///< the file load() read (what SIGHUP re-reads); empty otherwise
    std::string listenHost = "127.0.0.1"; ///< without brackets: "::1"
    std::uint16_t listenPort = 7411;      ///< 0 = any free port (tests)
    std::string token;                    ///< empty = no auth; required off loopback
    std::string metricsHost;              ///< empty = no metrics endpoint; loopback
    std::uint16_t metricsPort = 0;
    /// The browser viewer's HTTP and WebSocket address: "auto" (listen's host, listen's port
    /// + 1, or any free port when listen's is 0), "HOST:PORT", or "" for none. See webListen().
    std::string web = "auto";
    std::uint32_t maxClients = 16; ///< that have completed their handshake
    /// Connections still in their handshake (Hello, Auth), a cap of their own: the oldest is
    /// cut when one more arrives.
    std::uint32_t maxUnauthenticated = 32;
    /// Host names the viewer answers to besides the listen address's own (and, on loopback,
    /// localhost): its name behind a reverse proxy or in DNS. Any other Host is refused (403),
    /// so a page whose name was rebound to this address cannot read it.
    std::vector<std::string> webHosts;
    /// PEM certificate chain and private key: with them, the protocol's and the viewer's
    /// addresses speak TLS only (TLS 1.2 and later). Both or neither.
    std::string tlsCert, tlsKey;
    std::uint32_t handshakeTimeoutMs = 5000;
    std::uint32_t readTimeoutMs = 10000;
    std::uint32_t idleTimeoutMs = 300000;
    std::uint32_t writeTimeoutMs = 10000;
    /// Host memory for decompressed bricks, all volumes together. [budgets] host_mb = "auto"
    /// (the default) is resolved when the configuration is read: autoHostBudgetBytes().
    std::uint64_t hostBudgetBytes = autoHostBudgetBytes();
    bool hostBudgetAuto = true; ///< hostBudgetBytes came from "auto" (for the log)
    std::uint64_t gpuBudgetBytes = 512ull << 20;
    std::uint32_t restMs = 150;                    ///< camera at rest this long -> a refined frame
    std::uint32_t writeQueueFrames = 2;            ///< per session; older frames are dropped
    std::uint64_t writeQueueBytes = 16ull << 20;   ///< per session (one larger frame still goes)
    std::uint64_t maxFrameSamples = 64ull << 30;   ///< a frame's cost cap (RenderServiceConfig)
    std::uint64_t maxUnslicedSamples = 4ull << 30; ///< for renderers that cannot slice
    std::uint32_t sliceMs = 50;                    ///< target length of one slice of a long frame
    /// While a camera moves, the time a frame should take (server/InteractiveBudget.h); 0: frames
    /// are drawn at half size, whatever they take. 66 ms: docs/benchmarks/budgets.md.
    std::uint32_t interactiveMs = 66;
    bool prefetch = true; ///< bricks of each GPU session's predicted next view, while idle
    /// Encoded frames kept for identical requests of any session (server/FrameCache.h); 0: off.
    std::uint64_t frameCacheBytes = 64ull << 20;
    /// Under MPI: how long rank 0 waits for any rank's part of a frame.
    std::uint32_t clusterTimeoutMs = 30000;
    std::string storeDir; ///< where generated volumes are ingested
    std::vector<CatalogEntry> volumes;
    std::vector<PresetEntry> presets; ///< [[preset]]: beside the built-in ones
    /// Set by the command line's overrides (setListen, setMetrics, setWeb): a reload of the
    /// file keeps them.
    bool listenOverridden = false, metricsOverridden = false, webOverridden = false;

    bool operator==(const DaemonConfig&) const = default;

    /// Listens on "HOST:PORT" instead (a command-line override), keeping the token rule.
    /// @throw ConfigError naming sourceName when the text is bad or a token is missing.
    void setListen(const std::string& text, const std::string& sourceName);
    /// Serves metrics on "HOST:PORT" (a command-line override; loopback only).
    /// @throw ConfigError naming sourceName when the text is bad or not loopback.
    void setMetrics(const std::string& text, const std::string& sourceName);
    /// Serves the browser viewer on "HOST:PORT", "auto" or "" (none): a command-line override.
    /// @throw ConfigError naming sourceName when the text is bad or a token is missing.
    void setWeb(const std::string& text, const std::string& sourceName);
    /// The viewer's host and port as `web` resolves; nullopt when it is off.
    std::optional<std::pair<std::string, std::uint16_t>> webListen() const;
    /// Whether listenHost is a loopback address: 127.0.0.0/8, ::1 (also v4-mapped), localhost.
    bool loopbackOnly() const;
    /// The built-in configuration: loopback, no token, a generated 128^3 "phantom" and 160^3
    /// "vessels"; storeDir is the default cache folder.
    static DaemonConfig embeddedDefault();
    /// The embedded default as documented TOML text (what configs/brickcastd.toml holds).
    static std::string_view defaultToml();
    /// Parses and validates a configuration; relative paths are taken against baseDir.
    /// @throw ConfigError naming sourceName, line:column and the key: syntax errors, unknown
    /// keys, wrong types, out-of-range values, bad listen syntax, duplicate volume names, an
    /// entry with both or neither of store/generate, no token for a non-loopback listen, a
    /// preset whose file is unreadable, over 1 MiB or not a transfer function, or whose name
    /// is a built-in preset's or another preset's.
    static DaemonConfig parse(const std::string& tomlText, const std::string& sourceName,
                              const std::string& baseDir);
    /// Reads and parses a file; relative paths in it are taken against its folder.
    /// @throw ConfigError if it is unreadable or invalid
    static DaemonConfig load(const std::string& path);
};

/// 127.0.0.0/8, ::1 (also v4-mapped) or localhost.
bool isLoopback(const std::string& host);

/// How "auto" came out, for the daemon's log: "6144 MiB (a quarter of 24.0 GiB of physical
/// memory)" or "... of the 2.0 GiB limit of /sys/fs/cgroup/...".
std::string describeHostBudget(const DaemonConfig& config);

/// The default store folder: $XDG_CACHE_HOME/brickcast, or /tmp/brickcast-<uid> without it.
std::string defaultStoreDir();

} // namespace bc::server
