// openVdb on the real Houdini smoke volume (checked voxel by voxel against OpenVDB's own
// accessor) and on small grids written here for each bad input.
#include "brickstore/Error.h"
#include "brickstore/Readers.h"
#include "tests/TestSupport.h"
#include "tests/brickstore/VolumeTestSupport.h"

#include <gtest/gtest.h>
#include <openvdb/io/File.h>
#include <openvdb/openvdb.h>

#include <cmath>
#include <cstring>
#include <limits>

namespace bc::brickstore {
namespace {

using test::readAllSlices;

const char* const kSmoke = "gaffer_smoke.vdb";

class VdbReaderTest : public ::testing::Test {
  protected:
    static void SetUpTestSuite() { openvdb::initialize(); }

    /// Writes `grids` to a .vdb in the scratch folder and returns its path.
    std::string writeVdb(const std::string& name, const openvdb::GridPtrVec& grids) {
        const std::string path = mDir.file(name);
        openvdb::io::File(path).write(grids);
        return path;
    }

    test::TempDir mDir;
};

float floatAt(const std::vector<std::byte>& bytes, std::uint64_t index) {
    float v;
    std::memcpy(&v, bytes.data() + index * sizeof(float), sizeof(float));
    return v;
}

/// Runs `open` and returns the FormatError it throws (fails the test when it throws none).
template <typename Fn> FormatError formatErrorOf(Fn&& open) {
    try {
        open();
    } catch (const FormatError& e) {
        return e;
    }
    ADD_FAILURE() << "no FormatError";
    return FormatError("", "", "");
}

TEST_F(VdbReaderTest, SmokeDensityStreamsEveryVoxelAsOpenVdbSeesIt) {
    if (!test::haveData(kSmoke)) return test::missingData(kSmoke);
    const std::string path = test::dataPath(kSmoke);
    auto source = openVdb(path, "density");
    const VolumeInfo& info = source->info();
    EXPECT_EQ(info.dims, (std::array<std::uint64_t, 3>{111, 222, 112}));
    EXPECT_EQ(info.type, VoxelType::F32);
    for (double s : info.spacingMm)
        EXPECT_NEAR(s, 0.476, 5e-4);
    EXPECT_NE(info.description.find("density"), std::string::npos) << info.description;

    openvdb::io::File file(path);
    file.open();
    auto grid = openvdb::gridPtrCast<openvdb::FloatGrid>(file.readGrid("density"));
    ASSERT_TRUE(grid);
    const openvdb::CoordBBox box = grid->evalActiveVoxelBoundingBox();
    const openvdb::Vec3d origin = grid->indexToWorld(box.min());
    for (int a = 0; a < 3; ++a)
        EXPECT_NEAR(info.originMm[a], origin[a], 1e-9);
    EXPECT_EQ(info.background, double(grid->background()));

    const auto bytes = readAllSlices(*source, 5); // 5 does not divide 112: the last slab is short
    auto accessor = grid->getConstAccessor();
    std::uint64_t active = 0, index = 0;
    for (int z = box.min().z(); z <= box.max().z(); ++z)
        for (int y = box.min().y(); y <= box.max().y(); ++y)
            for (int x = box.min().x(); x <= box.max().x(); ++x, ++index) {
                float value;
                const bool on = accessor.probeValue(openvdb::Coord(x, y, z), value);
                active += on;
                const float expected = on ? value : grid->background();
                ASSERT_EQ(floatAt(bytes, index), expected) << "voxel " << x << "," << y << "," << z;
            }
    EXPECT_EQ(active, 1049275u);
    EXPECT_EQ(active, grid->activeVoxelCount());
}

TEST_F(VdbReaderTest, EmptyGridNamePicksTheFirstScalarGrid) {
    auto vectors = openvdb::Vec3SGrid::create();
    vectors->setName("velocity");
    vectors->tree().setValue(openvdb::Coord(0, 0, 0), openvdb::Vec3s(1, 2, 3));
    auto first = openvdb::FloatGrid::create(0.0f);
    first->setName("first");
    first->tree().setValue(openvdb::Coord(1, 2, 3), 5.0f);
    auto second = openvdb::FloatGrid::create(0.0f);
    second->setName("second");
    second->tree().setValue(openvdb::Coord(0, 0, 0), 7.0f);
    second->tree().setValue(openvdb::Coord(1, 1, 0), 8.0f);
    const std::string path = writeVdb("three.vdb", {vectors, first, second});

    auto picked = openVdb(path, "");
    EXPECT_EQ(picked->info().dims, (std::array<std::uint64_t, 3>{1, 1, 1}));
    EXPECT_EQ(floatAt(readAllSlices(*picked, 1), 0), 5.0f);
    auto named = openVdb(path, "second");
    EXPECT_EQ(named->info().dims, (std::array<std::uint64_t, 3>{2, 2, 1}));
    const auto bytes = readAllSlices(*named, 1);
    EXPECT_EQ(floatAt(bytes, 0), 7.0f);
    EXPECT_EQ(floatAt(bytes, 1), 0.0f);
    EXPECT_EQ(floatAt(bytes, 3), 8.0f);
}

TEST_F(VdbReaderTest, DoubleGridWithInactiveValuesTilesAndScaledTransform) {
    auto grid = openvdb::DoubleGrid::create(-1.5);
    grid->setName("phi");
    grid->setTransform(openvdb::math::Transform::createLinearTransform(0.25));
    grid->transform().postTranslate(openvdb::Vec3d(10, 20, 30));
    grid->tree().fill(openvdb::CoordBBox(openvdb::Coord(-16, 0, 0), openvdb::Coord(-1, 15, 15)),
                      2.25, true);
    grid->tree().setValue(openvdb::Coord(5, 3, 20), 4.5);     // in a leaf, raising bbox max z to 20
    grid->tree().setValueOff(openvdb::Coord(6, 3, 20), 99.0); // inactive: must read as background
    ASSERT_GT(grid->tree().activeTileCount(), 0u);
    const std::string path = writeVdb("phi.vdb", {grid});

    auto source = openVdb(path, "phi");
    const VolumeInfo& info = source->info();
    EXPECT_EQ(info.dims, (std::array<std::uint64_t, 3>{22, 16, 21}));
    EXPECT_EQ(info.background, -1.5);
    for (int a = 0; a < 3; ++a)
        EXPECT_DOUBLE_EQ(info.spacingMm[a], 0.25);
    EXPECT_DOUBLE_EQ(info.originMm[0], 10 - 16 * 0.25);
    EXPECT_DOUBLE_EQ(info.originMm[1], 20.0);
    EXPECT_DOUBLE_EQ(info.originMm[2], 30.0);
    const auto bytes = readAllSlices(*source, 4);
    auto at = [&](int x, int y, int z) {
        return floatAt(bytes,
                       (std::uint64_t(z) * 16 + std::uint64_t(y)) * 22 + std::uint64_t(x + 16));
    };
    EXPECT_EQ(at(-16, 0, 0), 2.25f);
    EXPECT_EQ(at(-1, 15, 15), 2.25f);
    EXPECT_EQ(at(0, 0, 0), -1.5f);
    EXPECT_EQ(at(-1, 0, 16), -1.5f);
    EXPECT_EQ(at(5, 3, 20), 4.5f);
    EXPECT_EQ(at(6, 3, 20), -1.5f);
    EXPECT_EQ(readAllSlices(*openVdb(path, "phi"), 1), bytes);
}

TEST_F(VdbReaderTest, FileWithoutScalarGridNamesTheGridsItHolds) {
    auto vectors = openvdb::Vec3SGrid::create();
    vectors->setName("velocity");
    vectors->tree().setValue(openvdb::Coord(0, 0, 0), openvdb::Vec3s(1, 0, 0));
    const std::string path = writeVdb("vectors.vdb", {vectors});
    const FormatError e = formatErrorOf([&] { openVdb(path, ""); });
    EXPECT_EQ(e.file(), path);
    EXPECT_EQ(e.field(), "grid");
    EXPECT_NE(std::string(e.what()).find("velocity"), std::string::npos) << e.what();
    const FormatError named = formatErrorOf([&] { openVdb(path, "velocity"); });
    EXPECT_EQ(named.field(), "grid");
    EXPECT_NE(std::string(named.what()).find("vec3s"), std::string::npos) << named.what();
}

TEST_F(VdbReaderTest, MissingGridNameListsTheGrids) {
    if (!test::haveData(kSmoke)) return test::missingData(kSmoke);
    const FormatError e = formatErrorOf([&] { openVdb(test::dataPath(kSmoke), "temperature"); });
    EXPECT_EQ(e.field(), "grid");
    EXPECT_NE(std::string(e.what()).find("temperature"), std::string::npos) << e.what();
    EXPECT_NE(std::string(e.what()).find("density"), std::string::npos) << e.what();
}

TEST_F(VdbReaderTest, FileThatIsNotAVdbThrowsFormatError) {
    const std::string path = mDir.file("fake.vdb");
    test::writeFile(path, std::string(4096, 'x'));
    EXPECT_EQ(formatErrorOf([&] { openVdb(path, ""); }).file(), path);
    EXPECT_THROW(openVdb(mDir.file("absent.vdb"), ""), FormatError);
}

TEST_F(VdbReaderTest, EmptyGridThrowsFormatError) {
    auto grid = openvdb::FloatGrid::create(0.0f);
    grid->setName("nothing");
    const std::string path = writeVdb("empty.vdb", {grid});
    EXPECT_EQ(formatErrorOf([&] { openVdb(path, ""); }).field(), "grid");
}

TEST_F(VdbReaderTest, FrustumTransformThrowsFormatError) {
    auto grid = openvdb::FloatGrid::create(0.0f);
    grid->setName("frustum");
    grid->setTransform(openvdb::math::Transform::createFrustumTransform(
        openvdb::BBoxd(openvdb::Vec3d(0, 0, 0), openvdb::Vec3d(10, 10, 10)), 0.5, 5.0, 1.0));
    grid->tree().setValue(openvdb::Coord(1, 1, 1), 1.0f);
    const std::string path = writeVdb("frustum.vdb", {grid});
    EXPECT_EQ(formatErrorOf([&] { openVdb(path, ""); }).field(), "transform");
}

TEST_F(VdbReaderTest, NanAtAnActiveVoxelThrowsNamingTheVoxel) {
    auto grid = openvdb::FloatGrid::create(0.0f);
    grid->setName("bad");
    grid->tree().setValue(openvdb::Coord(0, 0, 0), 1.0f);
    grid->tree().setValue(openvdb::Coord(3, 4, 9), std::numeric_limits<float>::quiet_NaN());
    const std::string path = writeVdb("nan.vdb", {grid});
    auto source = openVdb(path, "bad");
    std::vector<std::byte> bytes(source->info().voxelCount() * 4);
    const FormatError e = formatErrorOf([&] { source->readSlices(source->info().dims[2], bytes); });
    EXPECT_EQ(e.field(), "value");
    EXPECT_NE(std::string(e.what()).find("(3,4,9)"), std::string::npos) << e.what();
}

} // namespace
} // namespace bc::brickstore
