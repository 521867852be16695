// brickcastd: the streaming daemon. With no --config it serves the embedded default (loopback,
// no token, generated volumes); `brickcastd --print-default-config` writes that default as a
// documented TOML file to start from. Under `mpirun -np N` (N > 1, a build with MPI) it runs
// over the job's ranks: rank 0 serves the clients and every rank draws its part of the CPU and
// GPU raycasters' frames (server/cluster/RankedDaemon.h).
#include "server/Catalog.h"
#include "server/Daemon.h"
#include "server/DaemonConfig.h"
#include "server/Error.h"
#include "server/Log.h"
#ifdef BC_HAVE_MPI
#include "server/cluster/MpiRuntime.h"
#include "server/cluster/RankedDaemon.h"
#endif

#include <CLI/CLI.hpp>

#include <cstdio>
#include <cstdlib>
#include <fstream>
#include <memory>
#include <new>
#include <optional>
#include <sstream>
#include <string>

namespace {

struct Options {
    std::string configPath, portFile, listen, metrics, metricsPortFile, webPortFile;
    std::optional<std::string> web;
};

bc::server::DaemonConfig loadConfig(const Options& o) {
    auto config = o.configPath.empty() ? bc::server::DaemonConfig::embeddedDefault()
                                       : bc::server::DaemonConfig::load(o.configPath);
    if (!o.listen.empty()) config.setListen(o.listen, "--listen");
    if (!o.metrics.empty()) config.setMetrics(o.metrics, "--metrics");
    if (o.web) config.setWeb(*o.web, "--web");
    return config;
}

/// The config's text (what every rank of a job must share), or the embedded default's.
std::string configText(const Options& o) {
    if (o.configPath.empty()) return std::string(bc::server::DaemonConfig::defaultToml());
    std::ifstream in(o.configPath, std::ios::binary);
    std::ostringstream text;
    text << in.rdbuf();
    return text.str();
}

void writePorts(const Options& o, const bc::server::Daemon& daemon) {
    auto writePort = [](const std::string& file, unsigned port) {
        if (file.empty()) return;
        std::ofstream(file + ".tmp") << port << "\n";
        std::rename((file + ".tmp").c_str(), file.c_str());
    };
    writePort(o.metricsPortFile, daemon.metricsPort());
    writePort(o.webPortFile, daemon.webPort());
    writePort(o.portFile, daemon.port());
}

#ifdef BC_HAVE_MPI
/// The job's size as mpirun announces it in the environment before MPI starts; 1 when not
/// started by mpirun (or by a launcher this does not know).
int launcherRanks() {
    for (const char* name : {"OMPI_COMM_WORLD_SIZE", "PMI_SIZE", "PMIX_SIZE"})
        if (const char* v = std::getenv(name)) {
            const int n = std::atoi(v);
            if (n > 0) return n;
        }
    return 1;
}

/// The daemon over the job's ranks. Every rank loads the config; rank 0 opens the daemon
/// (and ingests generated volumes) before the others open their catalogs; then every rank's
/// config fingerprint and start are compared, and a job whose ranks differ or failed ends with
/// one line naming each rank at fault. Rank 0 then serves until SIGTERM, and tells the others
/// to stop; they draw parts until told.
int serveRanks(const Options& o, bc::server::Log& log) {
    using namespace bc::server;
    cluster::MpiRuntime mpi;
    const bool root = mpi.rank() == 0;
    const std::string who = "brickcastd: rank " + std::to_string(mpi.rank()) + " of " +
                            std::to_string(mpi.size()) + ": ";
    cluster::RankStart start;
    std::optional<DaemonConfig> config;
    try {
        config = loadConfig(o);
        start.configFingerprint = cluster::fingerprint(configText(o));
    } catch (const std::exception& e) {
        start.error = e.what();
    }
    const auto timeout = std::chrono::milliseconds(config ? config->clusterTimeoutMs : 30000);
    cluster::MpiFrameCluster frames(MPI_COMM_WORLD, timeout, log);
    std::unique_ptr<Daemon> daemon;
    std::unique_ptr<Catalog> catalog;
    if (root && config) try {
            daemon = std::make_unique<Daemon>(*config, log, /*handleSignals=*/true, &frames);
        } catch (const std::exception& e) {
            start.error = e.what();
        }
    MPI_Barrier(MPI_COMM_WORLD); // generated volumes are ingested once, by rank 0
    if (!root && config) try {
            catalog = std::make_unique<Catalog>(*config, log);
        } catch (const std::exception& e) {
            start.error = e.what();
        }
    if (const auto why = cluster::compareStarts(MPI_COMM_WORLD, start)) {
        if (root) log.error("brickcastd: the job's ranks cannot start: " + *why);
        return 1;
    }
    frames.arm();
    if (!root) {
        int code = 3;
        try {
            code = cluster::serveOrders(MPI_COMM_WORLD, *catalog, *config, log);
        } catch (const std::exception& e) {
            log.error(who + e.what() + ": this rank ends");
        }
        // A rank that failed leaves without MPI_Finalize, which would wait for the rank at
        // fault; rank 0 goes on serving its clients (errors for cluster frames).
        if (code != 0) std::_Exit(code);
        return 0;
    }
    log.info("cluster: " + std::to_string(mpi.size()) +
             " ranks draw the CPU and GPU raycasters' frames (sort-last, direct send; timeout " +
             std::to_string(timeout.count()) + " ms)");
    writePorts(o, *daemon);
    daemon->run();
    daemon.reset(); // the render thread ends: MPI is this thread's again
    if (!frames.stop()) {
        log.error(who + "the cluster failed (" + frames.failure().value_or("") +
                  "): ending every rank");
        frames.quitWorkers();
        cluster::MpiRuntime::abortAll(3);
    }
    return 0;
}
#endif

} // namespace

int main(int argc, char** argv) {
    CLI::App app{"brickcastd: out-of-core volume rendering, streamed to thin clients"};
    Options o;
    auto& [configPath, portFile, listen, metrics, metricsPortFile, webPortFile, web] = o;
    bool printDefault = false, quiet = false;
    app.add_option("-c,--config", configPath, "Config file (TOML); default: the embedded one");
    app.add_option("--listen", listen, "HOST:PORT, overriding the config (port 0: any free port)");
    app.add_option("--port-file", portFile, "Write the bound port here once listening");
    app.add_option("--metrics", metrics,
                   "HOST:PORT (loopback) for GET /metrics in the Prometheus text format, "
                   "overriding the config");
    app.add_option("--metrics-port-file", metricsPortFile,
                   "Write the metrics port here once listening");
    app.add_option("--web", web,
                   "HOST:PORT of the browser viewer, \"auto\" (the listen port + 1) or \"\" "
                   "(none), overriding the config");
    app.add_option("--web-port-file", webPortFile, "Write the viewer's port here once listening");
    app.add_flag("--print-default-config", printDefault,
                 "Print the embedded default config and exit");
    app.add_flag("-q,--quiet", quiet, "Log errors only");
    CLI11_PARSE(app, argc, argv);
    if (printDefault) {
        const auto text = bc::server::DaemonConfig::defaultToml();
        std::fwrite(text.data(), 1, text.size(), stdout);
        return 0;
    }
    bc::server::Log log(quiet);
    try {
#ifdef BC_HAVE_MPI
        if (launcherRanks() > 1) return serveRanks(o, log);
#endif
        bc::server::Daemon daemon(loadConfig(o), log, /*handleSignals=*/true);
        writePorts(o, daemon);
        daemon.run();
        return 0;
    } catch (const std::bad_alloc&) {
        log.error(
            "brickcastd: out of memory (std::bad_alloc) while loading or serving the config " +
            (configPath.empty() ? std::string("(embedded default)") : configPath));
        return 1;
    } catch (const std::exception& e) {
        log.error(std::string("brickcastd: ") + e.what());
        return 1;
    }
}
