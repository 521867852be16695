// libFuzzer target of the daemon's config file (server/DaemonConfig.h); scripts/fuzz.sh
// daemon_config builds and runs it.
//
// Input: the text of a brickcastd.toml, written to a private scratch folder (which also holds
// tf/*.json presets copied from configs/tf, for [[preset]] entries) and read with
// DaemonConfig::load, as brickcastd does. A ConfigError is the expected refusal; a crash,
// sanitizer report or other exception is a finding. A config that loads must keep its own
// rules: a token whenever it listens off loopback, a metrics endpoint only on loopback, each
// volume either a store or a generator, distinct volume names, presets that parsed; and
// loading its file again must give an equal config.
//
// With BC_FUZZ_SEED_DIR set, the binary first writes seeds there: configs/brickcastd.toml
// (BC_CONFIGS_DIR), the embedded default, and a config using every section.
#include "server/DaemonConfig.h"
#include "server/Error.h"
#include "tests/fuzz/FuzzSupport.h"

#include <set>

namespace {

using namespace bc;
using namespace bc::server;
using fuzz::require;

const std::filesystem::path& folder() {
    static const std::filesystem::path dir = [] {
        const auto& d = fuzz::scratchDir();
        std::filesystem::create_directories(d / "tf");
        const std::string configs = fuzz::envFolder("BC_CONFIGS_DIR");
        if (!configs.empty())
            for (const char* name : {"ct-bone.json", "mr.json"})
                std::filesystem::copy_file(std::filesystem::path(configs) / "tf" / name,
                                           d / "tf" / name,
                                           std::filesystem::copy_options::overwrite_existing);
        return d;
    }();
    return dir;
}

void checkRules(const DaemonConfig& c) {
    require(c.loopbackOnly() || !c.token.empty(), "a config listens off loopback without a token");
    require(c.metricsHost.empty() || isLoopback(c.metricsHost),
            "a config serves metrics off loopback");
    std::set<std::string> names;
    for (const CatalogEntry& v : c.volumes) {
        require(v.store.empty() != v.generate.empty(),
                "a volume is neither or both store and generator");
        require(names.insert(v.name).second, "two volumes share a name");
    }
    for (const PresetEntry& p : c.presets)
        require(!p.json.empty(), "a preset without its text");
}

void writeSeeds(const std::string& seeds) {
    fuzz::writeSeed(seeds, "embedded-default",
                    fuzz::textBytes(std::string(DaemonConfig::defaultToml())));
    if (const std::string configs = fuzz::envFolder("BC_CONFIGS_DIR"); !configs.empty())
        fuzz::writeSeed(seeds, "brickcastd.toml",
                        fuzz::readFile(std::filesystem::path(configs) / "brickcastd.toml"));
    fuzz::writeSeed(seeds, "every-section", fuzz::textBytes(R"([server]
listen = "0.0.0.0:7411"
token = "secret-token"
max_clients = 4
max_unauthenticated = 8
metrics = "127.0.0.1:9100"
web_hosts = ["viewer.example.org", "[::1]", "10.0.0.5"]
tls_cert = "cert.pem"
tls_key = "key.pem"

[timeouts]
handshake_ms = 1000
read_ms = 2000

[budgets]
host_mb = 256
gpu_mb = 128

[frames]
rest_ms = 100
write_queue = 3
prefetch = false

[[volume]]
name = "cthead"
store = "stores/cthead.bcs"
description = "CT head"

[[volume]]
name = "phantom"
generate = "phantom"
dims = [64, 64, 64]

[[preset]]
name = "my-bone"
file = "tf/ct-bone.json"

[[preset]]
name = "my-mr"
file = "tf/mr.json"
)"));
}

} // namespace

extern "C" int LLVMFuzzerTestOneInput(const std::uint8_t* data, std::size_t size) {
    const std::string path = (folder() / "brickcastd.toml").string();
    fuzz::writeFile(path, {data, size});
    DaemonConfig config;
    try {
        config = DaemonConfig::load(path);
    } catch (const ConfigError&) {
        return 0;
    }
    checkRules(config);
    require(DaemonConfig::load(path) == config, "loading the same file twice differs");
    return 0;
}

extern "C" int LLVMFuzzerInitialize(int*, char***) {
    if (const std::string seeds = fuzz::envFolder("BC_FUZZ_SEED_DIR"); !seeds.empty())
        writeSeeds(seeds);
    return 0;
}
