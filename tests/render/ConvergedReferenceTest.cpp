// The converged reference: the reference at smaller and smaller steps until halving
// the step changes the image by under a tolerance; a tolerance it cannot reach stops at the
// floor step or the time limit and says so; bad tolerances are refused before any frame.
#include "render/ConvergedReference.h"
#include "RenderTestSupport.h"

#include <cmath>
#include <limits>

namespace bc::render {
namespace {

using test::TestStore;

/// headsq (64x64x93) at 64x64, view 30,20, ct-skin.
struct HeadsqScene {
    explicit HeadsqScene(std::unique_ptr<TestStore> store)
        : t(std::move(store)), tf(TransferFunction::preset("ct-skin", t->stats)),
          view(View::of(Camera::orbit(LevelGeometry::of(*t->store, 0).box, 30, 20), 64, 64)) {
        options.width = options.height = 64;
    }
    Scene scene() { return Scene{*t->store, *t->cache, tf, classifications}; }

    std::unique_ptr<TestStore> t;
    TransferFunction tf;
    ClassificationCache classifications;
    View view;
    RenderOptions options;
};

std::unique_ptr<HeadsqScene> headsq() {
    auto t = test::ingestRealScan("headsq");
    return t ? std::make_unique<HeadsqScene>(std::move(t)) : nullptr;
}

TEST(ConvergedReference, HeadsqAt64FindsAStepAndTheDifferencesShrink) {
    auto s = headsq();
    if (!s) return test::missingData("scan headsq");
    ReferenceRenderer reference;
    ConvergenceConfig config; // 0.5/255 from step 1, floor 1/64
    const ConvergedReference r =
        renderConverged(reference, s->scene(), s->view, s->options, config);
    for (const auto& step : r.steps)
        std::printf("step %g: %.3f/255, %.1f ms\n", step.stepVoxels, step.maxAbsToPrevious * 255,
                    step.renderMs);
    ASSERT_TRUE(r.converged);
    EXPECT_EQ(r.stop, ConvergenceStop::Converged);
    ASSERT_GE(r.steps.size(), 3u);
    EXPECT_TRUE(std::isnan(r.steps[0].maxAbsToPrevious));
    for (std::size_t i = 2; i < r.steps.size(); ++i)
        EXPECT_LT(r.steps[i].maxAbsToPrevious, r.steps[i - 1].maxAbsToPrevious) << "frame " << i;
    EXPECT_LT(r.steps.back().maxAbsToPrevious, config.toleranceRgba);
    EXPECT_GE(r.steps[r.steps.size() - 2].maxAbsToPrevious, config.toleranceRgba);
    EXPECT_EQ(r.imageStepVoxels, r.steps.back().stepVoxels);
    EXPECT_EQ(r.stepVoxels, 2.0 * r.imageStepVoxels);
    // The image is the reference's frame at its step, to the bit.
    RenderOptions o = s->options;
    o.stepVoxels = r.imageStepVoxels;
    const Image direct = test::referenceFrame(*s->t, s->tf, s->view.camera, o);
    EXPECT_EQ(compareImages(direct, r.image).maxAbs, 0.0);
}

TEST(ConvergedReference, AnImpossibleToleranceStopsAtTheFloorNotConverged) {
    auto s = headsq();
    if (!s) return test::missingData("scan headsq");
    ReferenceRenderer reference;
    ConvergenceConfig config;
    config.toleranceRgba = 1e-12;
    config.floorStepVoxels = 0.125;
    const ConvergedReference r =
        renderConverged(reference, s->scene(), s->view, s->options, config);
    EXPECT_FALSE(r.converged);
    EXPECT_EQ(r.stop, ConvergenceStop::FloorStep);
    ASSERT_EQ(r.steps.size(), 4u); // 1, 1/2, 1/4, 1/8
    EXPECT_EQ(r.imageStepVoxels, 0.125);
    EXPECT_EQ(r.stepVoxels, 0.125);
}

TEST(ConvergedReference, TheTimeLimitStopsTheSearchNotConverged) {
    auto s = headsq();
    if (!s) return test::missingData("scan headsq");
    ReferenceRenderer reference;
    ConvergenceConfig config;
    config.toleranceRgba = 1e-12;
    config.timeLimitMs = 1e-3; // before the second frame
    const ConvergedReference r =
        renderConverged(reference, s->scene(), s->view, s->options, config);
    EXPECT_FALSE(r.converged);
    EXPECT_EQ(r.stop, ConvergenceStop::TimeLimit);
    EXPECT_EQ(r.steps.size(), 1u);
}

TEST(ConvergedReference, RefusesBadTolerancesStepsAndLimits) {
    const double nan = std::numeric_limits<double>::quiet_NaN();
    const double inf = std::numeric_limits<double>::infinity();
    auto refused = [](ConvergenceConfig c, const std::string& field) {
        try {
            c.validate();
            ADD_FAILURE() << field << " accepted";
        } catch (const std::invalid_argument& e) {
            EXPECT_NE(std::string(e.what()).find(field), std::string::npos) << e.what();
        }
    };
    for (double tol : {0.0, -1.0, nan, inf}) {
        ConvergenceConfig c;
        c.toleranceRgba = tol;
        refused(c, "toleranceRgba");
    }
    for (double step : {0.0, -0.5, nan}) {
        ConvergenceConfig c;
        c.startStepVoxels = step;
        refused(c, "startStepVoxels");
        c = {};
        c.floorStepVoxels = step;
        refused(c, "floorStepVoxels");
    }
    ConvergenceConfig above;
    above.floorStepVoxels = 2.0;
    refused(above, "floorStepVoxels");
    for (double ms : {-1.0, nan, inf}) {
        ConvergenceConfig c;
        c.timeLimitMs = ms;
        refused(c, "timeLimitMs");
    }
    // renderConverged checks before it draws anything.
    auto s = headsq();
    if (!s) return test::missingData("scan headsq");
    ReferenceRenderer reference;
    ConvergenceConfig zero;
    zero.toleranceRgba = 0.0;
    EXPECT_THROW(renderConverged(reference, s->scene(), s->view, s->options, zero),
                 std::invalid_argument);
    ConvergenceConfig tooFine; // 1/1024 is below the smallest step RenderOptions accepts
    tooFine.floorStepVoxels = 1e-3;
    try {
        renderConverged(reference, s->scene(), s->view, s->options, tooFine);
        ADD_FAILURE() << "a floor under the smallest step accepted";
    } catch (const std::invalid_argument& e) {
        EXPECT_NE(std::string(e.what()).find("floorStepVoxels"), std::string::npos) << e.what();
    }
}

} // namespace
} // namespace bc::render
