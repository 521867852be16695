// The GPU raycaster's interactive mode: a coarser level when level 0 does not fit the budget,
// and the level drawn reported in the frame's stats.
#include "RenderTestSupport.h"
#include "render/Image.h"

namespace bc::render {
namespace {

// Interactive mode draws a coarser level when level 0 does not fit the budget, and says so.
TEST(RaycasterInteractive, DrawsACoarserLevelWhenTheViewExceedsTheBudgetAndReportsIt) {
    auto source = brickstore::makeSynthetic(brickstore::SynthKind::Phantom, {128, 128, 96}, 2);
    test::glContext();
    auto t = test::ingestStore(*source, {16, 2, 8});
    const auto tf = TransferFunction::preset("ct-bone", t->stats);
    const Camera camera = Camera::orbit(LevelGeometry::of(*t->store, 0).box, 30, 20);
    GpuRaycaster raycaster({1ull << 20}); // 1 MiB: 64 slots of 20^3 u8... fewer than level 0 needs
    RenderOptions o;
    o.width = o.height = 96;
    FrameStats full, fast;
    test::gpuFrame(*t, raycaster, tf, camera, o, &full);
    o.interactive = true;
    const Image coarse = test::gpuFrame(*t, raycaster, tf, camera, o, &fast);
    EXPECT_EQ(full.level, 0u);
    EXPECT_GT(full.batches, 1u);
    EXPECT_GT(fast.level, 0u);
    EXPECT_EQ(fast.batches, 1u);
    EXPECT_TRUE(test::allFinite(coarse));
}

} // namespace
} // namespace bc::render
