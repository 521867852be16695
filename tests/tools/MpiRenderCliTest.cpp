// `brickcast render --mpi` under mpirun: 2 and 4 ranks, each drawing its part of
// the brick grid with the CPU raycaster, composited by direct send, give the one-process frame
// on a real scan and a generated volume (early termination off: the same samples, equal within
// float rounding, so within one 8-bit level; on: within its bound); a volume of fewer bricks
// than ranks; a rank that cannot open its store ends the job with its error, not a hang.
#include "render/Image.h"
#include "render/ImageMetrics.h"
#include "tests/render/RenderTestSupport.h"

#include <nlohmann/json.hpp>

#include <chrono>
#include <fstream>

namespace bc::render {
namespace {

using Output = bc::test::CommandOutput;

Output brickcast(const std::string& args) {
    return bc::test::runCommand(std::string(BC_BRICKCAST_EXE) + " " + args);
}

#ifdef BC_MPIEXEC
Output mpirun(int ranks, const std::string& args) {
    // As root in CI, and more ranks than the machine's 2 cores.
    return bc::test::runCommand(std::string(BC_MPIEXEC) +
                                " --allow-run-as-root --oversubscribe -np " +
                                std::to_string(ranks) + " " + BC_BRICKCAST_EXE + " " + args);
}
#endif

nlohmann::json readJson(const std::string& path) {
    std::ifstream f(path);
    return nlohmann::json::parse(f);
}

class MpiRenderCli : public ::testing::Test {
  protected:
    void SetUp() override {
#ifndef BC_MPIEXEC
        if (test::dataRequired()) FAIL() << "built without MPI (libopenmpi-dev)";
        GTEST_SKIP() << "built without MPI (libopenmpi-dev)";
#endif
    }
    /// The one-process frame and the frame of `ranks` ranks of `renderer` (cpu or gpu);
    /// returns the latter's stats. Without early termination, the ranks take the one process's
    /// samples unless `runningSkip` (a maximum or minimum: each rank leaps by its own rays'
    /// values so far, which start afresh in its part).
    nlohmann::json expectRanksDrawTheFrame(const std::string& store, const std::string& view,
                                           int ranks, bool ert, std::uint64_t* samples = nullptr,
                                           const std::string& renderer = "cpu",
                                           bool runningSkip = false) {
#ifdef BC_MPIEXEC
        const std::string one = dir.file("one.png"), many = dir.file("many.png"),
                          oneStats = dir.file("one.json"), manyStats = dir.file("many.json");
        const std::string args = " --size 120,96 " + view + (ert ? "" : " --ert off");
        auto a = brickcast("render " + store + " -o " + one + " --renderer " + renderer +
                           " --stats " + oneStats + args);
        EXPECT_EQ(a.exitCode, 0) << a.text;
        auto b = mpirun(ranks, "render " + store + " -o " + many + " --mpi --renderer " + renderer +
                                   " --stats " + manyStats + args);
        EXPECT_EQ(b.exitCode, 0) << b.text;
        if (a.exitCode != 0 || b.exitCode != 0) return {};
        const ImageComparison c = compareImages(readPng(one), readPng(many));
        // ERT off: float rounding (under 1e-6) flips at most an 8-bit rounding; on: each
        // rank stops its own segment, within early termination's bound (render/SCALEOUT.md).
        EXPECT_LE(c.maxAbs, (ert ? 1.25 * 0.01 : 0.0) + 1.0 / 255.0 + 1e-6)
            << ranks << " ranks, " << view << (ert ? ", ERT on" : ", ERT off");
        const auto j = readJson(manyStats);
        EXPECT_EQ(j.at("ranks").get<int>(), ranks);
        EXPECT_EQ(j.at("perRank").size(), std::size_t(ranks));
        if (!ert && !runningSkip) { // the ranks took exactly the one process's samples
            EXPECT_EQ(j.at("samples").get<std::uint64_t>(),
                      readJson(oneStats).at("samples").get<std::uint64_t>())
                << ranks << " ranks, " << view;
        }
        if (samples) *samples = j.at("samples").get<std::uint64_t>();
        return j;
#else
        return {};
#endif
    }
    void expectRanksDrawTheOneProcessGpuFrame(int ranks);
    /// The real scan cthead ingested in bricks of 32 into the scratch folder: its store, or
    /// "" when the data is missing (skipped) or the ingest failed (a failure recorded).
    std::string ingestCthead() {
        if (!test::haveData("stanford_cthead_256x256x113_uint16.raw")) {
            test::missingData("scan cthead");
            return {};
        }
        const std::string store = dir.file("cthead.bcs");
        auto r = brickcast("ingest " + test::dataPath("stanford_cthead_256x256x113_uint16.raw") +
                           " --dims 256,256,113 --type u16 --spacing 1,1,2 --endian little "
                           "--brick 32 -q -o " +
                           store);
        if (r.exitCode != 0) {
            ADD_FAILURE() << r.text;
            return {};
        }
        return store;
    }

    test::TempDir dir;
};

TEST_F(MpiRenderCli, TwoAndFourRanksDrawTheOneProcessFrameOfARealScan) {
    const std::string store = ingestCthead();
    if (store.empty()) return;
    for (const char* view :
         {"--tf ct-bone --orbit 30,20", "--tf ct-skin --orbit 210,10 --up 0,0,-1"})
        for (int ranks : {2, 4}) {
            const auto j = expectRanksDrawTheFrame(store, view, ranks, false);
            if (j.is_null()) continue;
            // Every rank owns bricks and stored bytes; the parts are disjoint boxes.
            for (const auto& p : j.at("perRank")) {
                EXPECT_GT(p.at("bricks").get<int>(), 0);
                EXPECT_GT(p.at("storedBytes").get<std::uint64_t>(), 0u);
            }
            EXPECT_GT(j.at("bytesComposited").get<std::uint64_t>(), 0u);
            EXPECT_GE(j.at("imbalance").get<double>(), 1.0);
            expectRanksDrawTheFrame(store, view, ranks, true);
        }
}

// Each mode, whole and cut, across two ranks: the projections combine by max, min or sums
// (render/Composite.h), the isosurface over front to back (the front-most hit).
TEST_F(MpiRenderCli, TwoRanksDrawTheOneProcessFrameOfEveryModeWholeAndCut) {
    const std::string store = ingestCthead();
    if (store.empty()) return;
    // Without early termination the ranks take the one process's samples, but for a maximum
    // or minimum (each rank's running skip knows only its own part's values). An isosurface's
    // ray stops at its hit in each part, so the ranks take more: it is compared as with early
    // termination (no count of samples).
    for (const std::string mode : {"mip", "minip", "average", "iso --iso 1200"})
        for (const char* cut : {"", " --crop 20,230,10,250,20,200 --clip=-1,0.4,0.2,180"})
            expectRanksDrawTheFrame(store, "--tf ct-bone --orbit 30,20 --mode " + mode + cut, 2,
                                    mode.rfind("iso", 0) == 0, nullptr, "cpu",
                                    mode == "mip" || mode == "minip");
}

TEST_F(MpiRenderCli, AGeneratedVolumeUnderAHostBudgetPerRankSmallerThanIt) {
    // 192^3 u8 vessels (7 MiB of voxels, 6^3 bricks of 32): each rank's host cache holds
    // 1 MiB, so every rank draws its part in batches, as one process does.
    const std::string store = dir.file("vessels.bcs");
    auto r = brickcast("ingest synth:vessels --dims 192,192,192 --brick 32 -q -o " + store);
    ASSERT_EQ(r.exitCode, 0) << r.text;
    for (int ranks : {2, 4})
        expectRanksDrawTheFrame(store, "--tf vessels --orbit 60,30 --host-budget-mb 1", ranks,
                                false);
}

/// Every rank makes its own GL context (llvmpipe in CI): small frames of a generated volume under
/// a 1 MiB host budget per rank and of a real scan, over `ranks`.
void MpiRenderCli::expectRanksDrawTheOneProcessGpuFrame(int ranks) {
    const std::string vessels = dir.file("vessels.bcs");
    auto r = brickcast("ingest synth:vessels --dims 128,128,128 --brick 32 -q -o " + vessels);
    ASSERT_EQ(r.exitCode, 0) << r.text;
    for (bool ert : {false, true})
        expectRanksDrawTheFrame(vessels, "--tf vessels --orbit 60,30 --host-budget-mb 1", ranks,
                                ert, nullptr, "gpu");
    if (!test::haveData("vtk_headsq_quarter_64x64x93_uint16.raw"))
        return test::missingData("scan headsq");
    const std::string headsq = dir.file("headsq.bcs");
    r = brickcast("ingest " + test::dataPath("vtk_headsq_quarter_64x64x93_uint16.raw") +
                  " --dims 64,64,93 --type u16 --spacing 3.2,3.2,1.5 --endian little --brick 32 "
                  "-q -o " +
                  headsq);
    ASSERT_EQ(r.exitCode, 0) << r.text;
    expectRanksDrawTheFrame(headsq, "--tf ct-bone --orbit 120,-30", ranks, false, nullptr, "gpu");
}

TEST_F(MpiRenderCli, TwoRanksDrawTheOneProcessGpuFrame) {
    expectRanksDrawTheOneProcessGpuFrame(2);
}

// Four ranks of llvmpipe on a 2-core machine take a minute or more: label "slow" (the CPU
// frames cover four ranks in the fast suite).
using MpiRenderCliSlow = MpiRenderCli;
TEST_F(MpiRenderCliSlow, FourRanksDrawTheOneProcessGpuFrame) {
    expectRanksDrawTheOneProcessGpuFrame(4);
}

TEST_F(MpiRenderCli, MoreRanksThanBricksLeaveRanksWithNothingToDraw) {
    const std::string store = dir.file("small.bcs");
    auto r = brickcast("ingest synth:phantom --dims 40,40,20 --brick 32 -q -o " + store);
    ASSERT_EQ(r.exitCode, 0) << r.text; // 2 x 2 x 1 bricks
    const auto j = expectRanksDrawTheFrame(store, "--tf ct-skin --orbit 30,20", 6, false);
    if (j.is_null()) return;
    int empty = 0;
    for (const auto& p : j.at("perRank"))
        if (p.at("bricks").get<int>() == 0) {
            ++empty;
            EXPECT_EQ(p.at("samples").get<std::uint64_t>(), 0u);
        }
    EXPECT_EQ(empty, 2);
}

TEST_F(MpiRenderCli, ARankThatCannotOpenItsStoreEndsTheJobWithItsError) {
#ifdef BC_MPIEXEC
    const std::string store = dir.file("small.bcs"), missing = dir.file("missing.bcs");
    ASSERT_EQ(brickcast("ingest synth:phantom --dims 40,40,40 --brick 16 -q -o " + store).exitCode,
              0);
    // Rank 1 is handed a store that is not there (as if its node did not mount the share).
    const std::string args =
        " --allow-run-as-root --oversubscribe -np 1 " + std::string(BC_BRICKCAST_EXE) + " render ";
    const auto start = std::chrono::steady_clock::now();
    auto r = bc::test::runCommand(std::string(BC_MPIEXEC) + args + store + " -o " +
                                  dir.file("a.png") + " --mpi --mpi-timeout-s 20 :" + args +
                                  missing + " -o " + dir.file("b.png") + " --mpi");
    const double s =
        std::chrono::duration<double>(std::chrono::steady_clock::now() - start).count();
    EXPECT_NE(r.exitCode, 0);
    EXPECT_NE(r.text.find("rank 1 of 2"), std::string::npos) << r.text;
    EXPECT_NE(r.text.find("missing.bcs"), std::string::npos) << r.text;
    EXPECT_LT(s, 60.0);
#endif
}

TEST_F(MpiRenderCli, MpiRefusesOtherRenderers) {
#ifdef BC_MPIEXEC
    const std::string store = dir.file("small.bcs");
    ASSERT_EQ(brickcast("ingest synth:phantom --dims 40,40,40 --brick 16 -q -o " + store).exitCode,
              0);
    auto r = mpirun(2, "render " + store + " -o " + dir.file("a.png") + " --mpi --reference");
    EXPECT_NE(r.exitCode, 0);
    EXPECT_NE(r.text.find("--mpi draws with the CPU or GPU raycaster"), std::string::npos)
        << r.text;
    r = mpirun(2, "render " + store + " -o " + dir.file("a.png") + " --mpi --renderer splat");
    EXPECT_NE(r.exitCode, 0);
    EXPECT_NE(r.text.find("not splat"), std::string::npos) << r.text;
#endif
}

} // namespace
} // namespace bc::render
