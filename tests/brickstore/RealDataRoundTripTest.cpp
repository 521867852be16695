// Done-when round trips: every real dataset and every generator, ingested and extracted at
// two brick sizes, gives back the source voxels exactly. Compared slab by slab against a
// fresh read of the source, so no test holds a whole volume twice.
#include "brickstore/BrickStore.h"
#include "brickstore/Ingest.h"
#include "brickstore/Readers.h"
#include "brickstore/StoreVolume.h"
#include "tests/TestSupport.h"

#include <cstring>

namespace bc::brickstore {
namespace {

struct RoundTripInput {
    std::string name;
    SourceSpec spec;
    std::array<std::uint64_t, 3> dims;
    VoxelType type;
};

SourceSpec fileSpec(const std::string& file) {
    SourceSpec s;
    s.input = test::dataPath(file);
    return s;
}

SourceSpec synthSpec(const std::string& kind, std::array<std::uint64_t, 3> dims) {
    SourceSpec s;
    s.input = "synth:" + kind;
    s.dims = dims;
    s.seed = 42;
    return s;
}

std::vector<RoundTripInput> inputs() {
    SourceSpec mosaic = fileSpec("vtk_headsq_quarter_64x64x93_uint16.raw");
    mosaic.mosaic = {2, 1, 2};
    return {
        {"cthead_raw",
         fileSpec("stanford_cthead_256x256x113_uint16.raw"),
         {256, 256, 113},
         VoxelType::U16},
        {"ct_avm_raw", fileSpec("CT_AVM_256x242x154_uint8.raw"), {256, 242, 154}, VoxelType::U8},
        {"ct_avm_nifti", fileSpec("CT_AVM.nii.gz"), {256, 242, 154}, VoxelType::U8},
        {"frog_raw", fileSpec("frog_500x470x136_uint8.raw"), {500, 470, 136}, VoxelType::U8},
        {"iguana_nifti", fileSpec("Iguana.nii.gz"), {210, 256, 179}, VoxelType::U8},
        {"pancreas_dicom", fileSpec("tcia_pancreas_ct_dicom"), {512, 512, 134}, VoxelType::I16},
        {"gaffer_vdb", fileSpec("gaffer_smoke.vdb"), {111, 222, 112}, VoxelType::F32},
        {"hydrogen_raw", fileSpec("hydrogen_64x64x64_float32.raw"), {64, 64, 64}, VoxelType::F32},
        {"headsq_raw",
         fileSpec("vtk_headsq_quarter_64x64x93_uint16.raw"),
         {64, 64, 93},
         VoxelType::U16},
        {"headsq_mosaic", mosaic, {128, 64, 186}, VoxelType::U16},
        {"phantom", synthSpec("phantom", {96, 80, 72}), {96, 80, 72}, VoxelType::U16},
        {"vessels", synthSpec("vessels", {128, 128, 128}), {128, 128, 128}, VoxelType::U8},
        {"checker", synthSpec("checker", {70, 50, 40}), {70, 50, 40}, VoxelType::U8},
    };
}

class RealDataRoundTrip
    : public ::testing::TestWithParam<std::tuple<RoundTripInput, BrickGeometry>> {};

TEST_P(RealDataRoundTrip, ExtractAfterIngestGivesBackTheSourceVoxels) {
    const auto& [in, geometry] = GetParam();
    if (in.spec.input.rfind("synth:", 0) != 0 && !std::filesystem::exists(in.spec.input))
        return test::missingData(in.spec.input);
    test::TempDir dir;
    const std::string path = dir.file("rt.bcs");
    {
        auto src = openSource(in.spec);
        IngestConfig config;
        config.geometry = geometry;
        ingest(*src, path, config);
    }
    auto store = BrickStore::open(path);
    EXPECT_EQ(store->info().volume.dims, in.dims);
    EXPECT_EQ(store->info().volume.type, in.type);
    auto original = openSource(in.spec);
    auto extracted = openStoreLevel(*store, 0);
    ASSERT_EQ(original->info().sliceBytes(), extracted->info().sliceBytes());
    EXPECT_EQ(original->info().spacingMm, extracted->info().spacingMm);
    EXPECT_EQ(original->info().valueScale, extracted->info().valueScale);
    EXPECT_EQ(original->info().valueOffset, extracted->info().valueOffset);
    EXPECT_EQ(original->info().description, extracted->info().description);
    const std::uint64_t sb = original->info().sliceBytes(), slab = 7;
    std::vector<std::byte> a(slab * sb), b(slab * sb);
    for (std::uint64_t z = 0; z < in.dims[2]; z += slab) {
        std::uint64_t n = std::min(slab, in.dims[2] - z);
        original->readSlices(n, std::span(a).first(n * sb));
        extracted->readSlices(n, std::span(b).first(n * sb));
        ASSERT_EQ(std::memcmp(a.data(), b.data(), n * sb), 0)
            << "slices " << z << ".." << z + n - 1;
    }
}

INSTANTIATE_TEST_SUITE_P(EveryInputTwoBrickSizes, RealDataRoundTrip,
                         ::testing::Combine(::testing::ValuesIn(inputs()),
                                            ::testing::Values(BrickGeometry{32, 2, 8},
                                                              BrickGeometry{64, 1, 8})),
                         [](const auto& info) {
                             return std::get<0>(info.param).name + "_brick" +
                                    std::to_string(std::get<1>(info.param).brickVoxels);
                         });

} // namespace
} // namespace bc::brickstore
