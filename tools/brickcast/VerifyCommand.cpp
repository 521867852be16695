// brickcast verify STORE: full scrub; non-zero exit naming every corrupt brick.
#include "brickstore/BrickStore.h"
#include "tools/brickcast/Commands.h"

#include <CLI/CLI.hpp>
#include <chrono>
#include <cstdio>

namespace bc::cli {

void addVerifyCommand(CLI::App& app) {
    auto path = std::make_shared<std::string>();
    auto threads = std::make_shared<unsigned>(0);
    auto* cmd = app.add_subcommand("verify", "Check every brick's checksum, size and summaries");
    cmd->add_option("STORE", *path, "Store file")->required();
    cmd->add_option("--threads", *threads, "Workers (0 = all cores)");
    cmd->callback([path, threads] {
        auto start = std::chrono::steady_clock::now();
        auto store = brickstore::BrickStore::open(*path);
        auto faults = store->verify(*threads);
        double s = std::chrono::duration<double>(std::chrono::steady_clock::now() - start).count();
        for (const auto& f : faults)
            std::fprintf(stderr, "corrupt: %s\n", f.c_str());
        if (!faults.empty()) {
            std::fprintf(stderr, "%s: %zu corrupt brick(s) of %llu\n", path->c_str(), faults.size(),
                         (unsigned long long)store->layout().brickCount());
            throw CLI::RuntimeError(1);
        }
        std::printf("%s: ok, %llu bricks (%llu stored) verified in %.2f s\n", path->c_str(),
                    (unsigned long long)store->layout().brickCount(),
                    (unsigned long long)store->info().storedBricks, s);
    });
}

} // namespace bc::cli
