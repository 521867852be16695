#include "bench/BenchDatasets.h"
#include "tools/Parse.h"

#include <algorithm>
#include <cstdio>
#include <filesystem>
#include <optional>
#include <random>

namespace bc::bench {

std::vector<Dataset> realDatasets(const std::string& dataDir, const std::string& wanted,
                                  const std::string& tfOverride, const char* who) {
    auto at = [&](const std::string& f) { return (std::filesystem::path(dataDir) / f).string(); };
    std::vector<Dataset> all;
    auto add = [&](std::string name, std::string preset, std::string input,
                   std::optional<std::array<double, 3>> spacing = std::nullopt) {
        brickstore::SourceSpec s;
        s.input = std::move(input);
        s.spacingMm = spacing;
        if (s.input.ends_with(".vdb")) s.gridName = "density";
        all.push_back({std::move(name), std::move(preset), s, 0, ""});
    };
    add("stanford_cthead", "ct-skin", at("stanford_cthead_256x256x113_uint16.raw"),
        std::array<double, 3>{1, 1, 2});
    add("stanford_cthead", "ct-bone", at("stanford_cthead_256x256x113_uint16.raw"),
        std::array<double, 3>{1, 1, 2});
    add("CT_AVM", "vessels", at("CT_AVM.nii.gz"));
    add("frog", "mr", at("frog_500x470x136_uint8.raw"), std::array<double, 3>{1, 1, 1.5});
    add("pancreas", "ct-bone", at("tcia_pancreas_ct_dicom"));
    add("Iguana", "ct-bone", at("Iguana.nii.gz"));
    add("gaffer_smoke", "smoke", at("gaffer_smoke.vdb"));
    add("hydrogen", "smoke", at("hydrogen_64x64x64_float32.raw"));
    const auto names = tools::splitList(wanted);
    std::vector<Dataset> out;
    for (auto& d : all) {
        if (!names.empty() && std::find(names.begin(), names.end(), d.name) == names.end())
            continue;
        if (!std::filesystem::exists(d.spec.input)) {
            std::fprintf(stderr, "%s: skipping %s: %s is missing\n", who, d.name.c_str(),
                         d.spec.input.c_str());
            continue;
        }
        if (!tfOverride.empty()) d.preset = tfOverride;
        if (std::none_of(out.begin(), out.end(), [&](const Dataset& e) {
                return e.name == d.name && e.preset == d.preset;
            }))
            out.push_back(d);
    }
    return out;
}

std::vector<render::Camera> cameraPath(const std::string& path, const render::Box& box,
                                       int frames) {
    std::vector<render::Camera> cams;
    std::mt19937 rng(20261201);
    std::uniform_real_distribution<double> az(0, 360), el(-70, 70), dist(0.7, 1.4);
    for (int f = 0; f <= frames; ++f)
        cams.push_back(path == "orbit" ? render::Camera::orbit(box, 30.0 + 2.0 * f, 20.0)
                                       : render::Camera::orbit(box, az(rng), el(rng), dist(rng)));
    return cams;
}

} // namespace bc::bench
