// Zarr v2 arrays and OME-Zarr images (detail/ZarrMetadata.h reads the JSON, detail/ZarrChunks.h
// the chunk files). The volume streams a z-row of chunks at a time (every chunk with the same
// z index), its chunks decoded side by side by up to one thread per core.
//
// Memory bound: a row whose whole slices take at most kMaxSlabBytes (256 MiB) is decoded once
// into a slab that serves the readSlices calls inside it; a deeper row is decoded again for
// each readSlices call that reaches into it, straight into the caller's slices. On top, each
// decoding thread holds one decoded chunk and its compressed file, the threads together at
// most kDecodeBudgetBytes (256 MiB) or, when one chunk is larger, one thread with that chunk
// (at most kZarrMaxChunkBytes, 1 GiB, decoded). A store larger than memory therefore ingests.
#include "brickstore/Error.h"
#include "brickstore/Readers.h"
#include "brickstore/readers/detail/ZarrChunks.h"
#include "brickstore/readers/detail/ZarrMetadata.h"

#include <algorithm>
#include <atomic>
#include <bit>
#include <cmath>
#include <cstring>
#include <exception>
#include <mutex>
#include <thread>
#include <vector>

namespace bc::brickstore {

namespace {

using detail::ZarrArray;
using detail::ZarrChunkIndex;
using detail::ZarrChunkReader;

constexpr std::uint64_t kMaxSlabBytes = 256ull << 20;
constexpr std::uint64_t kDecodeBudgetBytes = 256ull << 20;

/// Copies `count` voxels of `bytes` each from a chunk into a slice row (or leaves them where a
/// chunk was decoded in place) and puts them in host byte order.
void copyVoxels(std::byte* dst, const std::byte* src, std::uint64_t count, std::size_t bytes,
                bool swap) {
    if (dst != src) std::memcpy(dst, src, count * bytes);
    if (!swap || bytes == 1) return;
    for (std::uint64_t i = 0; i < count; ++i) {
        std::byte* v = dst + i * bytes;
        std::reverse(v, v + bytes);
    }
}

/// Index of the first non-finite float of `count` at `p`, or `count`.
std::uint64_t firstNonFinite(const std::byte* p, std::uint64_t count) {
    for (std::uint64_t i = 0; i < count; ++i) {
        float v;
        std::memcpy(&v, p + i * 4, 4);
        if (!std::isfinite(v)) return i;
    }
    return count;
}

class ZarrSource final : public VolumeSource {
  public:
    explicit ZarrSource(detail::ZarrImage image)
        : mArray(std::move(image.array)), mInfo(std::move(image.info)), mFolder(mArray),
          mVoxelBytes(voxelBytes(mArray.type)),
          mSwap((mArray.endian == Endian::Big) != (std::endian::native == std::endian::big)),
          mChunksX((mInfo.dims[0] + mArray.chunkDim(0) - 1) / mArray.chunkDim(0)),
          mChunksY((mInfo.dims[1] + mArray.chunkDim(1) - 1) / mArray.chunkDim(1)),
          mRowDepth(mArray.chunkDim(2)),
          mUseSlab(std::min(mRowDepth, mInfo.dims[2]) * mInfo.sliceBytes() <= kMaxSlabBytes) {
        const std::uint64_t perThread = 2 * mArray.chunkBytes;
        const std::uint64_t budget = std::max<std::uint64_t>(1, kDecodeBudgetBytes / perThread);
        const std::uint64_t cores = std::max(1u, std::thread::hardware_concurrency());
        mWorkers = std::size_t(std::min({budget, cores, mChunksX * mChunksY}));
        for (std::size_t w = 0; w < mWorkers; ++w)
            mReaders.push_back(std::make_unique<ZarrChunkReader>(mArray, mFolder));
        mScratch.resize(mWorkers);
    }

    const VolumeInfo& info() const override { return mInfo; }

  private:
    void readNextSlices(std::uint64_t count, std::span<std::byte> out) override {
        const std::uint64_t sliceBytes = mInfo.sliceBytes();
        for (std::uint64_t z = nextSlice(), end = z + count; z < end;) {
            const std::uint64_t row = z / mRowDepth, first = row * mRowDepth;
            const std::uint64_t last = std::min(first + mRowDepth, mInfo.dims[2]);
            const std::uint64_t n = std::min(end, last) - z;
            std::span<std::byte> dest = out.subspan((z - nextSlice()) * sliceBytes, n * sliceBytes);
            if (!mUseSlab || (z == first && n == last - first && mSlabRow != row)) {
                decodeRow(row, z, z + n, dest);
            } else {
                if (mSlabRow != row) {
                    mSlab.resize((last - first) * sliceBytes);
                    mSlabRow = ~std::uint64_t(0); // a failed decode leaves no valid slab
                    decodeRow(row, first, last, mSlab);
                    mSlabRow = row;
                }
                std::memcpy(dest.data(), mSlab.data() + (z - first) * sliceBytes, dest.size());
            }
            z += n;
        }
    }

    /// Decodes slices zFrom..zTo-1, all in chunk row `row`, into `dest` (whole slices), the
    /// row's chunks shared out among the decoding threads.
    void decodeRow(std::uint64_t row, std::uint64_t zFrom, std::uint64_t zTo,
                   std::span<std::byte> dest) {
        const std::uint64_t chunks = mChunksX * mChunksY;
        std::atomic<std::uint64_t> next{0};
        std::atomic<bool> failed{false};
        std::exception_ptr error;
        std::mutex errorMutex;
        auto work = [&](std::size_t w) {
            try {
                for (std::uint64_t c; !failed && (c = next++) < chunks;)
                    placeChunk(w, {row, c / mChunksX, c % mChunksX}, zFrom, zTo, dest);
            } catch (...) {
                std::lock_guard lock(errorMutex);
                if (!error) error = std::current_exception();
                failed = true;
            }
        };
        {
            std::vector<std::jthread> helpers;
            for (std::size_t w = 1; w < mWorkers; ++w)
                helpers.emplace_back(work, w);
            work(0);
        }
        if (error) std::rethrow_exception(error);
    }

    /// Whether the chunk is exactly `dest`: one chunk spans whole slices and the request is the
    /// chunk's depth, so it can be decoded straight into the caller's buffer.
    bool chunkIsDest(std::uint64_t zFrom, std::uint64_t zTo, std::span<std::byte> dest) const {
        return zTo - zFrom == mRowDepth && dest.size() == mArray.chunkBytes &&
               mArray.chunkDim(0) == mInfo.dims[0] && mArray.chunkDim(1) == mInfo.dims[1];
    }

    /// Decodes one chunk with thread `w`'s reader and puts its voxels of slices zFrom..zTo-1
    /// into `dest`; a chunk without a file puts the fill value there.
    void placeChunk(std::size_t w, const ZarrChunkIndex& index, std::uint64_t zFrom,
                    std::uint64_t zTo, std::span<std::byte> dest) {
        const bool direct = chunkIsDest(zFrom, zTo, dest);
        std::vector<std::byte>& scratch = mScratch[w];
        if (!direct && scratch.size() != mArray.chunkBytes) scratch.resize(mArray.chunkBytes);
        const bool present = mReaders[w]->read(index, direct ? dest : std::span(scratch));
        const std::uint64_t cx = mArray.chunkDim(0), cy = mArray.chunkDim(1);
        const std::uint64_t x0 = index[2] * cx, y0 = index[1] * cy;
        const std::uint64_t width = std::min(cx, mInfo.dims[0] - x0);
        const std::uint64_t height = std::min(cy, mInfo.dims[1] - y0);
        for (std::uint64_t z = zFrom; z < zTo; ++z) {
            for (std::uint64_t y = 0; y < height; ++y) {
                std::byte* dst =
                    dest.data() +
                    (((z - zFrom) * mInfo.dims[1] + y0 + y) * mInfo.dims[0] + x0) * mVoxelBytes;
                if (!present) {
                    fillVoxels(dst, width);
                    continue;
                }
                const std::uint64_t zc = z - index[0] * mRowDepth;
                const std::byte* src =
                    direct ? dst : scratch.data() + (zc * cy + y) * cx * mVoxelBytes;
                copyVoxels(dst, src, width, mVoxelBytes, mSwap);
                if (mInfo.type == VoxelType::F32) checkFinite(dst, width, index, x0, y0 + y, z);
            }
        }
    }

    /// Doubles the filled run with each copy: a missing chunk costs memcpy speed.
    void fillVoxels(std::byte* dst, std::uint64_t count) const {
        const std::uint64_t total = count * mVoxelBytes;
        std::memcpy(dst, mArray.fillValue.data(), mVoxelBytes);
        for (std::uint64_t done = mVoxelBytes; done < total; done *= 2)
            std::memcpy(dst + done, dst, std::min(done, total - done));
    }

    /// NaN or infinity would poison every min/max and average the store keeps.
    void checkFinite(const std::byte* row, std::uint64_t count, const ZarrChunkIndex& index,
                     std::uint64_t x0, std::uint64_t y, std::uint64_t z) const {
        const std::uint64_t i = firstNonFinite(row, count);
        if (i == count) return;
        float v;
        std::memcpy(&v, row + i * 4, 4);
        throw FormatError(mReaders[0]->chunkPath(index), "chunk",
                          "voxel (" + std::to_string(x0 + i) + "," + std::to_string(y) + "," +
                              std::to_string(z) + ") is " + (std::isnan(v) ? "NaN" : "infinite") +
                              "; float volumes must be finite");
    }

    ZarrArray mArray;
    VolumeInfo mInfo;
    detail::ZarrFolder mFolder;
    std::size_t mVoxelBytes;
    bool mSwap;
    std::uint64_t mChunksX, mChunksY; ///< chunks along x and y: one row's chunks
    std::uint64_t mRowDepth;          ///< slices of a chunk row (the last may have fewer)
    bool mUseSlab;
    std::size_t mWorkers = 1;
    std::vector<std::unique_ptr<ZarrChunkReader>> mReaders; ///< one per decoding thread
    std::vector<std::vector<std::byte>> mScratch;           ///< one decoded chunk per thread
    std::vector<std::byte> mSlab;                           ///< the slices of row mSlabRow
    std::uint64_t mSlabRow = ~std::uint64_t(0);
};

} // namespace

std::unique_ptr<VolumeSource> openZarr(const std::string& path, std::uint32_t level) {
    return std::make_unique<ZarrSource>(detail::readZarrImage(path, level));
}

} // namespace bc::brickstore
