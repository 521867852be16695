// brickcast info STORE [--json]: what a store holds, from its header and index alone.
#include "brickstore/BrickStore.h"
#include "tools/Parse.h"
#include "tools/brickcast/Commands.h"

#include <CLI/CLI.hpp>
#include <algorithm>
#include <cmath>
#include <cstdio>
#include <nlohmann/json.hpp>

namespace bc::cli {
namespace {

struct LevelSummary {
    std::uint64_t bricks = 0, stored = 0, storedBytes = 0;
};

LevelSummary summarise(const brickstore::BrickStore& store, std::uint32_t level) {
    LevelSummary s;
    const auto& layout = store.layout();
    const auto& l = layout.levels()[level];
    s.bricks = l.brickCount();
    for (std::uint64_t i = 0; i < s.bricks; ++i) {
        const auto& r = store.record(layout.keyOf(l.firstBrick + i));
        if (!r.stored()) continue;
        ++s.stored;
        s.storedBytes += r.compressedBytes + r.leafBytes;
    }
    return s;
}

nlohmann::json toJson(const brickstore::BrickStore& store) {
    const auto& info = store.info();
    const auto& g = info.geometry;
    nlohmann::json j;
    j["path"] = store.path();
    j["description"] = info.volume.description;
    j["dims"] = info.volume.dims;
    j["type"] = std::string(brickstore::voxelTypeName(info.volume.type));
    j["spacing_mm"] = info.volume.spacingMm;
    j["origin_mm"] = info.volume.originMm;
    j["background"] = info.volume.background;
    j["value_scale"] = info.volume.valueScale;
    j["value_offset"] = info.volume.valueOffset;
    j["value_min"] = info.valueMin;
    j["value_max"] = info.valueMax;
    j["brick_voxels"] = g.brickVoxels;
    j["apron_voxels"] = g.apronVoxels;
    j["leaf_voxels"] = g.leafVoxels;
    j["file_bytes"] = info.fileBytes;
    j["stored_bricks"] = info.storedBricks;
    j["stored_bytes"] = info.storedBytes;
    j["brick_count"] = store.layout().brickCount();
    j["histogram"] = info.histogram;
    for (std::uint32_t l = 0; l < store.layout().levels().size(); ++l) {
        const auto& level = store.layout().levels()[l];
        auto s = summarise(store, l);
        j["levels"].push_back({{"dims", level.dims},
                               {"bricks", level.bricks},
                               {"stored_bricks", s.stored},
                               {"stored_bytes", s.storedBytes}});
    }
    return j;
}

} // namespace

void printStoreInfo(const brickstore::BrickStore& store) {
    const auto& info = store.info();
    const auto& v = info.volume;
    const auto& g = info.geometry;
    const std::uint32_t edge = store.layout().storedEdge();
    double overhead =
        double(edge) * edge * edge / (double(g.brickVoxels) * g.brickVoxels * g.brickVoxels) - 1.0;
    std::printf("store       %s (%s)\n", store.path().c_str(),
                tools::formatBytes(double(info.fileBytes)).c_str());
    std::printf("source      %s\n", v.description.c_str());
    std::printf("volume      %llu x %llu x %llu %s, spacing %g x %g x %g mm\n",
                (unsigned long long)v.dims[0], (unsigned long long)v.dims[1],
                (unsigned long long)v.dims[2],
                std::string(brickstore::voxelTypeName(v.type)).c_str(), v.spacingMm[0],
                v.spacingMm[1], v.spacingMm[2]);
    std::printf("values      %g .. %g (background %g)", info.valueMin, info.valueMax, v.background);
    if (v.valueScale != 1.0 || v.valueOffset != 0.0)
        std::printf(", physical = stored x %g + %g", v.valueScale, v.valueOffset);
    std::printf("\n");
    std::printf(
        "bricks      %u^3 payload + %u apron = %u^3 stored (%.1f%% apron overhead), leaves %u^3\n",
        g.brickVoxels, g.apronVoxels, edge, 100.0 * overhead, g.leafVoxels);
    double raw = double(v.voxelCount()) * double(brickstore::voxelBytes(v.type));
    std::printf(
        "stored      %llu of %llu bricks, %s (level-0 volume %s)\n",
        (unsigned long long)info.storedBricks, (unsigned long long)store.layout().brickCount(),
        tools::formatBytes(double(info.storedBytes)).c_str(), tools::formatBytes(raw).c_str());
    for (std::uint32_t l = 0; l < store.layout().levels().size(); ++l) {
        const auto& level = store.layout().levels()[l];
        auto s = summarise(store, l);
        std::printf("  L%-2u %6llu x %-6llu x %-6llu %4u x %-4u x %-4u bricks, %llu stored (%s)\n",
                    l, (unsigned long long)level.dims[0], (unsigned long long)level.dims[1],
                    (unsigned long long)level.dims[2], level.bricks[0], level.bricks[1],
                    level.bricks[2], (unsigned long long)s.stored,
                    tools::formatBytes(double(s.storedBytes)).c_str());
    }
    // A coarse histogram: 16 groups of bins, log-scaled bar.
    const auto& h = info.histogram;
    if (h.empty()) return;
    std::printf("histogram   (%zu bins over the value range, 16 shown)\n", h.size());
    const std::size_t groups = std::min<std::size_t>(16, h.size()), per = h.size() / groups;
    std::vector<double> sums(groups, 0.0);
    for (std::size_t i = 0; i < h.size(); ++i)
        sums[std::min(groups - 1, i / per)] += double(h[i]);
    double peak = *std::max_element(sums.begin(), sums.end());
    for (std::size_t gi = 0; gi < groups; ++gi) {
        double lo = info.valueMin + (info.valueMax - info.valueMin) * double(gi) / double(groups);
        int bar =
            peak > 0 && sums[gi] > 0 ? int(1 + 39 * std::log1p(sums[gi]) / std::log1p(peak)) : 0;
        std::printf("  %12g %-40s %.0f\n", lo, std::string(std::size_t(bar), '#').c_str(),
                    sums[gi]);
    }
}

void addInfoCommand(CLI::App& app) {
    auto path = std::make_shared<std::string>();
    auto json = std::make_shared<bool>(false);
    auto* cmd = app.add_subcommand("info", "Print what a store holds (header and index only)");
    cmd->add_option("STORE", *path, "Store file")->required();
    cmd->add_flag("--json", *json, "Machine-readable output");
    cmd->callback([path, json] {
        auto store = brickstore::BrickStore::open(*path);
        if (*json)
            std::printf("%s\n", toJson(*store).dump(2).c_str());
        else
            printStoreInfo(*store);
    });
}

} // namespace bc::cli
