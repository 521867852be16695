// brickcast extract STORE -o OUT.raw [--level L]: native type, little-endian, x fastest.
#include "brickstore/BrickStore.h"
#include "brickstore/Error.h"
#include "brickstore/StoreVolume.h"
#include "tools/brickcast/Commands.h"

#include <CLI/CLI.hpp>
#include <cstdio>
#include <fstream>
#include <vector>

namespace bc::cli {
namespace {

void runExtract(const std::string& path, const std::string& output, std::uint32_t level) {
    auto store = brickstore::BrickStore::open(path);
    auto source = brickstore::openStoreLevel(*store, level);
    const auto& info = source->info();
    std::string temp = output + ".partial";
    std::ofstream out(temp, std::ios::binary | std::ios::trunc);
    if (!out) throw brickstore::StoreIoError(temp + ": cannot create");
    const std::uint64_t chunk = std::max<std::uint64_t>(1, (16ull << 20) / info.sliceBytes());
    std::vector<std::byte> buf(std::min(chunk, info.dims[2]) * info.sliceBytes());
    try {
        for (std::uint64_t z = 0; z < info.dims[2];) {
            std::uint64_t n = std::min(chunk, info.dims[2] - z);
            source->readSlices(n, std::span(buf).first(n * info.sliceBytes()));
            out.write(reinterpret_cast<const char*>(buf.data()),
                      std::streamsize(n * info.sliceBytes()));
            if (!out) throw brickstore::StoreIoError(temp + ": write failed");
            z += n;
        }
        out.close();
        if (std::rename(temp.c_str(), output.c_str()) != 0)
            throw brickstore::StoreIoError(output + ": cannot rename into place");
    } catch (...) {
        std::remove(temp.c_str());
        throw;
    }
    std::fprintf(stderr, "%s: level %u, %llu x %llu x %llu %s, spacing %g x %g x %g mm\n",
                 output.c_str(), level, (unsigned long long)info.dims[0],
                 (unsigned long long)info.dims[1], (unsigned long long)info.dims[2],
                 std::string(brickstore::voxelTypeName(info.type)).c_str(), info.spacingMm[0],
                 info.spacingMm[1], info.spacingMm[2]);
}

} // namespace

void addExtractCommand(CLI::App& app) {
    auto path = std::make_shared<std::string>();
    auto output = std::make_shared<std::string>();
    auto level = std::make_shared<std::uint32_t>(0);
    auto* cmd = app.add_subcommand("extract", "Write one pyramid level back out as a raw file");
    cmd->add_option("STORE", *path, "Store file")->required();
    cmd->add_option("-o,--output", *output, "Raw file (native type, little-endian, x fastest)")
        ->required();
    cmd->add_option("--level", *level, "Pyramid level (0 = full resolution)")
        ->capture_default_str();
    cmd->callback([path, output, level] { runExtract(*path, *output, *level); });
}

} // namespace bc::cli
