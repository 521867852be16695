// Transfer functions named on a command line: presets by name, files by path, and the errors
// that name the file at fault. Only programs read such files (the daemon never does for a
// client).
#include "tools/TransferFunctionFile.h"
#include "../TestSupport.h"

#include <string>

namespace bc::tools {
namespace {

render::VolumeValueStats stats() {
    return render::VolumeValueStats{0, 255, {10, 5, 5, 5}};
}

std::string doc(const std::string& point) {
    return R"({"name": "t", "points": [)" + point + "]}";
}

TEST(TransferFunctionFileTest, NamesTheFileOrListsThePresets) {
    try {
        loadTransferFunction("no-such-preset", stats());
        ADD_FAILURE() << "accepted an unknown preset";
    } catch (const render::RenderInputError& e) {
        EXPECT_EQ(e.file(), "no-such-preset");
        EXPECT_NE(std::string(e.what()).find("ct-bone, ct-skin, grey, mr, smoke, vessels"),
                  std::string::npos)
            << e.what();
    }
    EXPECT_THROW(loadTransferFunction("/no/such/dir/tf.json", stats()), render::RenderInputError);
    test::TempDir dir;
    const std::string path = dir.file("broken.json");
    test::writeFile(path, doc(R"({"value": 1, "rgba": [1, 1, 1, 2]})"));
    try {
        loadTransferFunction(path, stats());
        ADD_FAILURE() << "accepted a bad file";
    } catch (const render::RenderInputError& e) {
        EXPECT_EQ(e.file(), path);
        EXPECT_EQ(e.field(), "points[0].rgba[3]");
    }
    test::writeFile(path, doc(R"({"value": 7, "rgba": [1, 0, 0, 0.5]})"));
    const auto tf = loadTransferFunction(path, stats());
    EXPECT_EQ(tf.name(), "t");
    ASSERT_EQ(tf.points().size(), 1u);
    EXPECT_EQ(tf.points()[0].value, 7.0);
}

TEST(TransferFunctionFileTest, PresetFilesLoadAsTheEmbeddedPresets) {
    for (const auto& name : render::TransferFunction::presetNames()) {
        const auto embedded = loadTransferFunction(name, stats());
        const auto file =
            loadTransferFunction(std::string(BC_CONFIGS_DIR) + "/tf/" + name + ".json", stats());
        EXPECT_TRUE(embedded.sameFunction(file)) << name;
        EXPECT_EQ(embedded.name(), file.name());
    }
}

TEST(TransferFunctionFileTest, RefusesAFolderAndAnOversizedFile) {
    test::TempDir dir;
    EXPECT_THROW(loadTransferFunction(dir.path().string() + "/", stats()),
                 render::RenderInputError);
    const std::string big = dir.file("big.json");
    std::filesystem::resize_file((test::writeFile(big, ""), big), kMaxTfFileBytes + 1);
    try {
        loadTransferFunction(big, stats());
        ADD_FAILURE() << "accepted a file over the limit";
    } catch (const render::RenderInputError& e) {
        EXPECT_NE(std::string(e.what()).find("larger than"), std::string::npos) << e.what();
    }
}

} // namespace
} // namespace bc::tools
