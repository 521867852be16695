// The README's main job (scripts/main_job.sh) flies an orbit around the daemon's generated
// phantom (128^3, seed 1) under ct-skin, then ct-bone, with the protocol's default options:
// step 1 and every technique bit, jittered ray starts included (protocol/PROTOCOL.md). A fixed
// sample lattice draws wood-grain rings on it; these tests hold its frames to a bound on the
// structured error against the converged image (the low-pass PSNR of render/ImageMetrics.h,
// which keeps rings and lets pixel noise average out), and show that on the views where a
// fixed lattice draws rings it misses that bound by far, so the bound measures the rings.
// Measured at 160^2 over seven azimuths (0, 45, ..., 300): jittered, ct-skin 58.7-61.8 dB and
// ct-bone 37.7-40.8 dB; the fixed lattice 52.6-59.3 and 27.5-38.2 dB.
#include "RenderTestSupport.h"

namespace bc::render {
namespace {

struct Case {
    const char* tf;
    double azimuth;
    double lowPassBoundDb; ///< the default frame's low-pass PSNR must reach this
    bool rings;            ///< a view where the fixed lattice draws rings (it misses the bound)
};

class WoodGrain : public ::testing::TestWithParam<Case> {};

TEST_P(WoodGrain, TheMainJobsFramesShowNoRings) {
    const Case& k = GetParam();
    auto phantom = brickstore::makeSynthetic(brickstore::SynthKind::Phantom, {128, 128, 128}, 1);
    auto t = test::ingestStore(*phantom, {64, 2, 8});
    const auto tf = TransferFunction::preset(k.tf, t->stats);
    const Camera c = Camera::orbit(LevelGeometry::of(*t->store, 0).box, k.azimuth, 20);
    RenderOptions o; // what the daemon draws for the protocol's defaults
    o.width = o.height = 160;
    o.jitter = true;
    // The true image: the same model at 1/32 of the step, every sample (no early termination).
    RenderOptions fine = o, finer = o;
    fine.jitter = finer.jitter = false;
    fine.earlyTermination = finer.earlyTermination = false;
    fine.stepVoxels = 1.0 / 16.0;
    finer.stepVoxels = 1.0 / 32.0;
    const Image truth = test::cpuFrame(*t, tf, c, finer);
    const auto settled = compareImages(test::cpuFrame(*t, tf, c, fine), truth);
    test::printComparison(std::string(k.tf) + " step 1/16 vs 1/32 (how settled the truth is)",
                          settled);
    EXPECT_GT(settled.lowPassPsnrDb, k.lowPassBoundDb + 6.0) << "the truth is not settled enough";

    const auto jittered = compareImages(test::cpuFrame(*t, tf, c, o), truth);
    RenderOptions lattice = o;
    lattice.jitter = false;
    const auto fixed = compareImages(test::cpuFrame(*t, tf, c, lattice), truth);
    test::printComparison(std::string(k.tf) + " default (jittered) vs the true image", jittered);
    test::printComparison(std::string(k.tf) + " fixed lattice vs the true image", fixed);
    EXPECT_GE(jittered.lowPassPsnrDb, k.lowPassBoundDb);
    if (k.rings) {
        EXPECT_LT(fixed.lowPassPsnrDb, k.lowPassBoundDb - 3.0) << "the lattice's rings";
    }
    // Jitter moves error from rings into noise; it does not add any.
    EXPECT_LT(jittered.rmse, fixed.rmse * 1.1);
}

INSTANTIATE_TEST_SUITE_P(MainJobPhantom, WoodGrain,
                         ::testing::Values(Case{"ct-skin", 0.0, 57.0, true},
                                           Case{"ct-skin", 130.0, 57.0, false},
                                           Case{"ct-bone", 0.0, 36.0, true},
                                           Case{"ct-bone", 90.0, 36.0, true},
                                           Case{"ct-bone", 250.0, 36.0, false}),
                         [](const ::testing::TestParamInfo<Case>& i) {
                             std::string name = i.param.tf;
                             for (char& ch : name)
                                 if (ch == '-') ch = '_';
                             return name + "_az" + std::to_string(int(i.param.azimuth));
                         });

} // namespace
} // namespace bc::render
