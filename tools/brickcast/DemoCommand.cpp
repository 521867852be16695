// brickcast demo: the README's main job on an embedded default, no data files needed.
// Generates a CT-like phantom, ingests it, prints its summary, scrubs it and renders it.
#include "brickstore/BrickStore.h"
#include "brickstore/Ingest.h"
#include "brickstore/Readers.h"
#include "tools/Parse.h"
#include "tools/brickcast/Commands.h"

#include <CLI/CLI.hpp>
#include <cstdio>
#include <filesystem>

namespace bc::cli {
namespace {

struct DemoOptions {
    std::string dims = "256,256,192";
    std::string folder = "brickcast-demo";
    std::string tf = "ct-bone";
    std::string size = "512,512";
};

void runDemo(const DemoOptions& o) {
    std::filesystem::create_directories(o.folder);
    const std::string storePath = (std::filesystem::path(o.folder) / "phantom.bcs").string();
    auto source = brickstore::makeSynthetic(brickstore::SynthKind::Phantom,
                                            tools::parseTriple(o.dims, "--dims"), 1);
    std::printf("== ingest %s\n", source->info().description.c_str());
    auto report = brickstore::ingest(*source, storePath, {});
    std::printf("   %.2f s, %.1f MB/s, %llu bricks of which %llu constant (not stored)\n\n",
                report.seconds, double(report.sourceBytes) / 1e6 / report.seconds,
                (unsigned long long)report.bricks, (unsigned long long)report.constantBricks);
    auto store = brickstore::BrickStore::open(storePath);
    std::printf("== info\n");
    printStoreInfo(*store);
    auto faults = store->verify();
    std::printf("\n== verify: %s\n",
                faults.empty() ? "ok, every brick checks out" : faults.front().c_str());
    if (!faults.empty()) throw CLI::RuntimeError(1);
    const std::string image = (std::filesystem::path(o.folder) / "phantom.png").string();
    std::printf("\n== render (GPU raycaster through EGL, %s preset)\n", o.tf.c_str());
    renderStoreToPng(storePath, image, o.tf, "30,20", o.size, false);
}

} // namespace

void addDemoCommand(CLI::App& app) {
    auto o = std::make_shared<DemoOptions>();
    auto* cmd = app.add_subcommand(
        "demo", "Generate a phantom, ingest it, print its summary, verify it, render it");
    cmd->add_option("--dims", o->dims, "Phantom size X,Y,Z")->capture_default_str();
    cmd->add_option("--folder", o->folder, "Where the demo store and image go")
        ->capture_default_str();
    cmd->add_option("--tf", o->tf, "Transfer function preset or file")->capture_default_str();
    cmd->add_option("--size", o->size, "Image W,H")->capture_default_str();
    cmd->callback([o] { runDemo(*o); });
}

} // namespace bc::cli
