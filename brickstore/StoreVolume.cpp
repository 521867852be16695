#include "brickstore/StoreVolume.h"

#include "brickstore/BrickStore.h"

#include <algorithm>
#include <atomic>
#include <cstring>
#include <exception>
#include <mutex>
#include <stdexcept>
#include <thread>

namespace bc::brickstore {
namespace {

class StoreLevelSource final : public VolumeSource {
  public:
    StoreLevelSource(const BrickStore& store, std::uint32_t level, unsigned threads)
        : mStore(store), mLevel(level),
          mThreads(threads ? threads : std::max(1u, std::thread::hardware_concurrency())) {
        const auto& layout = store.layout();
        if (level >= layout.levels().size())
            throw std::out_of_range(store.path() + ": no level " + std::to_string(level) +
                                    " (the store has " + std::to_string(layout.levels().size()) +
                                    ")");
        mInfo = store.info().volume;
        mInfo.dims = layout.levels()[level].dims;
        for (auto& s : mInfo.spacingMm)
            s *= double(1u << level);
        mSlab.resize(std::size_t(layout.geometry().brickVoxels) * mInfo.sliceBytes());
    }

    const VolumeInfo& info() const override { return mInfo; }

  private:
    void readNextSlices(std::uint64_t count, std::span<std::byte> out) override {
        const std::uint64_t sliceBytes = mInfo.sliceBytes();
        const std::uint32_t b = mStore.layout().geometry().brickVoxels;
        for (std::uint64_t i = 0; i < count; ++i) {
            const std::uint64_t z = nextSlice() + i;
            std::uint32_t row = static_cast<std::uint32_t>(z / b);
            if (row != mSlabRow) loadRow(row);
            std::memcpy(out.data() + i * sliceBytes, mSlab.data() + (z % b) * sliceBytes,
                        sliceBytes);
        }
    }

    /// Decompresses brick row `bz` and copies its payloads into the slab.
    void loadRow(std::uint32_t bz) {
        const auto& layout = mStore.layout();
        const auto& level = layout.levels()[mLevel];
        const std::uint64_t perRow = std::uint64_t(level.bricks[0]) * level.bricks[1];
        std::atomic<std::uint64_t> next{0};
        std::exception_ptr error;
        std::mutex errorMutex;
        auto worker = [&] {
            std::vector<std::byte> brick(mStore.brickBytes());
            for (std::uint64_t i = next++; i < perRow; i = next++) {
                BrickKey key{
                    mLevel,
                    {std::uint32_t(i % level.bricks[0]), std::uint32_t(i / level.bricks[0]), bz}};
                try {
                    mStore.readBrick(key, brick);
                    copyPayload(key, brick);
                } catch (...) {
                    std::lock_guard lock(errorMutex);
                    if (!error) error = std::current_exception();
                }
            }
        };
        {
            std::vector<std::jthread> pool;
            for (unsigned t = 0; t < std::min<std::uint64_t>(mThreads, perRow); ++t)
                pool.emplace_back(worker);
        }
        if (error) std::rethrow_exception(error);
        mSlabRow = bz;
    }

    void copyPayload(const BrickKey& key, const std::vector<std::byte>& brick) {
        const auto& layout = mStore.layout();
        const std::size_t vb = voxelBytes(mInfo.type);
        const std::uint64_t a = layout.geometry().apronVoxels, edge = layout.storedEdge();
        auto origin = layout.payloadOrigin(key);
        auto extent = layout.payloadExtent(key);
        for (std::uint64_t z = 0; z < extent[2]; ++z)
            for (std::uint64_t y = 0; y < extent[1]; ++y) {
                const std::byte* src = brick.data() + (((z + a) * edge + (y + a)) * edge + a) * vb;
                std::byte* dst =
                    mSlab.data() +
                    ((z * mInfo.dims[1] + origin[1] + y) * mInfo.dims[0] + origin[0]) * vb;
                std::memcpy(dst, src, extent[0] * vb);
            }
    }

    const BrickStore& mStore;
    std::uint32_t mLevel;
    unsigned mThreads;
    VolumeInfo mInfo;
    std::vector<std::byte> mSlab;
    std::uint32_t mSlabRow = ~0u;
};

} // namespace

std::unique_ptr<VolumeSource> openStoreLevel(const BrickStore& store, std::uint32_t level,
                                             unsigned threads) {
    return std::make_unique<StoreLevelSource>(store, level, threads);
}

} // namespace bc::brickstore
