#pragma once
// The real scans the benchmarks run on (../shared/data, see MANIFEST.md), each with the
// transfer-function preset meant for its modality, and the camera paths they fly. Shared by
// bc_bench_render, bc_bench_tunables and bc_bench_splat.
#include "brickstore/Readers.h"
#include "render/Camera.h"

#include <string>
#include <vector>

namespace bc::bench {

struct Dataset {
    std::string name, preset;
    brickstore::SourceSpec spec;
    std::uint64_t budgetMb = 0; ///< 0: the bench's GPU budget; else a generated volume's own
    std::string tfJson;         ///< a transfer function of its own (generated volumes) or empty
};

/// The scans under `dataDir` named in the comma-separated `wanted` (all when empty), each
/// once per preset; `tfOverride` (when not empty) replaces every preset. Scans whose files
/// are missing are reported on stderr with `who` and left out.
std::vector<Dataset> realDatasets(const std::string& dataDir, const std::string& wanted,
                                  const std::string& tfOverride, const char* who);

/// frames + 1 cameras of `path` about `box` (the first warms pools and octrees, not timed):
/// "orbit" 2 degrees a frame at elevation 20 from 30 degrees, or "jumps", views at random
/// (seeded) azimuth, elevation -70..70 and 0.7..1.4 times the framing distance.
std::vector<render::Camera> cameraPath(const std::string& path, const render::Box& box, int frames);

} // namespace bc::bench
