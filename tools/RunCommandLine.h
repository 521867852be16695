#pragma once
// What a program's main does with its command line: parse it (the selected command runs
// inside the parse, as CLI11 callbacks), and turn what failed into one line on stderr and
// exit status 1. Shared by brickcast and the benchmarks of bench/ that were its commands.
#include "brickstore/Error.h"
#include "render/Error.h"

#include <CLI/CLI.hpp>

#include <cstdio>
#include <exception>
#include <new>
#include <string>

namespace bc::tools {

/// Parses `argv` with `app` (running what it selects); returns the process's exit status.
/// Bad options print CLI11's message; failures print "<program>: bad input: ...",
/// "<program>: corrupt store: ..." or "<program>: ..." and return 1; std::bad_alloc that no
/// command explained prints the command line it happened in.
inline int runCommandLine(CLI::App& app, int argc, char** argv, const char* program) {
    try {
        app.parse(argc, argv);
    } catch (const CLI::ParseError& e) {
        return app.exit(e);
    } catch (const brickstore::FormatError& e) {
        std::fprintf(stderr, "%s: bad input: %s\n", program, e.what());
        return 1;
    } catch (const brickstore::StoreCorrupt& e) {
        std::fprintf(stderr, "%s: corrupt store: %s\n", program, e.what());
        return 1;
    } catch (const render::RenderInputError& e) {
        std::fprintf(stderr, "%s: bad input: %s\n", program, e.what());
        return 1;
    } catch (const std::bad_alloc&) {
        // A command that can say more (which file, which stage) catches it itself.
        std::string line;
        for (int i = 1; i < argc; ++i)
            line += std::string(" ") + argv[i];
        std::fprintf(stderr, "%s: out of memory (std::bad_alloc) while running:%s\n", program,
                     line.c_str());
        return 1;
    } catch (const std::exception& e) {
        std::fprintf(stderr, "%s: %s\n", program, e.what());
        return 1;
    }
    return 0;
}

} // namespace bc::tools
