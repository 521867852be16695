#pragma once
// The `brickcast` command line: each sub-command registers its options on a CLI11 app and
// runs when selected. Only this layer turns command-line text into module configs.
#include <array>
#include <cstdint>
#include <string>
#include <vector>

namespace CLI {
class App;
}

namespace bc::brickstore {
class BrickStore;
}

namespace bc::cli {

/// Registers `ingest`, `info`, `verify`, `extract` and `demo` on `app`.
void addIngestCommand(CLI::App& app);
void addInfoCommand(CLI::App& app);
void addVerifyCommand(CLI::App& app);
void addExtractCommand(CLI::App& app);
void addDemoCommand(CLI::App& app);
void addRenderCommand(CLI::App& app);
void addCompareCommand(CLI::App& app);
void addLoadtestCommand(CLI::App& app);

/// Renders one frame of a store on the GPU (or the CPU reference) and writes a PNG; prints
/// the frame's summary line. @throw what the store, TF and renderer throw.
void renderStoreToPng(const std::string& storePath, const std::string& output,
                      const std::string& tfName, const std::string& orbit, const std::string& size,
                      bool reference);

/// The text `brickcast info` prints.
void printStoreInfo(const brickstore::BrickStore& store);

} // namespace bc::cli
