// `brickcast ingest` on the TIFF, Zarr, HDF5, MetaImage and .vti formats, end to end: the dispatch
// by extension and folder content, --dataset (HDF5), --level (OME-Zarr), --spacing over a TIFF's
// own, --stats. One small volume written by the independent writers (tests/tools/writers/
// write_cli_inputs.py: h5py, zarr, tifffile, VTK) must ingest and extract to its raw bytes.
#include "tests/TestSupport.h"

#include <nlohmann/json.hpp>

#include <fstream>

namespace {

using bc::test::CommandOutput;

CommandOutput brickcast(const std::string& args) {
    return bc::test::runCommand(std::string(BC_BRICKCAST_EXE) + " " + args);
}

bool contains(const std::string& text, const std::string& part) {
    return text.find(part) != std::string::npos;
}

/// The writer's folder, written once for the suite; empty when its Python modules are missing
/// (a skip, or a failure under CI=true, which installs them).
class FormatsCli : public ::testing::Test {
  protected:
    static void SetUpTestSuite() {
        sDir = std::make_unique<bc::test::TempDir>();
        const CommandOutput r = bc::test::runCommand("/usr/bin/python3 '" BC_TESTS_DIR
                                                     "/tools/writers/write_cli_inputs.py' '" +
                                                     sDir->path().string() + "'");
        sWritten = r.exitCode == 0;
        sWriterOutput = r.text;
    }
    static void TearDownTestSuite() { sDir.reset(); }

    void SetUp() override {
        if (sWritten) return;
        if (bc::test::dataRequired())
            FAIL() << "the writers (h5py, zarr, tifffile, vtk for /usr/bin/python3) failed under "
                      "CI=true, which installs them: "
                   << sWriterOutput;
        GTEST_SKIP() << "the independent writers are missing: " << sWriterOutput;
    }

    static std::string at(const std::string& name) { return sDir->file(name); }

    /// Ingests `input` (with `options`), extracts level 0 and compares it with vol.raw.
    static void expectRoundTrip(const std::string& input, const std::string& options) {
        bc::test::TempDir dir;
        const std::string store = dir.file("s.bcs"), raw = dir.file("s.raw");
        const CommandOutput ingest =
            brickcast("ingest '" + input + "' " + options + " -q -o " + store);
        ASSERT_EQ(ingest.exitCode, 0) << input << ": " << ingest.text;
        ASSERT_EQ(brickcast("extract " + store + " -o " + raw).exitCode, 0);
        EXPECT_EQ(bc::test::readFile(raw), bc::test::readFile(at("vol.raw"))) << input;
    }

    static inline std::unique_ptr<bc::test::TempDir> sDir;
    static inline bool sWritten = false;
    static inline std::string sWriterOutput;
};

TEST_F(FormatsCli, EveryFormatIngestsToTheSourceVoxels) {
    expectRoundTrip(at("scan.h5"), "--dataset /a/vol");
    expectRoundTrip(at("ome.zarr"), "");
    expectRoundTrip(at("slices"), "");
    expectRoundTrip(at("vol.mha"), "");
    expectRoundTrip(at("vol.vti"), "");
}

TEST_F(FormatsCli, Hdf5WithoutDatasetListsTheCandidates) {
    bc::test::TempDir dir;
    const CommandOutput r = brickcast("ingest " + at("scan.h5") + " -o " + dir.file("s.bcs"));
    EXPECT_NE(r.exitCode, 0);
    EXPECT_TRUE(contains(r.text, "scan.h5")) << r.text;
    EXPECT_TRUE(contains(r.text, "dataset")) << r.text;
    EXPECT_TRUE(contains(r.text, "/a/vol")) << r.text;
    EXPECT_FALSE(contains(r.text, "/b/flat")) << "a 2D dataset is no candidate: " << r.text;
    EXPECT_FALSE(std::filesystem::exists(dir.file("s.bcs")));
}

TEST_F(FormatsCli, OmeZarrLevelAndSpacing) {
    bc::test::TempDir dir;
    const std::string store = dir.file("s.bcs");
    const CommandOutput ingest =
        brickcast("ingest " + at("ome.zarr") + " --level 1 -q -o " + store);
    ASSERT_EQ(ingest.exitCode, 0) << ingest.text;
    const CommandOutput info = brickcast("info --json " + store);
    const auto j = nlohmann::json::parse(info.text);
    EXPECT_EQ(j["dims"], nlohmann::json({20, 15, 10})) << info.text;
    // (z, y, x) scale (4, 2, 2) micrometres -> (x, y, z) spacing in mm.
    const auto spacing = j["spacing_mm"];
    ASSERT_EQ(spacing.size(), 3u) << info.text;
    EXPECT_NEAR(spacing[0].get<double>(), 0.002, 1e-12);
    EXPECT_NEAR(spacing[1].get<double>(), 0.002, 1e-12);
    EXPECT_NEAR(spacing[2].get<double>(), 0.004, 1e-12);
    const CommandOutput past = brickcast("ingest " + at("ome.zarr") + " --level 2 -o " + store);
    EXPECT_NE(past.exitCode, 0);
    EXPECT_TRUE(contains(past.text, "level")) << past.text;
}

TEST_F(FormatsCli, SpacingOverridesTheTiffsAndStatsSayWhereTheTimeWent) {
    bc::test::TempDir dir;
    const std::string store = dir.file("s.bcs"), stats = dir.file("s.json");
    const CommandOutput ingest = brickcast(
        "ingest " + at("slices") + " --spacing 0.5,0.25,2 -q --stats " + stats + " -o " + store);
    ASSERT_EQ(ingest.exitCode, 0) << ingest.text;
    const auto info = nlohmann::json::parse(brickcast("info --json " + store).text);
    EXPECT_EQ(info["spacing_mm"], nlohmann::json({0.5, 0.25, 2.0}));
    std::ifstream in(stats);
    const auto s = nlohmann::json::parse(in);
    EXPECT_EQ(s["sourceBytes"], 40u * 30 * 20 * 2);
    for (const char* stage :
         {"read", "cut", "ringWait", "brickCut", "compress", "write", "histogram", "finish"})
        EXPECT_GE(s["times"][stage].get<double>(), 0.0) << stage;
    EXPECT_GT(s["seconds"].get<double>(), 0.0);
}

} // namespace
