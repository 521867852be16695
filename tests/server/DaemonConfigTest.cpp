// The daemon configuration: the embedded default and the shipped file agree, every bad input
// names the file, the position and the key, paths resolve against the config's folder.
#include "server/DaemonConfig.h"
#include "brickstore/HostMemory.h"
#include "server/ConfigChanges.h"
#include "server/Error.h"

#include "tests/TestSupport.h"

#include <gtest/gtest.h>

#include <cstdlib>
#include <string>
#include <unistd.h>

namespace bc::server {
namespace {

const char* kVolume = "[[volume]]\nname = \"p\"\ngenerate = \"phantom\"\ndims = [16, 16, 16]\n";

DaemonConfig parseText(const std::string& text, const std::string& baseDir = "/cfg") {
    return DaemonConfig::parse(text, "bad.toml", baseDir);
}

/// The ConfigError text of parsing `text`, or "" when it parses.
std::string errorOf(const std::string& text) {
    try {
        parseText(text);
    } catch (const ConfigError& e) {
        return e.what();
    }
    return "";
}

TEST(DaemonConfigTest, EmbeddedDefaultParsesAndValidates) {
    const DaemonConfig c = DaemonConfig::embeddedDefault();
    EXPECT_EQ(c.source, "<embedded default>");
    EXPECT_EQ(c.listenHost, "127.0.0.1");
    EXPECT_EQ(c.listenPort, 7411);
    EXPECT_TRUE(c.token.empty());
    EXPECT_TRUE(c.loopbackOnly());
    EXPECT_EQ(c.storeDir, defaultStoreDir());
    ASSERT_EQ(c.volumes.size(), 2u);
    EXPECT_EQ(c.volumes[0].name, "phantom");
    EXPECT_EQ(c.volumes[0].generate, "phantom");
    EXPECT_EQ(c.volumes[0].dims, (std::array<std::uint64_t, 3>{128, 128, 128}));
    EXPECT_EQ(c.volumes[1].name, "vessels");
    EXPECT_EQ(c.volumes[1].dims, (std::array<std::uint64_t, 3>{160, 160, 160}));
    EXPECT_TRUE(c.volumes[0].store.empty());
    // Every other field is the struct's default: the text documents the defaults.
    DaemonConfig defaults;
    defaults.storeDir = c.storeDir;
    defaults.volumes = c.volumes;
    EXPECT_EQ(c, defaults);
}

TEST(DaemonConfigTest, ShippedConfigFileEqualsTheEmbeddedDefault) {
    const std::string path = std::string(BC_CONFIGS_DIR) + "/brickcastd.toml";
    DaemonConfig file = DaemonConfig::load(path);
    EXPECT_EQ(file.source, path);
    EXPECT_EQ(file.file, path); // what SIGHUP re-reads
    file.source = "<embedded default>";
    file.file.clear();
    EXPECT_EQ(file, DaemonConfig::embeddedDefault());
    // Byte for byte, comments included: --print-default-config prints what the file says.
    const auto bytes = bc::test::readFile(path);
    EXPECT_EQ(std::string(bytes.begin(), bytes.end()), DaemonConfig::defaultToml());
}

// host_mb = "auto" (the default) is a quarter of the memory the daemon may use, at least
// 256 MiB, fixed when the configuration is read; a number of MiB overrides it.
TEST(DaemonConfigTest, HostBudgetIsAQuarterOfTheMachinesMemoryUnlessGiven) {
    const auto memory = bc::brickstore::hostMemory();
    ASSERT_GT(memory.physicalBytes, 0u) << "sysconf says how much memory there is on Linux";
    const DaemonConfig byDefault = parseText(kVolume);
    EXPECT_TRUE(byDefault.hostBudgetAuto);
    EXPECT_EQ(byDefault.hostBudgetBytes,
              std::max<std::uint64_t>(256ull << 20, memory.perProcessBytes() / 4 >> 20 << 20));
    const DaemonConfig spelt = parseText(std::string("[budgets]\nhost_mb = \"auto\"\n") + kVolume);
    EXPECT_EQ(spelt, byDefault);
    const DaemonConfig given = parseText(std::string("[budgets]\nhost_mb = 3\n") + kVolume);
    EXPECT_FALSE(given.hostBudgetAuto);
    EXPECT_EQ(given.hostBudgetBytes, 3ull << 20);
    EXPECT_EQ(describeHostBudget(given), "3 MiB (budgets.host_mb)");
    EXPECT_NE(describeHostBudget(byDefault).find("(auto: a quarter of "), std::string::npos)
        << describeHostBudget(byDefault);
}

TEST(DaemonConfigTest, OmittedKeysKeepTheirDefaults) {
    const DaemonConfig c = parseText(std::string("[server]\nmax_clients = 3\n") + kVolume);
    EXPECT_EQ(c.maxClients, 3u);
    EXPECT_EQ(c.listenPort, 7411);
    EXPECT_EQ(c.idleTimeoutMs, 300000u);
    EXPECT_EQ(c.gpuBudgetBytes, 512ull << 20);
    EXPECT_EQ(c.writeQueueFrames, 2u);
}

TEST(DaemonConfigTest, EveryKeyIsRead) {
    const DaemonConfig c = parseText(std::string(R"(
[server]
listen = "[::1]:0"
token = "s3cret"
max_clients = 4
max_unauthenticated = 7
store_dir = "cache"
metrics = "127.0.0.1:9100"
web_hosts = ["Viewer.Example.org", "10.1.2.3", "[fe80::1]"]
[timeouts]
handshake_ms = 1
read_ms = 2
idle_ms = 3
write_ms = 4
[budgets]
host_mb = 5
gpu_mb = 6
[frames]
rest_ms = 0
write_queue = 16
prefetch = false
cache_mb = 0
interactive_ms = 40
)") + kVolume + "description = \"d\"\n");
    EXPECT_EQ(c.listenHost, "::1");
    EXPECT_EQ(c.listenPort, 0);
    EXPECT_EQ(c.token, "s3cret");
    EXPECT_EQ(c.maxClients, 4u);
    EXPECT_EQ(c.maxUnauthenticated, 7u);
    EXPECT_EQ(c.webHosts,
              (std::vector<std::string>{"viewer.example.org", "10.1.2.3", "[fe80::1]"}));
    EXPECT_EQ(c.storeDir, "/cfg/cache");
    EXPECT_EQ(c.metricsHost, "127.0.0.1");
    EXPECT_EQ(c.metricsPort, 9100);
    EXPECT_EQ(c.handshakeTimeoutMs, 1u);
    EXPECT_EQ(c.readTimeoutMs, 2u);
    EXPECT_EQ(c.idleTimeoutMs, 3u);
    EXPECT_EQ(c.writeTimeoutMs, 4u);
    EXPECT_EQ(c.hostBudgetBytes, 5ull << 20);
    EXPECT_EQ(c.gpuBudgetBytes, 6ull << 20);
    EXPECT_EQ(c.restMs, 0u);
    EXPECT_EQ(c.writeQueueFrames, 16u);
    EXPECT_FALSE(c.prefetch);
    EXPECT_EQ(c.frameCacheBytes, 0u);
    EXPECT_EQ(c.interactiveMs, 40u);
    EXPECT_EQ(c.volumes.at(0).description, "d");
}

TEST(DaemonConfigTest, ErrorTextIsFileLineColumnKeyWhy) {
    const std::string text = std::string(kVolume) + "\n[[volume]]\n  name = '../x'\n";
    EXPECT_EQ(
        errorOf(text),
        "bad.toml:7:10: [[volume]] 2 .name: '../x' has a character outside A-Z a-z 0-9 . _ -");
}

struct BadCase {
    const char* what;
    std::string text;
    std::vector<std::string> mentions; ///< besides "bad.toml"
    int line = 0;                      ///< 0: no position to check
};

std::vector<BadCase> badCases() {
    const std::string v = kVolume;
    const std::string gen = "generate = \"phantom\"\ndims = [16, 16, 16]\n";
    return {
        {"syntax", "[server\nlisten = 1\n", {"syntax"}, 1},
        {"syntax in value", v + "[server]\nmax_clients = = 3\n", {"syntax"}, 6},
        {"unknown section", v + "[srever]\n", {"srever", "unknown key", "server"}, 5},
        {"unknown key",
         "[server]\nlisen = \"x\"\n" + v,
         {"server.lisen", "unknown key", "listen"},
         2},
        {"unknown volume key", v + "dim = [1]\n", {"[[volume]] 1 .dim", "unknown key"}, 5},
        {"string for integer",
         "[server]\nmax_clients = \"16\"\n" + v,
         {"server.max_clients", "expected an integer, got string"},
         2},
        {"float for integer",
         "[timeouts]\nhandshake_ms = 5000.0\n" + v,
         {"timeouts.handshake_ms", "floating-point"},
         2},
        {"integer for string",
         "[server]\nlisten = 7411\n" + v,
         {"server.listen", "expected a string"},
         2},
        {"section not a table", "server = 3\n" + v, {"server", "expected a [server] table"}, 1},
        {"volume not tables", "volume = 3\n", {"volume", "expected [[volume]] tables"}, 1},
        {"no volumes", "[server]\n", {"[[volume]]", "at least one"}},
        {"max_clients 0",
         "[server]\nmax_clients = 0\n" + v,
         {"server.max_clients", "0 is outside 1..1024"},
         2},
        {"max_clients 1025", "[server]\nmax_clients = 1025\n" + v, {"1025 is outside 1..1024"}, 2},
        {"negative rest",
         "[frames]\nrest_ms = -1\n" + v,
         {"frames.rest_ms", "-1 is outside 0..60000"},
         2},
        {"write_queue 17", "[frames]\nwrite_queue = 17\n" + v, {"frames.write_queue", "1..16"}, 2},
        {"negative cache", "[frames]\ncache_mb = -1\n" + v, {"frames.cache_mb", "outside 0.."}, 2},
        {"interactive_ms 10001",
         "[frames]\ninteractive_ms = 10001\n" + v,
         {"frames.interactive_ms", "10001 is outside 0..10000"},
         2},
        {"host_mb 0", "[budgets]\nhost_mb = 0\n" + v, {"budgets.host_mb", "outside 1.."}, 2},
        {"host_mb a word",
         "[budgets]\nhost_mb = \"lots\"\n" + v,
         {"budgets.host_mb", "an integer (MiB) or \"auto\"", "\"lots\""},
         2},
        {"host_mb a float", "[budgets]\nhost_mb = 1.5\n" + v, {"budgets.host_mb", "integer"}, 2},
        {"idle 0", "[timeouts]\nidle_ms = 0\n" + v, {"timeouts.idle_ms", "outside 1.."}, 2},
        {"long token",
         "[server]\ntoken = \"" + std::string(257, 'a') + "\"\n" + v,
         {"server.token", "longer than 256"},
         2},
        {"duplicate name", v + v, {"[[volume]] 2 .name", "'p' is already [[volume]] 1"}, 6},
        {"store and generate", v + "store = \"p.bcs\"\n", {"[[volume]] 1 .generate", "both"}, 3},
        {"neither", v + "[[volume]]\nname = \"q\"\n", {"[[volume]] 2 .store", "missing"}, 5},
        {"no name", "[[volume]]\n" + gen, {"[[volume]] 1 .name", "missing"}, 1},
        {"name with slash",
         "[[volume]]\nname = \"../x\"\n" + gen,
         {"[[volume]] 1 .name", "'../x' has a character outside"},
         2},
        {"name with dot", "[[volume]]\nname = \".x\"\n" + gen, {".name", "starts with '.'"}, 2},
        {"name too long",
         "[[volume]]\nname = \"" + std::string(65, 'n') + "\"\n" + gen,
         {".name", "1..64 bytes"},
         2},
        {"empty name", "[[volume]]\nname = \"\"\n" + gen, {".name", "1..64 bytes"}, 2},
        {"unknown kind",
         "[[volume]]\nname = \"x\"\ngenerate = \"sphere\"\ndims = [8, 8, 8]\n",
         {"[[volume]] 1 .generate", "'sphere' is not one of phantom, vessels, checker"},
         3},
        {"no dims",
         "[[volume]]\nname = \"x\"\ngenerate = \"checker\"\n",
         {".dims", "needs dims"},
         1},
        {"dims too small",
         "[[volume]]\nname = \"x\"\ngenerate = \"checker\"\ndims = [8, 7, 8]\n",
         {".dims", "element 2", "8..1024"},
         4},
        {"dims too large",
         "[[volume]]\nname = \"x\"\ngenerate = \"checker\"\ndims = [8, 8, 1025]\n",
         {".dims", "element 3"},
         4},
        {"two dims",
         "[[volume]]\nname = \"x\"\ngenerate = \"checker\"\ndims = [8, 8]\n",
         {".dims", "array of 3 integers"},
         4},
        {"dims for a store",
         "[[volume]]\nname = \"x\"\nstore = \"x.bcs\"\ndims = [8, 8, 8]\n",
         {".dims", "only for generate"},
         4},
        {"empty store", "[[volume]]\nname = \"x\"\nstore = \"\"\n", {".store", "empty"}, 3},
        {"token off loopback",
         "[server]\nlisten = \"0.0.0.0:7411\"\n" + v,
         {"server.token", "required", "0.0.0.0"},
         2},
        {"empty token off loopback",
         "[server]\nlisten = \"10.1.2.3:7411\"\ntoken = \"\"\n" + v,
         {"server.token", "required"},
         3},
    };
}

TEST(DaemonConfigTest, EveryBadInputNamesFileKeyAndLine) {
    for (const BadCase& c : badCases()) {
        const std::string message = errorOf(c.text);
        ASSERT_FALSE(message.empty()) << c.what << ": parsed without error";
        EXPECT_EQ(message.rfind("bad.toml:", 0), 0u) << c.what << ": " << message;
        for (const std::string& m : c.mentions)
            EXPECT_NE(message.find(m), std::string::npos)
                << c.what << ": '" << message << "' does not mention '" << m << "'";
        if (c.line) {
            EXPECT_EQ(message.rfind("bad.toml:" + std::to_string(c.line) + ":", 0), 0u)
                << c.what << ": " << message;
        }
    }
}

TEST(DaemonConfigTest, BadListenSyntaxIsNamed) {
    const char* bad[][2] = {
        {"127.0.0.1", "has no port"},
        {"::1:7411", "in brackets"},
        {"[::1", "no closing ']'"},
        {"[::1]7411", "no port"},
        {"[zz]:7411", "'zz' is not an IPv6 address"},
        {"[]:7411", "is not an IPv6 address"},
        {"127.0.0.1:99999", "port '99999'"},
        {"127.0.0.1:", "port ''"},
        {"127.0.0.1:7a", "port '7a'"},
        {":7411", "the host is empty"},
        {"300.1.1.1:7411", "not an IPv4 address"},
        {"my host:7411", "neither an IPv4 address nor a host name"},
    };
    for (auto& [listen, why] : bad) {
        const std::string message =
            errorOf("[server]\nlisten = \"" + std::string(listen) + "\"\n" + kVolume);
        EXPECT_NE(message.find("bad.toml:2:10: server.listen: "), std::string::npos) << message;
        EXPECT_NE(message.find(why), std::string::npos) << listen << ": " << message;
    }
}

TEST(DaemonConfigTest, TokenRequiredOnlyOffLoopback) {
    auto listen = [](const std::string& l, const std::string& token) {
        return parseText("[server]\nlisten = \"" + l + "\"\ntoken = \"" + token + "\"\n" + kVolume);
    };
    EXPECT_THROW(listen("0.0.0.0:7411", ""), ConfigError);
    EXPECT_THROW(listen("[::]:7411", ""), ConfigError);
    EXPECT_THROW(listen("example.org:7411", ""), ConfigError);
    const DaemonConfig open = listen("0.0.0.0:7411", "t0ken");
    EXPECT_EQ(open.token, "t0ken");
    EXPECT_FALSE(open.loopbackOnly());
    EXPECT_EQ(listen("127.0.0.1:7411", "").listenHost, "127.0.0.1");
    const DaemonConfig v6 = listen("[::1]:7411", "");
    EXPECT_EQ(v6.listenHost, "::1");
    EXPECT_EQ(v6.listenPort, 7411);
    EXPECT_EQ(listen("localhost:0", "").listenPort, 0);
}

// The metrics endpoint has no authentication: loopback only, from the file and --metrics.
TEST(DaemonConfigTest, MetricsAddressIsLoopbackOnlyAndNamed) {
    auto metrics = [](const std::string& m) {
        return errorOf("[server]\nmetrics = \"" + m + "\"\n" + kVolume);
    };
    EXPECT_EQ(metrics("127.0.0.1:0"), "");
    EXPECT_EQ(metrics(""), "");
    const std::string open = metrics("0.0.0.0:9100");
    EXPECT_NE(open.find("bad.toml:2:"), std::string::npos) << open;
    EXPECT_NE(open.find("server.metrics"), std::string::npos) << open;
    EXPECT_NE(open.find("not loopback"), std::string::npos) << open;
    EXPECT_NE(metrics("9100").find("server.metrics"), std::string::npos);
    EXPECT_TRUE(DaemonConfig::embeddedDefault().metricsHost.empty()) << "off by default";
    DaemonConfig c = DaemonConfig::embeddedDefault();
    c.setMetrics("[::1]:9100", "--metrics");
    EXPECT_EQ(c.metricsHost, "::1");
    EXPECT_EQ(c.metricsPort, 9100);
    try {
        c.setMetrics("example.org:9100", "--metrics");
        ADD_FAILURE() << "no ConfigError";
    } catch (const ConfigError& e) {
        EXPECT_NE(std::string(e.what()).find("--metrics"), std::string::npos) << e.what();
    }
    EXPECT_EQ(c.metricsHost, "::1") << "a refused override changes nothing";
}

// The viewer's address: "auto" follows listen, "" is off, HOST:PORT as listen's syntax, and a
// non-loopback one needs the token as listen does.
TEST(DaemonConfigTest, WebAddressFollowsListenAndKeepsTheTokenRule) {
    using Where = std::optional<std::pair<std::string, std::uint16_t>>;
    auto web = [](const std::string& text) {
        return parseText("[server]\n" + text + kVolume).webListen();
    };
    EXPECT_EQ(DaemonConfig::embeddedDefault().web, "auto");
    EXPECT_EQ(DaemonConfig::embeddedDefault().webListen(), (Where{{"127.0.0.1", 7412}}));
    EXPECT_EQ(web("listen = \"[::1]:8000\"\n"), (Where{{"::1", 8001}}));
    EXPECT_EQ(web("listen = \"127.0.0.1:0\"\n"), (Where{{"127.0.0.1", 0}})) << "any free port";
    EXPECT_EQ(web("web = \"\"\n"), Where{}) << "off";
    EXPECT_EQ(web("web = \"127.0.0.1:9000\"\n"), (Where{{"127.0.0.1", 9000}}));
    const std::string bad = errorOf("[server]\nweb = \"9000\"\n" + std::string(kVolume));
    EXPECT_NE(bad.find("bad.toml:2:"), std::string::npos) << bad;
    EXPECT_NE(bad.find("server.web"), std::string::npos) << bad;
    const std::string open = errorOf("[server]\nweb = \"0.0.0.0:9000\"\n" + std::string(kVolume));
    EXPECT_NE(open.find("server.token"), std::string::npos) << open;
    EXPECT_NE(open.find("viewer"), std::string::npos) << open;
    EXPECT_EQ(errorOf("[server]\nweb = \"0.0.0.0:9000\"\ntoken = \"t\"\n" + std::string(kVolume)),
              "");
    DaemonConfig c = DaemonConfig::embeddedDefault();
    c.setWeb("", "--web");
    EXPECT_EQ(c.webListen(), Where{});
    try {
        c.setWeb("0.0.0.0:80", "--web");
        ADD_FAILURE() << "no ConfigError";
    } catch (const ConfigError& e) {
        EXPECT_NE(std::string(e.what()).find("--web"), std::string::npos) << e.what();
    }
    EXPECT_EQ(c.web, "") << "a refused override changes nothing";
}

TEST(DaemonConfigTest, LoopbackOnlyCases) {
    DaemonConfig c;
    auto loopback = [&](const char* host) {
        c.listenHost = host;
        return c.loopbackOnly();
    };
    for (const char* yes : {"127.0.0.1", "127.255.3.4", "::1", "0:0:0:0:0:0:0:1", "localhost",
                            "LocalHost", "::ffff:127.0.0.1"})
        EXPECT_TRUE(loopback(yes)) << yes;
    for (const char* no : {"0.0.0.0", "::", "128.0.0.1", "10.0.0.1", "192.168.1.2", "::2",
                           "::ffff:10.0.0.1", "example.org", "localhost.example.org", ""})
        EXPECT_FALSE(loopback(no)) << no;
}

TEST(DaemonConfigTest, RelativeStorePathsResolveAgainstBaseDir) {
    const std::string text = R"(
[server]
store_dir = "../cache"
[[volume]]
name = "a"
store = "stores/a.bcs"
[[volume]]
name = "b"
store = "../b.bcs"
[[volume]]
name = "c"
store = "/abs/c.bcs"
)";
    const DaemonConfig c = parseText(text, "/data/configs");
    EXPECT_EQ(c.storeDir, "/data/cache");
    EXPECT_EQ(c.volumes.at(0).store, "/data/configs/stores/a.bcs");
    EXPECT_EQ(c.volumes.at(1).store, "/data/b.bcs");
    EXPECT_EQ(c.volumes.at(2).store, "/abs/c.bcs");
    EXPECT_TRUE(c.volumes.at(0).generate.empty());
}

TEST(DaemonConfigTest, LoadResolvesAgainstTheFilesFolder) {
    test::TempDir dir;
    const std::string path = dir.file("d.toml");
    test::writeFile(path, "[[volume]]\nname = \"a\"\nstore = \"s/a.bcs\"\n");
    const DaemonConfig c = DaemonConfig::load(path);
    EXPECT_EQ(c.source, path);
    EXPECT_EQ(c.volumes.at(0).store, (dir.path() / "s/a.bcs").string());
}

TEST(DaemonConfigTest, LoadErrorsNameTheFile) {
    test::TempDir dir;
    const std::string missing = dir.file("none.toml");
    try {
        DaemonConfig::load(missing);
        ADD_FAILURE() << "no ConfigError";
    } catch (const ConfigError& e) {
        EXPECT_NE(std::string(e.what()).find(missing + ": cannot read"), std::string::npos)
            << e.what();
    }
    EXPECT_THROW(DaemonConfig::load(dir.path().string()), ConfigError);
    const std::string bad = dir.file("bad.toml");
    test::writeFile(bad, "[server]\nmax_clients = true\n");
    try {
        DaemonConfig::load(bad);
        ADD_FAILURE() << "no ConfigError";
    } catch (const ConfigError& e) {
        EXPECT_EQ(std::string(e.what()).rfind(bad + ":2:", 0), 0u) << e.what();
    }
}

TEST(DaemonConfigTest, DefaultStoreDirFollowsXdgCacheHome) {
    const char* old = std::getenv("XDG_CACHE_HOME");
    const std::string saved = old ? old : "";
    ::setenv("XDG_CACHE_HOME", "/var/cache/u", 1);
    EXPECT_EQ(defaultStoreDir(), "/var/cache/u/brickcast");
    EXPECT_EQ(parseText(kVolume).storeDir, "/var/cache/u/brickcast");
    ::unsetenv("XDG_CACHE_HOME");
    EXPECT_EQ(defaultStoreDir(), "/tmp/brickcast-" + std::to_string(::getuid()));
    if (old) ::setenv("XDG_CACHE_HOME", saved.c_str(), 1);
}

} // namespace
} // namespace bc::server

namespace bc::server {
namespace {

TEST(DaemonConfigTest, BadWebHostsAreNamed) {
    for (const char* hosts : {"\"viewer.lan\"", "[\"viewer.lan:8080\"]", "[\"evil.com/x\"]",
                              "[\"[::zz]\"]", "[1]", "[\"\"]"}) {
        try {
            DaemonConfig::parse("[server]\nweb_hosts = " + std::string(hosts) + "\n" + kVolume,
                                "c.toml", "/cfg");
            ADD_FAILURE() << hosts << " was accepted";
        } catch (const ConfigError& e) {
            EXPECT_NE(std::string(e.what()).find("server.web_hosts"), std::string::npos)
                << e.what();
        }
    }
}

TEST(DaemonConfigTest, AReloadNamesEverySettingItCannotApply) {
    const DaemonConfig running =
        parseText(std::string("[server]\nlisten = \"127.0.0.1:7411\"\n") + kVolume);
    DaemonConfig next = running;
    next.volumes.push_back(next.volumes.at(0));
    next.volumes.back().name = "another";
    EXPECT_TRUE(settingsAReloadKeeps(running, next).empty()) << "the catalog is a reload's";
    next.listenPort = 7500;
    next.writeTimeoutMs = 1;
    EXPECT_EQ(settingsAReloadKeeps(running, next),
              (std::vector<std::string>{"server.listen", "timeouts.write_ms"}));
    DaemonConfig overridden = running;
    overridden.setListen("127.0.0.1:7600", "--listen");
    EXPECT_EQ(settingsAReloadKeeps(overridden, next), std::vector<std::string>{"timeouts.write_ms"})
        << "listen given on the command line stays the command line's";
}

} // namespace
} // namespace bc::server
