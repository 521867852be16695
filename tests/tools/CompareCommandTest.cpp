// `brickcast compare` end to end: the figures it prints (max abs and where, RMSE, PSNR, SSIM),
// its JSON and difference image, and bad or mismatched PNGs named.
#include "render/Image.h"
#include "render/ImageMetrics.h"
#include "tests/TestSupport.h"

#include <nlohmann/json.hpp>

#include <array>
#include <cstdio>
#include <sys/wait.h>

namespace bc::render {
namespace {

using Output = bc::test::CommandOutput;

Output brickcast(const std::string& args) {
    return bc::test::runCommand(std::string(BC_BRICKCAST_EXE) + " " + args);
}

bool contains(const std::string& text, const std::string& part) {
    return text.find(part) != std::string::npos;
}

/// Two 48x48 opaque black frames, the second with pixel (12,40) red at 64/255.
struct ComparePair {
    test::TempDir dir;
    std::string a = dir.file("a.png"), b = dir.file("b.png");
    ComparePair() {
        Image image(48, 48);
        for (std::size_t i = 3; i < image.rgba.size(); i += 4)
            image.rgba[i] = 1.0f;
        writePng(a, image);
        image.pixel(12, 40)[0] = 64.0f / 255.0f;
        writePng(b, image);
    }
};

TEST(CompareCommandTest, PrintsMaxAbsLocationRmsePsnrAndSsimAndWritesTheDiff) {
    ComparePair pair;
    const std::string diff = pair.dir.file("diff.png");
    const Output out =
        brickcast("compare " + pair.a + " " + pair.b + " --diff " + diff + " --gain 2");
    ASSERT_EQ(out.exitCode, 0) << out.text;
    // RMSE = (64/255) / sqrt(48*48*4) = 0.0026144; PSNR = 20 log10(1/RMSE) = 51.65 dB.
    EXPECT_TRUE(
        contains(out.text, "max abs 64/255 (0.2510) at (12,40)  RMSE 0.00261  PSNR 51.7 dB  SSIM "))
        << out.text;
    char ssim[32];
    std::snprintf(ssim, sizeof ssim, "SSIM %.5f",
                  compareImages(readPng(pair.a), readPng(pair.b)).ssim);
    EXPECT_TRUE(contains(out.text, ssim)) << out.text;
    const Image d = readPng(diff);
    ASSERT_EQ(d.width, 48u);
    EXPECT_EQ(d.pixel(12, 40)[0], 128.0f / 255.0f);
    EXPECT_EQ(d.pixel(12, 40)[3], 1.0f);
    EXPECT_EQ(d.pixel(0, 0)[0], 0.0f);
    EXPECT_EQ(d.pixel(0, 0)[3], 1.0f);
}

TEST(CompareCommandTest, JsonOutputCarriesTheFiguresAndNullPsnrForIdenticalImages) {
    ComparePair pair;
    const Output out = brickcast("compare --json " + pair.a + " " + pair.b);
    ASSERT_EQ(out.exitCode, 0) << out.text;
    const auto j = nlohmann::json::parse(out.text);
    EXPECT_EQ(j["maxAbs255"], 64);
    EXPECT_EQ(j["maxAbsX"], 12);
    EXPECT_EQ(j["maxAbsY"], 40);
    EXPECT_NEAR(j["maxAbs"].get<double>(), 64.0 / 255.0, 1e-7);
    EXPECT_NEAR(j["psnrDb"].get<double>(), 51.65, 0.01);
    const Output same = brickcast("compare --json " + pair.a + " " + pair.a);
    ASSERT_EQ(same.exitCode, 0) << same.text;
    const auto k = nlohmann::json::parse(same.text);
    EXPECT_TRUE(k["psnrDb"].is_null());
    EXPECT_EQ(k["ssim"], 1.0);
    EXPECT_TRUE(contains(brickcast("compare " + pair.a + " " + pair.a).text, "PSNR inf dB"));
}

TEST(CompareCommandTest, BadPngOrSizeMismatchExitsNonZeroNamingTheFile) {
    ComparePair pair;
    const std::string bad = pair.dir.file("bad.png");
    test::writeFile(bad, "this is not a png");
    const Output out = brickcast("compare " + pair.a + " " + bad);
    EXPECT_NE(out.exitCode, 0);
    EXPECT_TRUE(contains(out.text, "bad input")) << out.text;
    EXPECT_TRUE(contains(out.text, bad)) << out.text;
    const Output missing = brickcast("compare " + pair.dir.file("nope.png") + " " + pair.a);
    EXPECT_NE(missing.exitCode, 0);
    EXPECT_TRUE(contains(missing.text, pair.dir.file("nope.png"))) << missing.text;
    writePng(bad, Image(10, 20));
    const Output size = brickcast("compare " + pair.a + " " + bad);
    EXPECT_NE(size.exitCode, 0);
    EXPECT_TRUE(contains(size.text, "48x48") && contains(size.text, "10x20")) << size.text;
}

} // namespace
} // namespace bc::render
