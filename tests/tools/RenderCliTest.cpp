// `brickcast render`: end to end through the command line, bad input named, no usable EGL a
// clear error (never a crash).
#include "render/Image.h"
#include "tests/render/RenderTestSupport.h"

#include <nlohmann/json.hpp>

#include <array>
#include <fstream>
#include <sys/wait.h>

namespace bc::render {
namespace {

using Output = bc::test::CommandOutput;

Output brickcast(const std::string& args, const std::string& env = "") {
    return bc::test::runCommand(env + " " + std::string(BC_BRICKCAST_EXE) + " " + args);
}

bool contains(const std::string& text, const std::string& part) {
    return text.find(part) != std::string::npos;
}

class RenderCli : public ::testing::Test {
  protected:
    void SetUp() override {
        store = dir.file("phantom.bcs");
        auto r = brickcast("ingest synth:phantom --dims 64,64,48 --brick 16 -o " + store);
        ASSERT_EQ(r.exitCode, 0) << r.text;
    }
    test::TempDir dir;
    std::string store;
};

TEST_F(RenderCli, GpuFrameMatchesTheReferenceFrameAndWritesStats) {
    const std::string gpu = dir.file("gpu.png"), ref = dir.file("ref.png"),
                      stats = dir.file("s.json");
    auto a = brickcast(
        "render " + store + " -o " + gpu +
        " --size 96,64 --tf ct-bone --orbit 40,25 --ert off --renderer gpu --stats " + stats);
    ASSERT_EQ(a.exitCode, 0) << a.text;
    auto b = brickcast("render " + store + " -o " + ref +
                       " --size 96,64 --tf ct-bone --orbit 40,25 --reference");
    ASSERT_EQ(b.exitCode, 0) << b.text;
    const Image ga = readPng(gpu), rb = readPng(ref);
    EXPECT_EQ(ga.width, 96u);
    EXPECT_EQ(ga.height, 64u);
    EXPECT_LE(compareImages(ga, rb).maxAbs, 1.0 / 255.0 + 1e-6);
    std::ifstream f(stats);
    const auto j = nlohmann::json::parse(f);
    EXPECT_GT(j.at("samples").get<double>(), 0.0);
    EXPECT_EQ(j.at("level").get<int>(), 0);
    EXPECT_EQ(j.at("batches").get<int>(), 1);
    EXPECT_EQ(j.at("rendererName"), "gpu");
    EXPECT_EQ(j.at("rendererChoice"), "asked for gpu");
    auto c = brickcast("compare " + gpu + " " + ref);
    EXPECT_EQ(c.exitCode, 0) << c.text;
}

// --reference reads bricks through the host cache in batches that fit --host-budget-mb (it used
// to read the level whole): the same image under a budget that holds a fraction of the bricks.
TEST_F(RenderCli, ReferenceDrawsInBatchesThatFitTheHostBudgetAndTheSameImage) {
    const std::string big = dir.file("big.bcs");
    // 128x128x96 u16 in bricks of 16 (20³ stored): 384 bricks, 6 MiB decompressed.
    auto in = brickcast("ingest synth:phantom --dims 128,128,96 --brick 16 -o " + big);
    ASSERT_EQ(in.exitCode, 0) << in.text;
    const std::string args = " --size 64,48 --tf ct-bone --orbit 40,25 --reference";
    const std::string whole = dir.file("whole.png"), small = dir.file("small.png"),
                      stats = dir.file("small.json");
    auto a = brickcast("render " + big + " -o " + whole + args);
    ASSERT_EQ(a.exitCode, 0) << a.text;
    auto b =
        brickcast("render " + big + " -o " + small + args + " --host-budget-mb 1 --stats " + stats);
    ASSERT_EQ(b.exitCode, 0) << b.text;
    EXPECT_EQ(compareImages(readPng(whole), readPng(small)).maxAbs, 0.0);
    std::ifstream f(stats);
    const auto j = nlohmann::json::parse(f);
    EXPECT_GE(j.at("batches").get<int>(), 4) << "1 MiB holds 65 of the 384 bricks";
}

// --repeat: one renderer draws the view again and again; the last (warm) image is the first's.
TEST_F(RenderCli, RepeatDrawsWarmFramesOfTheSameImage) {
    for (const std::string renderer : {"cpu", "gpu"}) {
        const std::string one = dir.file(renderer + "1.png"), three = dir.file(renderer + "3.png"),
                          stats = dir.file(renderer + ".json");
        const std::string args = " --size 64,48 --tf ct-bone --orbit 40,25 --renderer " + renderer;
        auto a = brickcast("render " + store + " -o " + one + args);
        ASSERT_EQ(a.exitCode, 0) << a.text;
        auto b =
            brickcast("render " + store + " -o " + three + args + " --repeat 3 --stats " + stats);
        ASSERT_EQ(b.exitCode, 0) << b.text;
        EXPECT_TRUE(contains(b.text, "3 frames: first")) << b.text;
        EXPECT_LE(compareImages(readPng(one), readPng(three)).maxAbs, 1.0 / 255.0) << renderer;
        std::ifstream f(stats);
        const auto j = nlohmann::json::parse(f);
        EXPECT_EQ(j.at("frameMs").size(), 3u);
        EXPECT_EQ(j.at("bricksUploaded").get<int>(), 0) << renderer << ": the last frame is warm";
    }
    auto bad = brickcast("render " + store + " -o " + dir.file("x.png") + " --repeat 0");
    EXPECT_NE(bad.exitCode, 0);
    EXPECT_TRUE(contains(bad.text, "--repeat")) << bad.text;
}

// --reference --converge: the step found and every halving's difference go into --stats; bad
// tolerances and a --converge without --reference are refused before anything is drawn.
TEST_F(RenderCli, ConvergeWritesTheStepAndTheDifferencesAndRefusesBadTolerances) {
    const std::string png = dir.file("conv.png"), stats = dir.file("conv.json");
    const std::string args = " --size 32,24 --tf ct-skin --orbit 40,25 --reference";
    auto a = brickcast("render " + store + " -o " + png + args +
                       " --converge 0.02 --converge-floor 0.25 --stats " + stats);
    ASSERT_EQ(a.exitCode, 0) << a.text;
    std::ifstream f(stats);
    const auto c = nlohmann::json::parse(f).at("convergence");
    const auto& steps = c.at("steps");
    ASSERT_GE(steps.size(), 2u);
    EXPECT_TRUE(steps[0].at("maxAbsToPrevious").is_null());
    EXPECT_EQ(c.at("toleranceRgba").get<double>(), 0.02);
    const double last = steps.back().at("maxAbsToPrevious").get<double>();
    EXPECT_EQ(c.at("converged").get<bool>(), last < 0.02) << a.text;
    EXPECT_EQ(c.at("imageStepVoxels").get<double>(), steps.back().at("stepVoxels").get<double>());
    for (const std::string bad : {"0", "-0.1", "nan", "inf", "x"}) {
        auto r = brickcast("render " + store + " -o " + png + args + " --converge " + bad);
        EXPECT_NE(r.exitCode, 0) << bad;
        EXPECT_TRUE(contains(r.text, "--converge")) << r.text;
    }
    auto r = brickcast("render " + store + " -o " + png + " --size 8,8 --converge");
    EXPECT_NE(r.exitCode, 0);
    EXPECT_TRUE(contains(r.text, "--converge needs --reference")) << r.text;
}

TEST_F(RenderCli, BadOptionsAndTransferFunctionsAreNamed) {
    const std::string out = dir.file("x.png");
    auto size = brickcast("render " + store + " -o " + out + " --size 0,64");
    EXPECT_NE(size.exitCode, 0);
    EXPECT_TRUE(contains(size.text, "--size")) << size.text;
    auto eye = brickcast("render " + store + " -o " + out + " --eye 1,2,nan --target 0,0,0");
    EXPECT_NE(eye.exitCode, 0);
    EXPECT_TRUE(contains(eye.text, "--eye")) << eye.text;
    const std::string tf = dir.file("bad.json");
    test::writeFile(tf, std::string(R"({"points":[{"value":1,"rgba":[1,1,1,2]}]})"));
    auto bad = brickcast("render " + store + " -o " + out + " --tf " + tf);
    EXPECT_NE(bad.exitCode, 0);
    EXPECT_TRUE(contains(bad.text, "bad.json") && contains(bad.text, "points[0].rgba[3]"))
        << bad.text;
    auto preset = brickcast("render " + store + " -o " + out + " --tf no-such-preset");
    EXPECT_NE(preset.exitCode, 0);
    EXPECT_TRUE(contains(preset.text, "ct-bone")) << "lists the presets: " << preset.text;
    auto skip = brickcast("render " + store + " -o " + out + " --skip sometimes");
    EXPECT_NE(skip.exitCode, 0);
    EXPECT_TRUE(contains(skip.text, "sometimes")) << skip.text;
    EXPECT_FALSE(std::filesystem::exists(out));
}

// --mode, --iso, --crop and --clip: a MIP of a cropped, clipped volume is the reference's
// image; bad values are named; a renderer that draws composite only says so.
TEST_F(RenderCli, ModesCropsAndClipsAreDrawnAndBadOnesNamed) {
    const std::string cpu = dir.file("cpu.png"), ref = dir.file("ref.png"),
                      stats = dir.file("s.json");
    const std::string view = " --size 64,64 --tf ct-bone --orbit 40,25 --mode mip"
                             " --crop 2,60,2,60,4,40 --clip=-1,0.2,0,48";
    auto a =
        brickcast("render " + store + " -o " + cpu + view + " --renderer cpu --stats " + stats);
    ASSERT_EQ(a.exitCode, 0) << a.text;
    auto b = brickcast("render " + store + " -o " + ref + view + " --reference");
    ASSERT_EQ(b.exitCode, 0) << b.text;
    EXPECT_LE(compareImages(readPng(cpu), readPng(ref)).maxAbs, 1.0 / 255.0 + 1e-6);
    std::ifstream f(stats);
    EXPECT_EQ(nlohmann::json::parse(f).at("mode"), "mip");
    const std::string still = dir.file("still.png"); // the running skip off: the same image
    auto c =
        brickcast("render " + store + " -o " + still + view + " --renderer cpu --no-running-skip");
    ASSERT_EQ(c.exitCode, 0) << c.text;
    EXPECT_EQ(compareImages(readPng(still), readPng(cpu)).maxAbs, 0.0);
    auto iso = brickcast("render " + store + " -o " + cpu + " --size 32,32 --mode iso --iso 900");
    EXPECT_EQ(iso.exitCode, 0) << iso.text;
    // --cap: the cut faces drawn, the reference's image, not the uncapped one.
    const std::string capView = " --size 64,64 --tf ct-bone --orbit 40,25 --crop 2,60,2,60,4,40"
                                " --clip=-1,0.2,0,48 --cap";
    const std::string capped = dir.file("capped.png"), cappedRef = dir.file("capped-ref.png"),
                      uncapped = dir.file("uncapped.png");
    for (const auto& [png, how] : {std::pair{capped, capView + " --renderer cpu"},
                                   std::pair{cappedRef, capView + " --reference"}}) {
        auto r = brickcast("render " + store + " -o " + png + how);
        ASSERT_EQ(r.exitCode, 0) << r.text;
    }
    EXPECT_LE(compareImages(readPng(capped), readPng(cappedRef)).maxAbs, 2.0 / 255.0 + 1e-6);
    auto u = brickcast("render " + store + " -o " + uncapped +
                       " --size 64,64 --tf ct-bone "
                       "--orbit 40,25 --crop 2,60,2,60,4,40 --clip=-1,0.2,0,48 --renderer cpu");
    ASSERT_EQ(u.exitCode, 0) << u.text;
    EXPECT_GT(compareImages(readPng(capped), readPng(uncapped)).maxAbs, 0.05);
    const std::string out = dir.file("x.png");
    const std::pair<std::string, std::string> bad[] = {
        {" --mode iso", "--iso"},
        {" --iso 5", "--iso"},
        {" --mode max", "max"},
        {" --mode iso --iso 1e9", "iso:"},
        {" --crop 10,5,0,1,0,1", "crop:"},
        {" --crop 1,2,3", "--crop"},
        {" --clip 0,0,0,1", "clip[0]: the normal is zero"},
        {" --clip 1,0,0,nan", "--clip"},
        {" --renderer splat --mode mip", "splatters: composite only, not mip"},
        {" --mode mip --crop 1,20,1,20,1,20 --cap", "cap: mode mip draws no surface"},
    };
    for (const auto& [args, named] : bad) {
        auto r = brickcast("render " + store + " -o " + out + " --size 32,32" + args);
        EXPECT_NE(r.exitCode, 0) << args;
        EXPECT_TRUE(contains(r.text, named)) << args << ": " << r.text;
    }
    EXPECT_FALSE(std::filesystem::exists(out));
}

// GLVND with no vendor library: EGL offers no display at all.
const std::string kNoEgl =
    "__EGL_VENDOR_LIBRARY_FILENAMES=/nonexistent.json EGL_PLATFORM=surfaceless";

TEST_F(RenderCli, NoUsableEglIsAClearErrorNotACrash) {
    auto r = brickcast("render " + store + " -o " + dir.file("x.png") + " --renderer gpu", kNoEgl);
    EXPECT_EQ(r.exitCode, 1) << r.text;
    EXPECT_TRUE(contains(r.text, "no usable EGL")) << r.text;
}

// The default, auto, with no EGL at all: the CPU raycaster draws, and the stats and the log
// say why; the image is --renderer cpu's.
TEST_F(RenderCli, AutoWithoutEglDrawsOnTheCpuRaycasterAndSaysWhy) {
    const std::string autoPng = dir.file("auto.png"), cpuPng = dir.file("cpu.png"),
                      stats = dir.file("auto.json");
    const std::string args = " --size 64,48 --tf ct-bone --orbit 40,25";
    auto a = brickcast("render " + store + " -o " + autoPng + args + " --stats " + stats, kNoEgl);
    ASSERT_EQ(a.exitCode, 0) << a.text;
    EXPECT_TRUE(contains(a.text, "render: auto: cpu (no EGL context: no usable EGL")) << a.text;
    std::ifstream f(stats);
    const auto j = nlohmann::json::parse(f);
    EXPECT_EQ(j.at("rendererName"), "cpu");
    EXPECT_TRUE(contains(j.at("rendererChoice").get<std::string>(),
                         "auto: cpu (no EGL context: no usable EGL"))
        << j.at("rendererChoice");
    auto c = brickcast("render " + store + " -o " + cpuPng + args + " --renderer cpu", kNoEgl);
    ASSERT_EQ(c.exitCode, 0) << c.text;
    EXPECT_FALSE(contains(c.text, "render: auto")) << "a named renderer is not announced";
    EXPECT_EQ(compareImages(readPng(autoPng), readPng(cpuPng)).maxAbs, 0.0);
}

// GL: `brickcast render` without --renderer is auto, decided from this machine's GL_RENDERER
// (on llvmpipe, the dev VM and CI: the CPU raycaster), and draws --renderer NAME's image.
TEST_F(RenderCli, AutoIsTheDefaultAndFollowsThisMachinesGlRenderer) {
    const EglContext& gl = test::glContext();
    const std::string expected = gl.software() ? "cpu" : "gpu";
    if (contains(gl.renderer(), "llvmpipe")) {
        EXPECT_EQ(expected, "cpu") << gl.renderer();
    }
    const std::string autoPng = dir.file("auto.png"), namedPng = dir.file("named.png"),
                      stats = dir.file("auto.json");
    const std::string args = " --size 64,48 --tf ct-bone --orbit 40,25";
    auto a = brickcast("render " + store + " -o " + autoPng + args + " --stats " + stats);
    ASSERT_EQ(a.exitCode, 0) << a.text;
    const std::string why = "auto: " + expected + " (GL_RENDERER '" + gl.renderer() + "' is a " +
                            (gl.software() ? "software rasteriser)" : "hardware GPU)");
    EXPECT_TRUE(contains(a.text, "render: " + why)) << a.text;
    std::ifstream f(stats);
    const auto j = nlohmann::json::parse(f);
    EXPECT_EQ(j.at("rendererName"), expected);
    EXPECT_EQ(j.at("rendererChoice"), why);
    if (gl.software()) {
        EXPECT_TRUE(contains(j.at("renderer").get<std::string>(), "CPU raycaster"));
    }
    auto n = brickcast("render " + store + " -o " + namedPng + args + " --renderer " + expected);
    ASSERT_EQ(n.exitCode, 0) << n.text;
    EXPECT_EQ(compareImages(readPng(autoPng), readPng(namedPng)).maxAbs, 0.0);
}

} // namespace
} // namespace bc::render
