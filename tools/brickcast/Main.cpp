// brickcast: ingest volumes into brick stores, inspect, verify and extract them, render and
// compare frames, and load-test a running daemon.
#include "tools/RunCommandLine.h"
#include "tools/brickcast/Commands.h"

#include <CLI/CLI.hpp>

int main(int argc, char** argv) {
    CLI::App app{"brickcast: out-of-core volume bricking, rendering and streaming"};
    app.require_subcommand(1);
    bc::cli::addIngestCommand(app);
    bc::cli::addInfoCommand(app);
    bc::cli::addVerifyCommand(app);
    bc::cli::addExtractCommand(app);
    bc::cli::addDemoCommand(app);
    bc::cli::addCompareCommand(app);
    bc::cli::addRenderCommand(app);
    bc::cli::addLoadtestCommand(app);
    return bc::tools::runCommandLine(app, argc, argv, "brickcast");
}
