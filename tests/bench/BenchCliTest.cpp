// The rendering benchmarks' command lines end to end on the smallest real scan: their options,
// the rows and columns of their tables and CSV, and bad input named. Never a time.
#include "tests/render/RenderTestSupport.h"

#include <array>
#include <fstream>
#include <map>
#include <sstream>
#include <sys/wait.h>

namespace bc::bench {
namespace {

using Output = bc::test::CommandOutput;

Output run(const std::string& exe, const std::string& args) {
    return bc::test::runCommand(exe + " " + args);
}
Output benchRender(const std::string& args) {
    return run(BC_BENCH_RENDER_EXE, args);
}
Output benchSplat(const std::string& args) {
    return run(BC_BENCH_SPLAT_EXE, args);
}

bool contains(const std::string& text, const std::string& part) {
    return text.find(part) != std::string::npos;
}

// bc_bench_tunables: every tunable's values, one default row per tunable (its ratios' base),
// finite
// samples over oracle of at least 1 (no renderer takes fewer samples than are visible); bad
// input named.
TEST(BenchCli, TheTunablesSweepPrintsEveryValueAgainstTheDefault) {
    if (!test::realScan("hydrogen")) return test::missingData("scan hydrogen");
    test::TempDir dir;
    const std::string csv = dir.file("tunables.csv");
    auto r =
        run(BC_BENCH_TUNABLES_EXE, "--data " + std::string(BC_SHARED_DATA_DIR) +
                                       " --datasets hydrogen --size 24 --frames 2 --csv " + csv);
    ASSERT_EQ(r.exitCode, 0) << r.text;
    EXPECT_TRUE(contains(r.text, "### hydrogen / smoke")) << r.text;
    std::ifstream f(csv);
    std::string line;
    std::getline(f, line);
    EXPECT_EQ(line.rfind("dataset,tf,tunable,value,default,ms,ratio,samples_over_oracle,", 0), 0u)
        << line;
    std::map<std::string, int> values, defaults;
    while (std::getline(f, line)) {
        std::vector<std::string> cells;
        std::stringstream in(line);
        for (std::string c; std::getline(in, c, ',');)
            cells.push_back(c);
        ASSERT_EQ(cells.size(), 13u) << line;
        ++values[cells[2]];
        if (cells[4] == "1") {
            ++defaults[cells[2]];
            EXPECT_EQ(std::stod(cells[6]), 1.0) << "a default row is its tunable's ratios' base";
        }
        EXPECT_GE(std::stod(cells[7]), 1.0) << "fewer samples than the oracle's: " << line;
        EXPECT_FALSE(contains(line, "nan")) << line;
    }
    EXPECT_EQ(values, (std::map<std::string, int>{{"brick edge", 3},
                                                  {"leaf edge", 3},
                                                  {"map cell edge", 4},
                                                  {"octree ratio", 3},
                                                  {"octree level limit", 3}}));
    for (const auto& [tunable, n] : defaults)
        EXPECT_EQ(n, 1) << tunable << ": not one default value";
    EXPECT_EQ(defaults.size(), 5u);
    auto bad = run(BC_BENCH_TUNABLES_EXE, "--datasets hydrogen --path spiral");
    EXPECT_NE(bad.exitCode, 0);
    EXPECT_TRUE(contains(bad.text, "spiral")) << bad.text;
}

// bc_bench_render (formerly `brickcast bench`) on the smallest real scan: every technique set of
// every path, speed-ups over plain taken in the run, errors against the reference, a step sweep;
// bad lists named.
TEST(BenchCli, PrintsEveryTechniqueSetWithErrorsAndASweepAndNamesBadInput) {
    if (!test::realScan("hydrogen")) return test::missingData("scan hydrogen");
    test::TempDir dir;
    const std::string csv = dir.file("bench.csv");
    auto r = benchRender("--data " + std::string(BC_SHARED_DATA_DIR) +
                         " --datasets hydrogen --sizes 32 --frames 2 --steps 1,2 --no-rebuild-512"
                         " --no-generated --csv " +
                         csv);
    ASSERT_EQ(r.exitCode, 0) << r.text;
    std::ifstream f(csv);
    std::string line;
    std::getline(f, line);
    EXPECT_TRUE(contains(line, "samples_over_oracle")) << line;
    int paths = 0, sweeps = 0, plain = 0;
    while (std::getline(f, line)) {
        paths += line.starts_with("path,hydrogen,smoke,");
        sweeps += line.starts_with("sweep,hydrogen,smoke,orbit,32,all,");
        if (line.find(",plain,") != std::string::npos) {
            ++plain;
            EXPECT_TRUE(contains(line, ",1,")) << "plain's speed-up over itself: " << line;
        }
        EXPECT_FALSE(contains(line, "nan")) << line;
    }
    EXPECT_EQ(paths, 18) << "9 technique sets x 2 paths";
    EXPECT_EQ(sweeps, 2);
    EXPECT_EQ(plain, 2);
    auto bad = benchRender("--datasets hydrogen --paths spiral --no-rebuild-512 --no-generated");
    EXPECT_NE(bad.exitCode, 0);
    EXPECT_TRUE(contains(bad.text, "spiral")) << bad.text;
    auto none = benchRender("--datasets nosuchscan --no-generated");
    EXPECT_NE(none.exitCode, 0);
    EXPECT_TRUE(contains(none.text, "--datasets")) << none.text;
}

// bc_bench_splat (formerly `brickcast bench-splat`): the paper's three views per dataset (all
// splats, mixed, all points, as the splatter's own counts say), the raycaster sweep beside it,
// errors against the reference; bad sweeps named.
TEST(SplatBenchCli, PrintsTheFigure9ViewsBesideTheRaycasterSweepAndNamesBadInput) {
    if (!test::realScan("hydrogen")) return test::missingData("scan hydrogen");
    test::TempDir dir;
    const std::string csv = dir.file("splat.csv");
    auto r = benchSplat("--data " + std::string(BC_SHARED_DATA_DIR) +
                        " --datasets hydrogen,checker --size 48 --frames 1 --steps 1,2"
                        " --supersampling 1 --csv " +
                        csv);
    ASSERT_EQ(r.exitCode, 0) << r.text;
    EXPECT_TRUE(contains(r.text, "| All splats | Mixed | All points |")) << r.text;
    EXPECT_TRUE(contains(r.text, "| checker box 100^3 | checker | 100x100x100 | 1000000 |"))
        << r.text;
    std::ifstream f(csv);
    std::string line;
    std::getline(f, line);
    EXPECT_EQ(line, "dataset,tf,view,distance_factor,renderer,step,supersampling,ms,psnr_db,ssim,"
                    "splats,points,culled");
    int splatRows = 0, raycastRows = 0;
    while (std::getline(f, line)) {
        EXPECT_FALSE(contains(line, "nan")) << line;
        std::vector<std::string> cell;
        std::stringstream in(line);
        for (std::string c; std::getline(in, c, ',');)
            cell.push_back(c);
        cell.resize(13);
        if (cell[4] == "cpu raycaster") {
            ++raycastRows;
            EXPECT_GT(std::stod(cell[8]), 20.0) << line; // a PSNR, against the reference
        }
        if (cell[4] != "splatter") continue;
        ++splatRows;
        const double splats = std::stod(cell[10]), points = std::stod(cell[11]);
        EXPECT_GT(std::stod(cell[8]), 20.0) << line;
        if (cell[2] == "all splats") {
            EXPECT_TRUE(splats > 0 && points == 0) << line;
        } else if (cell[2] == "mixed") {
            EXPECT_TRUE(splats > 0 && points > 0) << line;
        } else {
            EXPECT_EQ(cell[2], "all points");
            EXPECT_TRUE(splats == 0 && points > 0) << line;
        }
    }
    EXPECT_EQ(splatRows, 6) << "3 views x 2 datasets";
    EXPECT_EQ(raycastRows, 12) << "2 steps x 3 views x 2 datasets";
    auto step = benchSplat("--datasets hydrogen --steps 0");
    EXPECT_NE(step.exitCode, 0);
    EXPECT_TRUE(contains(step.text, "--steps")) << step.text;
    auto ss = benchSplat("--datasets hydrogen --supersampling 1.5");
    EXPECT_NE(ss.exitCode, 0);
    EXPECT_TRUE(contains(ss.text, "--supersampling")) << ss.text;
}

} // namespace
} // namespace bc::bench
