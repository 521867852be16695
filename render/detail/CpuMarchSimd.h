#pragma once
// The CPU raycaster's march through one brick, vectorised across consecutive samples of a ray
// with Highway (render/detail/CpuMarchSimd.cpp), for the widest instruction set the host has.
#include "brickstore/BrickStore.h"
#include "render/detail/CpuRay.h"

#include <cstdint>
#include <string>

namespace bc::render::detail {

/// marchBrick() of CpuRay.h for voxels of `type`, same arguments and the same image: tests
/// the octree a vector of samples at a time, skips the samples in empty leaves and leaps over
/// empty nodes, and takes the rest a vector at a time (value, classification, then gradient
/// and shading only where some sample is visible), compositing lane by lane so early
/// termination stops at the same sample. Samples where the fused gradient does not apply go
/// through the scalar code. It may take a few more (transparent) samples than marchBrick().
bool marchBrickSimd(brickstore::VoxelType type, const Frame& f, const void* voxels,
                    const std::uint32_t* words, glm::vec3 local, glm::vec3 dv, glm::vec3 dir,
                    float t0, int& k, int kEnd, Accum& acc, RayCount& n);

/// The instruction set marchBrickSimd() runs on this host ("AVX3", "AVX2", "SSE4", ...).
std::string simdTargetName();
/// Samples per vector there.
int simdLanes();

} // namespace bc::render::detail
