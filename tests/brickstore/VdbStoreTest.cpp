// gaffer_smoke.vdb through the whole store: only bricks that overlap active voxels are
// stored, and every active voxel reads back as OpenVDB's own accessor gives it.
#include "brickstore/BrickStore.h"
#include "brickstore/Ingest.h"
#include "brickstore/Readers.h"
#include "brickstore/StoreVolume.h"
#include "tests/TestSupport.h"

#include <openvdb/openvdb.h>
#include <set>

namespace bc::brickstore {
namespace {

TEST(VdbStoreTest, StoresOnlyBricksOverlappingActiveVoxelsAndKeepsTheirDensities) {
    const std::string file = test::dataPath("gaffer_smoke.vdb");
    if (!std::filesystem::exists(file)) return test::missingData(file);
    test::TempDir dir;
    const std::string path = dir.file("smoke.bcs");
    IngestConfig config;
    config.geometry = {32, 2, 8};
    {
        auto src = openVdb(file, "density");
        ingest(*src, path, config);
    }
    auto store = BrickStore::open(path);

    openvdb::initialize();
    openvdb::io::File vdb(file);
    vdb.open();
    auto grid = openvdb::gridPtrCast<openvdb::FloatGrid>(vdb.readGrid("density"));
    vdb.close();
    ASSERT_TRUE(grid);
    const openvdb::CoordBBox bbox = grid->evalActiveVoxelBoundingBox();
    const auto& layout = store->layout();
    const auto& l0 = layout.levels()[0];
    const std::int64_t b = config.geometry.brickVoxels, a = config.geometry.apronVoxels;

    // Every brick whose sample region (payload + apron) holds an active voxel.
    std::set<std::uint64_t> overlapping;
    std::uint64_t active = 0;
    for (auto it = grid->cbeginValueOn(); it; ++it) {
        ASSERT_TRUE(it.isVoxelValue()) << "the smoke grid has no active tiles";
        openvdb::Coord c = it.getCoord() - bbox.min();
        ++active;
        // Brick n reads voxels [n*b - a, n*b + b + a) along each axis.
        std::array<std::int64_t, 3> lo{}, hi{};
        for (int ax = 0; ax < 3; ++ax) {
            lo[ax] = l0.bricks[ax];
            hi[ax] = -1;
            for (std::int64_t n = 0; n < l0.bricks[ax]; ++n)
                if (c[ax] >= n * b - a && c[ax] < n * b + b + a)
                    lo[ax] = std::min(lo[ax], n), hi[ax] = n;
        }
        for (std::int64_t z = lo[2]; z <= hi[2]; ++z)
            for (std::int64_t y = lo[1]; y <= hi[1]; ++y)
                for (std::int64_t x = lo[0]; x <= hi[0]; ++x)
                    overlapping.insert(layout.indexOf(
                        {0, {std::uint32_t(x), std::uint32_t(y), std::uint32_t(z)}}));
    }
    EXPECT_EQ(active, 1049275u);
    std::uint64_t stored = 0;
    for (std::uint64_t i = 0; i < l0.brickCount(); ++i) {
        if (!store->record(layout.keyOf(i)).stored()) continue;
        ++stored;
        EXPECT_TRUE(overlapping.count(i))
            << "brick " << layout.keyOf(i).toString() << " stored but holds no active voxel";
    }
    EXPECT_GT(stored, 0u);
    EXPECT_LT(stored, l0.brickCount()) << "some bricks of the smoke's bounding box are empty";
    std::printf("gaffer_smoke: %llu of %llu level-0 bricks stored, %zu overlap active voxels\n",
                (unsigned long long)stored, (unsigned long long)l0.brickCount(),
                overlapping.size());

    // Densities at active voxels, through the store's extract stream.
    auto extracted = openStoreLevel(*store, 0);
    const auto& d = extracted->info().dims;
    std::vector<float> volume(d[0] * d[1] * d[2]);
    extracted->readSlices(d[2], std::as_writable_bytes(std::span(volume)));
    auto acc = grid->getConstAccessor();
    std::uint64_t checked = 0;
    for (auto it = grid->cbeginValueOn(); it; ++it) {
        openvdb::Coord c = it.getCoord() - bbox.min();
        float got = volume[(std::uint64_t(c.z()) * d[1] + c.y()) * d[0] + c.x()];
        ASSERT_EQ(got, acc.getValue(it.getCoord())) << "voxel " << it.getCoord();
        ++checked;
    }
    EXPECT_EQ(checked, active);
}

} // namespace
} // namespace bc::brickstore
