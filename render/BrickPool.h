#pragma once
// GPU brick pool: bricks live in slots of one large 3D texture under a byte budget, LRU over
// slots, pinned while a batch of a frame uses them. Every upload is counted (count, bytes,
// milliseconds): this is the host->GPU bus of the residency model. Render thread only.
#include "brickstore/VoxelType.h"

#include <array>
#include <cstdint>
#include <functional>
#include <list>
#include <memory>
#include <optional>
#include <span>
#include <unordered_map>
#include <unordered_set>
#include <vector>

namespace bc::render {

struct BrickPoolConfig {
    std::uint64_t budgetBytes = 512ull << 20; ///< GPU bytes for brick slots
};

struct BrickPoolStats {
    std::uint64_t hits = 0;
    std::uint64_t uploads = 0;
    std::uint64_t bytesUploaded = 0;
    std::uint64_t evictions = 0;
    /// Uploads of bricks this pool held before and evicted (cleared by clear()).
    std::uint64_t refetches = 0;
    std::uint64_t bytesRefetched = 0;
    double uploadMs = 0.0;
};

/// How a texel of the pool maps back to native values: native = texel * scale + offset.
struct TexelMapping {
    double scale = 1.0;
    double offset = 0.0;
};

class BrickPool {
  public:
    /// Supplies a brick's stored voxels ((edge)^3, native type) on a miss.
    using Loader = std::function<std::span<const std::byte>()>;

    /// A pool of slots of `edge`^3 voxels of `type`. The slot count is the budget divided by
    /// the slot bytes, bounded by the largest 3D texture the driver allows.
    /// @throw RenderError when not even one slot fits (budget or texture size).
    BrickPool(brickstore::VoxelType type, std::uint32_t edge, const BrickPoolConfig& config);
    ~BrickPool();
    BrickPool(const BrickPool&) = delete;
    BrickPool& operator=(const BrickPool&) = delete;

    brickstore::VoxelType type() const { return mType; }
    std::uint32_t edge() const { return mEdge; }
    std::uint32_t capacity() const { return mCapacity; }
    /// The slot grid a pool of at most `n` slots uses when a 3D texture holds at most
    /// `perAxis` slots a side: the most slots that fit, as near a cube as that allows.
    static std::array<std::uint32_t, 3> slotGridFor(std::uint64_t n, std::uint64_t perAxis);
    /// The bytes a pool needs to hold `bricks` slots of `edge`^3 voxels of `type`, at most
    /// `budgetBytes`: a pool larger than every brick a store has buys nothing and costs its
    /// memory (and on a software GPU the time to clear it).
    static std::uint64_t bytesFor(std::uint64_t bricks, brickstore::VoxelType type,
                                  std::uint32_t edge, std::uint64_t budgetBytes);
    std::array<std::uint32_t, 3> slotGrid() const { return mSlotGrid; }
    std::array<std::uint32_t, 3> textureSize() const;
    std::uint64_t slotBytes() const;
    TexelMapping texelMapping() const;
    /// The GL texture name (GL_TEXTURE_3D, linear filtering, clamp to edge).
    unsigned texture() const;

    /// The slot holding `key`, uploading it through `load` on a miss (evicting the least
    /// recently used unpinned slot). The slot stays pinned until unpinAll(). nullopt when
    /// every slot is pinned. @throw what `load` throws; nothing changes then.
    std::optional<std::uint32_t> acquire(std::uint64_t key, const Loader& load);
    /// Ends a batch: every slot may be evicted again.
    void unpinAll();
    /// Forgets every brick (e.g. the volume changed); the texture stays allocated.
    void clear();
    bool resident(std::uint64_t key) const { return mSlotOf.count(key) != 0; }
    const BrickPoolStats& stats() const { return mStats; }

  private:
    void upload(std::uint32_t slot, std::span<const std::byte> voxels);

    struct Gpu;
    std::unique_ptr<Gpu> mGpu;
    brickstore::VoxelType mType;
    std::uint32_t mEdge;
    std::uint32_t mCapacity = 0;
    std::array<std::uint32_t, 3> mSlotGrid{};
    std::unordered_map<std::uint64_t, std::uint32_t> mSlotOf;
    std::vector<std::uint64_t> mKeyOf; ///< per slot; kNoKey when free
    std::vector<std::uint8_t> mPinned; ///< per slot
    std::list<std::uint32_t> mLru;     ///< unpinned occupied slots, oldest first
    std::vector<std::list<std::uint32_t>::iterator> mLruPos;
    std::vector<std::uint32_t> mFree;
    std::vector<std::uint16_t> mStaging;        ///< i16 -> biased u16
    std::unordered_set<std::uint64_t> mEvicted; ///< evicted, not uploaded since
    BrickPoolStats mStats;
};

} // namespace bc::render
