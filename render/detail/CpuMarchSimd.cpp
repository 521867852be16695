// The CPU raycaster's march vectorised (render/detail/CpuMarchSimd.h), compiled once per
// instruction set by Highway's foreach_target and dispatched at run time to the best one the
// host has. Two layouts:
//
// - Across rays (marchPacketSimd, the default): each lane is one ray of a list of neighbouring
//   pixels, and a step takes one sample of every lane. A ray is a chain of dependent steps
//   (DDA, leaf test, leap, sample, composite); sixteen independent chains side by side keep
//   the core busy where one ray's chain leaves it waiting. Lanes walk the brick grid each on
//   its own and sample their own bricks (32-bit gather offsets from one base); a lane out of
//   samples takes its next brick, or the next ray of the list, once a quarter of the lanes
//   are. Visible samples wait in a queue for their colour (TF colour, gradient, shading),
//   taken a full vector at a time: a step only classifies, so the gradient's 24 voxel loads
//   are paid per visible sample, not per lane of every step with one visible sample. A queued
//   sample names its ray, not its lane, and adds to the ray's state: a lane that takes another
//   brick or ray leaves the queue as it is (only a ray that composites outside the queue, a
//   brick of one value or the scalar loop, has it emptied first).
//
// - Across one ray's consecutive samples in one brick (marchBrickSimd): the brick DDA, the
//   octree leaps and early termination stay the scalar code's, per ray; the per-sample work
//   runs a vector of samples at a time. Pre-integration's scalar march aside, this is what
//   RenderOptions::packets = false selects.
//
// Same image as the scalar march, bit for bit: every lane does the scalar code's float
// operations in the scalar code's order, and this file, with the parts it includes, is compiled
// without contraction into fused multiply-adds (render/CMakeLists.txt), so a sample's colour does
// not depend on the lane it ran in, on the vector width, or on whether it ran here at all.
// Compositing keeps each ray's order: across samples it goes lane by lane; across rays a lane's
// transmittance is updated at its step (so early termination stops at the same sample) and the
// queued colours are added to its sums in the order its samples were taken.
#undef HWY_TARGET_INCLUDE
#define HWY_TARGET_INCLUDE "render/detail/CpuMarchSimd.cpp"
#include <hwy/foreach_target.h> // IWYU pragma: keep

#include <hwy/highway.h>

#include "render/detail/CpuMarchSimd.h"

// The march's parts by phase, in order (each includes the parts it uses): Highway's -inl.h
// headers, compiled once per target with this file and included from here only, so that
// they share its -ffp-contract=off.
// clang-format off
#include "render/detail/CpuMarchGathers-inl.h" // voxels of a vector of samples, trilinear
#include "render/detail/CpuMarchShading-inl.h" // classification, lighting, the colour queue
#include "render/detail/CpuMarchBrick-inl.h"   // one ray in one brick; lanes' empty-space leaps
#include "render/detail/CpuMarchBegin-inl.h"   // the walks of a vector of fresh rays
#include "render/detail/CpuMarchPacket-inl.h"  // lanes of rays: steps and refills
#include "render/detail/CpuMarchModes-inl.h"   // the same for the other modes than composite
// clang-format on

HWY_BEFORE_NAMESPACE();
namespace bc::render::detail {
namespace HWY_NAMESPACE {

/// marchBrickSimd() on this target.
bool MarchBrick(brickstore::VoxelType type, const Frame& f, const void* voxels,
                const std::uint32_t* words, glm::vec3 local, glm::vec3 dv, glm::vec3 dir, float t0,
                int& k, int kEnd, Accum& acc, RayCount& n) {
    switch (type) {
    case brickstore::VoxelType::U8:
        return marchBrickT(f, static_cast<const std::uint8_t*>(voxels), words, local, dv, dir, t0,
                           k, kEnd, acc, n);
    case brickstore::VoxelType::U16:
        return marchBrickT(f, static_cast<const std::uint16_t*>(voxels), words, local, dv, dir, t0,
                           k, kEnd, acc, n);
    case brickstore::VoxelType::I16:
        return marchBrickT(f, static_cast<const std::int16_t*>(voxels), words, local, dv, dir, t0,
                           k, kEnd, acc, n);
    case brickstore::VoxelType::F32:
        return marchBrickT(f, static_cast<const float*>(voxels), words, local, dv, dir, t0, k, kEnd,
                           acc, n);
    }
    return true;
}

/// marchPacketSimd() on this target.
void MarchPacket(brickstore::VoxelType type, const Frame& f, const PacketRay* rays,
                 std::size_t count, RayCount& n) {
    const int lanes = int(hn::Lanes(DF()));
    const bool composite = f.mode == BlendMode::Composite;
    switch (type) {
    case brickstore::VoxelType::U8:
        return composite ? Packet<std::uint8_t>(f, rays, count, lanes, n).run()
                         : ModePacket<std::uint8_t>(f, rays, count, lanes, n).run();
    case brickstore::VoxelType::U16:
        return composite ? Packet<std::uint16_t>(f, rays, count, lanes, n).run()
                         : ModePacket<std::uint16_t>(f, rays, count, lanes, n).run();
    case brickstore::VoxelType::I16:
        return composite ? Packet<std::int16_t>(f, rays, count, lanes, n).run()
                         : ModePacket<std::int16_t>(f, rays, count, lanes, n).run();
    case brickstore::VoxelType::F32:
        return composite ? Packet<float>(f, rays, count, lanes, n).run()
                         : ModePacket<float>(f, rays, count, lanes, n).run();
    }
}

/// segmentEndsSimd() on this target.
void SegmentEnds(const Frame& f, const PacketRay* rays, std::size_t count, glm::vec3* in,
                 glm::vec3* out, bool* ok) {
    segmentEndsOf(f, rays, count, in, out, ok);
}

/// cutEntriesSimd() on this target.
void CutEntries(const Frame& f, const PacketRay* rays, std::size_t count, CutEntry* entries,
                bool* cut) {
    cutEntriesOf(f, rays, count, entries, cut);
}

std::int64_t Target() {
    return HWY_TARGET;
}
int LaneCount() {
    return int(hn::Lanes(DF()));
}

} // namespace HWY_NAMESPACE
} // namespace bc::render::detail
HWY_AFTER_NAMESPACE();

#if HWY_ONCE
namespace bc::render::detail {

HWY_EXPORT(MarchBrick);
HWY_EXPORT(MarchPacket);
HWY_EXPORT(SegmentEnds);
HWY_EXPORT(CutEntries);
HWY_EXPORT(Target);
HWY_EXPORT(LaneCount);

bool marchBrickSimd(brickstore::VoxelType type, const Frame& f, const void* voxels,
                    const std::uint32_t* words, glm::vec3 local, glm::vec3 dv, glm::vec3 dir,
                    float t0, int& k, int kEnd, Accum& acc, RayCount& n) {
    return HWY_DYNAMIC_DISPATCH(MarchBrick)(type, f, voxels, words, local, dv, dir, t0, k, kEnd,
                                            acc, n);
}

void marchPacketSimd(brickstore::VoxelType type, const Frame& f, const PacketRay* rays,
                     std::size_t count, RayCount& n) {
    HWY_DYNAMIC_DISPATCH(MarchPacket)(type, f, rays, count, n);
}

void segmentEndsSimd(const Frame& f, const PacketRay* rays, std::size_t count, glm::vec3* in,
                     glm::vec3* out, bool* ok) {
    HWY_DYNAMIC_DISPATCH(SegmentEnds)(f, rays, count, in, out, ok);
}

void cutEntriesSimd(const Frame& f, const PacketRay* rays, std::size_t count, CutEntry* entries,
                    bool* cut) {
    HWY_DYNAMIC_DISPATCH(CutEntries)(f, rays, count, entries, cut);
}

std::string simdTargetName() {
    return hwy::TargetName(HWY_DYNAMIC_DISPATCH(Target)());
}

int simdLanes() {
    return HWY_DYNAMIC_DISPATCH(LaneCount)();
}

} // namespace bc::render::detail
#endif
