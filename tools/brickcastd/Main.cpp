// brickcastd: the streaming daemon. With no --config it serves the embedded default (loopback,
// no token, generated volumes); `brickcastd --print-default-config` writes that default as a
// documented TOML file to start from.
#include "server/Daemon.h"
#include "server/DaemonConfig.h"
#include "server/Error.h"
#include "server/Log.h"

#include <CLI/CLI.hpp>

#include <cstdio>
#include <fstream>
#include <new>
#include <optional>
#include <string>

int main(int argc, char** argv) {
    CLI::App app{"brickcastd: out-of-core volume rendering, streamed to thin clients"};
    std::string configPath, portFile, listen, metrics, metricsPortFile, webPortFile;
    std::optional<std::string> web;
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
        auto config = configPath.empty() ? bc::server::DaemonConfig::embeddedDefault()
                                         : bc::server::DaemonConfig::load(configPath);
        if (!listen.empty()) config.setListen(listen, "--listen");
        if (!metrics.empty()) config.setMetrics(metrics, "--metrics");
        if (web) config.setWeb(*web, "--web");
        bc::server::Daemon daemon(std::move(config), log, /*handleSignals=*/true);
        auto writePort = [](const std::string& file, unsigned port) {
            if (file.empty()) return;
            std::ofstream(file + ".tmp") << port << "\n";
            std::rename((file + ".tmp").c_str(), file.c_str());
        };
        writePort(metricsPortFile, daemon.metricsPort());
        writePort(webPortFile, daemon.webPort());
        writePort(portFile, daemon.port());
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
