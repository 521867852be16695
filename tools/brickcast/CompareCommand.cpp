// brickcast compare A.png B.png [--diff OUT.png] [--gain G] [--json]: how far two frames
// are apart (max abs, RMSE, PSNR, SSIM), and optionally a picture of where.
#include "render/Image.h"
#include "render/ImageMetrics.h"
#include "tools/brickcast/Commands.h"

#include <CLI/CLI.hpp>
#include <nlohmann/json.hpp>

#include <cmath>
#include <cstdio>
#include <stdexcept>

namespace bc::cli {
namespace {

struct CompareCliOptions {
    std::string first, second, diffPath;
    float gain = 1.0f;
    bool json = false;
};

/// maxAbs in 1/255 steps, the unit an 8-bit PNG differs by.
long stepsOf255(double maxAbs) {
    return std::lround(maxAbs * 255.0);
}

/// The figures as JSON; psnrDb is null when the images are identical (PSNR is infinite).
nlohmann::json comparisonJson(const CompareCliOptions& o, const render::Image& a,
                              const render::ImageComparison& c) {
    nlohmann::json j = {
        {"a", o.first},         {"b", o.second},        {"width", a.width},
        {"height", a.height},   {"maxAbs", c.maxAbs},   {"maxAbs255", stepsOf255(c.maxAbs)},
        {"maxAbsX", c.maxAbsX}, {"maxAbsY", c.maxAbsY}, {"rmse", c.rmse},
        {"psnrDb", nullptr},    {"ssim", c.ssim}};
    if (std::isfinite(c.psnrDb)) j["psnrDb"] = c.psnrDb;
    j["lowPassRmse"] = c.lowPassRmse;
    j["lowPassPsnrDb"] = nullptr;
    if (std::isfinite(c.lowPassPsnrDb)) j["lowPassPsnrDb"] = c.lowPassPsnrDb;
    if (!o.diffPath.empty()) j["diff"] = o.diffPath;
    return j;
}

void printComparison(const render::ImageComparison& c) {
    char psnr[32];
    if (std::isfinite(c.psnrDb))
        std::snprintf(psnr, sizeof psnr, "%.1f", c.psnrDb);
    else
        std::snprintf(psnr, sizeof psnr, "inf");
    char lowPass[32];
    if (std::isfinite(c.lowPassPsnrDb))
        std::snprintf(lowPass, sizeof lowPass, "%.1f", c.lowPassPsnrDb);
    else
        std::snprintf(lowPass, sizeof lowPass, "inf");
    std::printf("max abs %ld/255 (%.4f) at (%u,%u)  RMSE %.3g  PSNR %s dB  SSIM %.5f  "
                "low-pass PSNR %s dB\n",
                stepsOf255(c.maxAbs), c.maxAbs, c.maxAbsX, c.maxAbsY, c.rmse, psnr, c.ssim,
                lowPass);
}

void runCompare(const CompareCliOptions& o) {
    const render::Image a = render::readPng(o.first);
    const render::Image b = render::readPng(o.second);
    if (a.width != b.width || a.height != b.height)
        throw std::invalid_argument(o.first + " is " + std::to_string(a.width) + "x" +
                                    std::to_string(a.height) + " but " + o.second + " is " +
                                    std::to_string(b.width) + "x" + std::to_string(b.height));
    const render::ImageComparison c = render::compareImages(a, b);
    if (!o.diffPath.empty()) render::writePng(o.diffPath, render::differenceImage(a, b, o.gain));
    if (o.json)
        std::printf("%s\n", comparisonJson(o, a, c).dump(2).c_str());
    else
        printComparison(c);
}

} // namespace

void addCompareCommand(CLI::App& app) {
    auto o = std::make_shared<CompareCliOptions>();
    auto* cmd = app.add_subcommand("compare", "Compare two PNG frames: max abs, RMSE, PSNR, SSIM");
    cmd->add_option("A", o->first, "First PNG")->required();
    cmd->add_option("B", o->second, "Second PNG")->required();
    cmd->add_option("--diff", o->diffPath, "Write |A-B| * gain per colour channel as a PNG");
    cmd->add_option("--gain", o->gain, "Scale of the --diff image")
        ->check(CLI::NonNegativeNumber)
        ->capture_default_str();
    cmd->add_flag("--json", o->json, "Machine-readable output");
    cmd->callback([o] { runCompare(*o); });
}

} // namespace bc::cli
