// The `brickcast` command line end to end: ingest, info, verify, extract, and its errors.
#include "tests/TestSupport.h"

#include <array>
#include <cstdio>
#include <sys/wait.h>

namespace {

using Output = bc::test::CommandOutput;

Output brickcast(const std::string& args) {
    return bc::test::runCommand(std::string(BC_BRICKCAST_EXE) + " " + args);
}

bool contains(const std::string& text, const std::string& part) {
    return text.find(part) != std::string::npos;
}

TEST(CliTest, IngestInfoVerifyExtractRoundTrip) {
    bc::test::TempDir dir;
    const std::string store = dir.file("c.bcs"), raw = dir.file("c.raw");
    auto ingest = brickcast("ingest synth:checker --dims 40,30,20 --brick 16 -o " + store);
    ASSERT_EQ(ingest.exitCode, 0) << ingest.text;
    auto info = brickcast("info " + store);
    ASSERT_EQ(info.exitCode, 0) << info.text;
    EXPECT_TRUE(contains(info.text, "40 x 30 x 20 u8")) << info.text;
    auto json = brickcast("info --json " + store);
    EXPECT_TRUE(contains(json.text, "\"dims\"")) << json.text;
    EXPECT_TRUE(contains(json.text, "\"histogram\"")) << json.text;
    auto verify = brickcast("verify " + store);
    EXPECT_EQ(verify.exitCode, 0) << verify.text;
    auto extract = brickcast("extract " + store + " -o " + raw);
    ASSERT_EQ(extract.exitCode, 0) << extract.text;
    EXPECT_EQ(std::filesystem::file_size(raw), 40u * 30 * 20);
    // Re-ingesting the extracted raw and extracting again gives the same bytes.
    ASSERT_EQ(brickcast("ingest " + raw + " --dims 40,30,20 --type u8 -q -o " + dir.file("d.bcs"))
                  .exitCode,
              0);
    ASSERT_EQ(brickcast("extract " + dir.file("d.bcs") + " -o " + dir.file("d.raw")).exitCode, 0);
    EXPECT_TRUE(bc::test::readFile(raw) == bc::test::readFile(dir.file("d.raw")));
    auto level1 = brickcast("extract " + store + " --level 1 -o " + dir.file("l1.raw"));
    ASSERT_EQ(level1.exitCode, 0) << level1.text;
    EXPECT_EQ(std::filesystem::file_size(dir.file("l1.raw")), 20u * 15 * 10);
}

TEST(CliTest, VerifyNamesTheCorruptBrickAndFails) {
    bc::test::TempDir dir;
    const std::string store = dir.file("v.bcs");
    ASSERT_EQ(brickcast("ingest synth:phantom --dims 48,48,48 --brick 16 -q -o " + store).exitCode,
              0);
    auto bytes = bc::test::readFile(store);
    bytes[4096 + 100] ^= 0x01; // inside the first brick written
    bc::test::writeFile(store, bytes.data(), bytes.size());
    auto verify = brickcast("verify " + store);
    EXPECT_NE(verify.exitCode, 0);
    EXPECT_TRUE(contains(verify.text, "corrupt: ")) << verify.text;
    EXPECT_TRUE(contains(verify.text, "brick L")) << verify.text;
    EXPECT_TRUE(contains(verify.text, "1 corrupt brick")) << verify.text;
}

TEST(CliTest, BadInputIsNamedAndLeavesNoStore) {
    bc::test::TempDir dir;
    const std::string store = dir.file("x.bcs");
    auto missing =
        brickcast("ingest " + dir.file("nope.raw") + " --dims 4,4,4 --type u8 -o " + store);
    EXPECT_EQ(missing.exitCode, 1);
    EXPECT_TRUE(contains(missing.text, "nope.raw")) << missing.text;
    bc::test::writeFile(dir.file("blob.bin"), std::string(64, 'x'));
    auto noDims = brickcast("ingest " + dir.file("blob.bin") + " -o " + store);
    EXPECT_EQ(noDims.exitCode, 1);
    EXPECT_TRUE(contains(noDims.text, "blob.bin: dims")) << noDims.text;
    auto badType =
        brickcast("ingest " + dir.file("blob.bin") + " --dims 4,4,4 --type u32 -o " + store);
    EXPECT_TRUE(contains(badType.text, "blob.bin: type")) << badType.text;
    auto badKind = brickcast("ingest synth:teapot --dims 4,4,4 -o " + store);
    EXPECT_TRUE(contains(badKind.text, "synth:teapot")) << badKind.text;
    auto badDims = brickcast("ingest synth:checker --dims 4,x,4 -o " + store);
    EXPECT_NE(badDims.exitCode, 0);
    EXPECT_TRUE(contains(badDims.text, "--dims")) << badDims.text;
    EXPECT_FALSE(std::filesystem::exists(store));
    auto notStore = brickcast("info " + dir.file("blob.bin"));
    EXPECT_EQ(notStore.exitCode, 1);
    EXPECT_TRUE(contains(notStore.text, "blob.bin")) << notStore.text;
}

TEST(CliTest, EveryCommandHasHelp) {
    for (std::string c : {"", "ingest", "info", "verify", "extract", "demo"}) {
        auto help = brickcast(c + " --help");
        EXPECT_EQ(help.exitCode, 0) << c;
        EXPECT_TRUE(contains(help.text, "Usage")) << help.text;
    }
}

} // namespace
