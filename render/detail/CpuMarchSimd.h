#pragma once
// The CPU raycaster's march vectorised with Highway (render/detail/CpuMarchSimd.cpp), for the
// widest instruction set the host has: across rays (a packet of rays, one sample per lane), or
// across consecutive samples of one ray in one brick.
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

/// One pixel's ray for marchPacketSimd(): its image-plane position and sample shift
/// (RayWalk::begin()) and its state; no state: no pixel.
struct PacketRay {
    float sx = 0.0f, sy = 0.0f, shift = 0.0f;
    RayState* state = nullptr;
    RayResume* resume = nullptr; ///< where it goes on if it stops to wait (with state)
};

/// The rays `rays[0, count)` for the bricks of batch f.batch, a vector of rays at a time: each
/// lane holds one ray (the next of the list when its own has no samples left in the pass), and
/// a step takes one sample of every lane, or leaps the lanes in empty octree leaves over their
/// nodes. Each ray walks the brick grid on its own (RayWalk); lanes in different bricks sample
/// their own bricks in the same step. List neighbouring pixels next to each other (blocks of
/// 4x4): the lanes' rays then read the same voxels and octree words.
///
/// The same image as marchRay() with marchBrick(), bit for bit: every lane takes the scalar
/// code's samples with its float operations in its order and composites them in order; it may
/// take a few more transparent samples, like marchBrickSimd(). Not for pre-integration.
void marchPacketSimd(brickstore::VoxelType type, const Frame& f, const PacketRay* rays,
                     std::size_t count, RayCount& n);

/// segmentEnds() of CpuRay.h for the rays `rays[0, count)`, a vector of rays at a time (a
/// crop or clip ray by ray): ok[i] says whether ray i has ends, in[i] and out[i] are them.
/// Every march takes its ends from here, so they are the same whichever marched the lattice.
void segmentEndsSimd(const Frame& f, const PacketRay* rays, std::size_t count, glm::vec3* in,
                     glm::vec3* out, bool* ok);

/// Capping: where the rays `rays[0, count)` enter what they keep through a cut, a vector of rays
/// at a time: cut[i] says whether ray i does (a crop face or a plane inside the volume's box,
/// with a sample of its lattice behind it), entries[i] is where. Every march takes its faces
/// from here.
void cutEntriesSimd(const Frame& f, const PacketRay* rays, std::size_t count, CutEntry* entries,
                    bool* cut);

/// The instruction set marchBrickSimd() runs on this host ("AVX3", "AVX2", "SSE4", ...).
std::string simdTargetName();
/// Samples per vector there.
int simdLanes();

} // namespace bc::render::detail
