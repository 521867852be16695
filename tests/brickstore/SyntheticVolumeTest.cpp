#include "brickstore/Error.h"
#include "brickstore/Readers.h"

#include "tests/TestSupport.h"
#include "tests/brickstore/VolumeTestSupport.h"

#include <cstring>
#include <numeric>

namespace bc::brickstore {
namespace {

constexpr std::uint64_t kCheckerPeriod = 8; // kCheckerPeriodVoxels of the generator

using Dims = std::array<std::uint64_t, 3>;
using test::readAllSlices;

std::vector<std::byte> generate(SynthKind kind, const Dims& dims, std::uint64_t seed,
                                std::uint64_t chunk = 1) {
    return readAllSlices(*makeSynthetic(kind, dims, seed), chunk);
}

std::uint16_t u16At(const std::vector<std::byte>& bytes, const Dims& d, std::uint64_t x,
                    std::uint64_t y, std::uint64_t z) {
    std::uint16_t v;
    std::memcpy(&v, bytes.data() + ((z * d[1] + y) * d[0] + x) * 2, 2);
    return v;
}

double nonZeroFraction(const std::vector<std::byte>& bytes) {
    const auto nonZero =
        std::count_if(bytes.begin(), bytes.end(), [](std::byte b) { return b != std::byte{0}; });
    return double(nonZero) / double(bytes.size());
}

TEST(SyntheticVolumeTest, ReportsRequestedDimsAndTypes) {
    const Dims dims{40, 30, 20};
    EXPECT_EQ(makeSynthetic(SynthKind::Phantom, dims, 1)->info().type, VoxelType::U16);
    EXPECT_EQ(makeSynthetic(SynthKind::Vessels, dims, 1)->info().type, VoxelType::U8);
    EXPECT_EQ(makeSynthetic(SynthKind::Checker, dims, 1)->info().type, VoxelType::U8);
    auto phantom = makeSynthetic(SynthKind::Phantom, dims, 1);
    EXPECT_EQ(phantom->info().dims, dims);
    EXPECT_EQ(phantom->info().spacingMm, (std::array<double, 3>{1, 1, 1}));
    EXPECT_EQ(phantom->info().description, "synthetic phantom 40x30x20, u16, seed 1");
}

TEST(SyntheticVolumeTest, ZeroDimensionThrowsFormatErrorNamingTheGenerator) {
    for (auto [kind, name] : {std::pair{SynthKind::Phantom, "synth:phantom"},
                              {SynthKind::Vessels, "synth:vessels"},
                              {SynthKind::Checker, "synth:checker"}}) {
        try {
            makeSynthetic(kind, {64, 0, 64}, 1);
            FAIL() << "no error for " << name;
        } catch (const FormatError& e) {
            EXPECT_EQ(e.file(), name);
            EXPECT_EQ(e.field(), "dims");
        }
    }
    EXPECT_THROW(makeSynthetic(SynthKind::Checker, {1ull << 21, 4, 4}, 1), FormatError);
}

TEST(SyntheticVolumeTest, SameSeedGivesIdenticalBytesAndOtherSeedsDiffer) {
    const Dims dims{48, 40, 36};
    for (SynthKind kind : {SynthKind::Phantom, SynthKind::Vessels}) {
        const auto a = generate(kind, dims, 7), b = generate(kind, dims, 7),
                   c = generate(kind, dims, 8);
        EXPECT_EQ(a, b);
        EXPECT_NE(a, c);
    }
    EXPECT_EQ(generate(SynthKind::Checker, dims, 7), generate(SynthKind::Checker, dims, 7));
}

TEST(SyntheticVolumeTest, ChunkSizeDoesNotChangeTheBytes) {
    const Dims dims{37, 29, 41};
    for (SynthKind kind : {SynthKind::Phantom, SynthKind::Vessels, SynthKind::Checker}) {
        const auto one = generate(kind, dims, 3, 1);
        EXPECT_EQ(one, generate(kind, dims, 3, 5));
        EXPECT_EQ(one, generate(kind, dims, 3, 41));
    }
}

TEST(SyntheticVolumeTest, ReadingPastTheLastSliceThrows) {
    auto source = makeSynthetic(SynthKind::Checker, {8, 8, 4}, 1);
    std::vector<std::byte> slab(5 * 64);
    EXPECT_THROW(source->readSlices(5, slab), std::out_of_range);
    EXPECT_THROW(source->readSlices(2, slab), std::invalid_argument);
}

TEST(SyntheticVolumeTest, NextSliceAdvancesOnlyOnAcceptedReads) {
    auto source = makeSynthetic(SynthKind::Checker, {8, 8, 4}, 1);
    std::vector<std::byte> slab(5 * 64);
    EXPECT_THROW(source->readSlices(2, slab), std::invalid_argument);
    EXPECT_EQ(source->nextSlice(), 0u);
    source->readSlices(3, std::span(slab).first(3 * 64));
    EXPECT_EQ(source->nextSlice(), 3u);
    EXPECT_THROW(source->readSlices(2, std::span(slab).first(2 * 64)), std::out_of_range);
    EXPECT_EQ(source->nextSlice(), 3u);
    source->readSlices(1, std::span(slab).first(64));
    EXPECT_EQ(source->nextSlice(), 4u);
}

TEST(SyntheticVolumeTest, VesselOccupancyIsBetweenOneAndFivePercent) {
    for (const Dims& dims : {Dims{128, 128, 128}, Dims{96, 64, 80}, Dims{64, 64, 64}}) {
        for (std::uint64_t seed : {1, 2, 3}) {
            const double fraction = nonZeroFraction(generate(SynthKind::Vessels, dims, seed, 16));
            std::printf("vessels %llux%llux%llu seed %llu: %.2f%% non-zero\n",
                        (unsigned long long)dims[0], (unsigned long long)dims[1],
                        (unsigned long long)dims[2], (unsigned long long)seed, fraction * 100.0);
            EXPECT_GE(fraction, 0.01);
            EXPECT_LE(fraction, 0.05);
        }
    }
}

TEST(SyntheticVolumeTest, VesselLumenIsBrightAndBackgroundZero) {
    const Dims dims{96, 96, 96};
    const auto bytes = generate(SynthKind::Vessels, dims, 1, 96);
    const auto brightest = *std::max_element(bytes.begin(), bytes.end());
    EXPECT_GE(std::to_integer<int>(brightest), 200);
    EXPECT_EQ(bytes.front(), std::byte{0}); // a corner
}

TEST(SyntheticVolumeTest, CheckerCellsAreEightVoxelsOfZeroAnd255) {
    const Dims dims{20, 18, 17};
    const auto bytes = generate(SynthKind::Checker, dims, 1, 4);
    auto at = [&](std::uint64_t x, std::uint64_t y, std::uint64_t z) {
        return std::to_integer<int>(bytes[(z * dims[1] + y) * dims[0] + x]);
    };
    EXPECT_EQ(at(0, 0, 0), 0);
    EXPECT_EQ(at(7, 7, 7), 0);
    EXPECT_EQ(at(8, 0, 0), 255);
    EXPECT_EQ(at(0, 8, 0), 255);
    EXPECT_EQ(at(0, 0, 8), 255);
    EXPECT_EQ(at(8, 8, 0), 0);
    EXPECT_EQ(at(8, 8, 8), 255);
    EXPECT_EQ(at(19, 17, 16), 0); // cells (2,2,2)
    for (std::uint64_t z = 0; z < dims[2]; ++z)
        for (std::uint64_t y = 0; y < dims[1]; ++y)
            for (std::uint64_t x = 0; x < dims[0]; ++x)
                ASSERT_EQ(at(x, y, z),
                          ((x / kCheckerPeriod + y / kCheckerPeriod + z / kCheckerPeriod) % 2) *
                              255);
}

TEST(SyntheticVolumeTest, PhantomHasAirAtCornersSkullAndSoftTissue) {
    const Dims dims{96, 112, 104};
    const auto bytes = generate(SynthKind::Phantom, dims, 1, 13);
    for (std::uint64_t z : {std::uint64_t{0}, dims[2] - 1})
        for (std::uint64_t y : {std::uint64_t{0}, dims[1] - 1})
            for (std::uint64_t x : {std::uint64_t{0}, dims[0] - 1})
                EXPECT_EQ(u16At(bytes, dims, x, y, z), 0);
    std::uint16_t highest = 0;
    std::uint64_t bone = 0, soft = 0, voxels = bytes.size() / 2;
    for (std::uint64_t i = 0; i < voxels; ++i) {
        std::uint16_t v;
        std::memcpy(&v, bytes.data() + 2 * i, 2);
        highest = std::max(highest, v);
        bone += v >= 1700;
        soft += v >= 990 && v <= 1110;
    }
    EXPECT_LE(highest, 4095);
    EXPECT_GE(highest, 2300);
    EXPECT_GT(double(bone) / double(voxels), 0.01); // the skull shell
    EXPECT_GT(double(soft) / double(voxels), 0.15); // brain and scalp
    // The centre of the head is brain tissue (ventricles at most), not bone or air.
    const std::uint16_t centre = u16At(bytes, dims, dims[0] / 2, dims[1] / 2, dims[2] / 2);
    EXPECT_GE(centre, 990);
    EXPECT_LE(centre, 1110);
}

} // namespace
} // namespace bc::brickstore
