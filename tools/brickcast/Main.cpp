// brickcast: ingest volumes into brick stores and inspect them (later: render, bench).
#include "brickstore/Error.h"
#include "render/Error.h"
#include "tools/brickcast/Commands.h"

#include <CLI/CLI.hpp>
#include <cstdio>
#include <exception>

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
    bc::cli::addBenchCommand(app);
    bc::cli::addSplatBenchCommand(app);
    bc::cli::addLoadtestCommand(app);
    try {
        app.parse(argc, argv);
    } catch (const CLI::ParseError& e) {
        return app.exit(e);
    } catch (const bc::brickstore::FormatError& e) {
        std::fprintf(stderr, "brickcast: bad input: %s\n", e.what());
        return 1;
    } catch (const bc::brickstore::StoreCorrupt& e) {
        std::fprintf(stderr, "brickcast: corrupt store: %s\n", e.what());
        return 1;
    } catch (const bc::render::RenderInputError& e) {
        std::fprintf(stderr, "brickcast: bad input: %s\n", e.what());
        return 1;
    } catch (const std::exception& e) {
        std::fprintf(stderr, "brickcast: %s\n", e.what());
        return 1;
    }
    return 0;
}
