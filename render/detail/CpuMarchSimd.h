#pragma once
// The CPU raycaster's march through one brick, vectorised across consecutive samples of a ray
// with Highway (render/detail/CpuMarchSimd.cpp), for the widest instruction set the host has.
#include "brickstore/BrickStore.h"
#include "render/detail/CpuRay.h"

#include <cstdint>
#include <string>

namespace bc::render::detail {

/// marchBrick() of CpuRay.h for voxels of `type`, same samples and same arguments: walks the
/// octree per ray, gathers runs of samples in non-empty leaves and takes them a vector at a
/// time (value, classification, then gradient and shading only where some sample is
/// visible), compositing lane by lane so early termination stops at the same sample.
/// Samples where the fused gradient does not apply go through the scalar code.
bool marchBrickSimd(brickstore::VoxelType type, const Frame& f, const void* voxels,
                    const std::uint32_t* words, glm::vec3 local, glm::vec3 dv, glm::vec3 dir,
                    float t0, int& k, int kEnd, Accum& acc, RayCount& n);

/// The instruction set marchBrickSimd() runs on this host ("AVX3", "AVX2", "SSE4", ...).
std::string simdTargetName();
/// Samples per vector there.
int simdLanes();

} // namespace bc::render::detail
