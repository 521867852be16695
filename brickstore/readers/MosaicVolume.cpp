// A volume tiled IxJxK times: the way to turn a real scan of megabytes into a test volume of
// gigabytes. Along x and y the tiles are copies within a slice; along z a fresh source is
// opened per repetition, since a reader only streams forwards.
#include "brickstore/Error.h"
#include "brickstore/Readers.h"

#include <algorithm>
#include <cstring>
#include <vector>

namespace bc::brickstore {
namespace {

/// Source slices read per call into the scratch buffer, at most (and at least one slice).
constexpr std::uint64_t kScratchBytes = 32ull << 20;

std::string tilesText(const std::array<std::uint64_t, 3>& tiles) {
    return std::to_string(tiles[0]) + "x" + std::to_string(tiles[1]) + "x" +
           std::to_string(tiles[2]);
}

class MosaicVolume final : public VolumeSource {
  public:
    MosaicVolume(std::function<std::unique_ptr<VolumeSource>()> open,
                 const std::array<std::uint64_t, 3>& tiles)
        : mOpen(std::move(open)), mTiles(tiles) {
        const std::string name = "mosaic " + tilesText(tiles);
        for (std::uint64_t t : tiles)
            if (t == 0) throw FormatError(name, "tiles", "tile counts must be at least 1");
        mSource = openSource();
        mSourceInfo = mSource->info();
        validateVolumeInfo(mSourceInfo, name);
        mInfo = mSourceInfo;
        for (int a = 0; a < 3; ++a) {
            if (mTiles[a] > kMaxDimVoxels / mSourceInfo.dims[a])
                throw FormatError(name, "dims",
                                  "tiling " + std::to_string(mSourceInfo.dims[a]) + " voxels " +
                                      std::to_string(mTiles[a]) + " times exceeds the limit of " +
                                      std::to_string(kMaxDimVoxels));
            mInfo.dims[a] = mSourceInfo.dims[a] * mTiles[a];
        }
        mInfo.description = name + " of " + mSourceInfo.description;
        validateVolumeInfo(mInfo, name);
    }

    const VolumeInfo& info() const override { return mInfo; }

  private:
    void readNextSlices(std::uint64_t count, std::span<std::byte> out) override {
        const std::uint64_t sourceSliceBytes = mSourceInfo.sliceBytes();
        const std::uint64_t batchLimit =
            std::max<std::uint64_t>(1, kScratchBytes / sourceSliceBytes);
        std::byte* dst = out.data();
        while (count > 0) {
            if (mSourceZ == mSourceInfo.dims[2]) reopen();
            const std::uint64_t batch =
                std::min({count, batchLimit, mSourceInfo.dims[2] - mSourceZ});
            mScratch.resize(batch * sourceSliceBytes);
            mSource->readSlices(batch, mScratch);
            for (std::uint64_t i = 0; i < batch; ++i, dst += mInfo.sliceBytes())
                tileSlice(mScratch.data() + i * sourceSliceBytes, dst);
            mSourceZ += batch;
            count -= batch;
        }
    }

    std::unique_ptr<VolumeSource> openSource() {
        std::unique_ptr<VolumeSource> source = mOpen();
        if (!source)
            throw FormatError("mosaic " + tilesText(mTiles), "source",
                              "the source could not be opened");
        return source;
    }

    /// Next repetition along z: a fresh stream of the same volume.
    void reopen() {
        mSource.reset(); // release the old reader's buffers and file before the new one opens
        mSource = openSource();
        const VolumeInfo& again = mSource->info();
        if (again.dims != mSourceInfo.dims || again.type != mSourceInfo.type)
            throw FormatError("mosaic " + tilesText(mTiles), "source",
                              "reopened source differs from the first: " + again.description);
        mSourceZ = 0;
    }

    /// One output slice: the source slice's rows, each repeated tiles[0] times, repeated tiles[1]
    /// times.
    void tileSlice(const std::byte* src, std::byte* dst) const {
        const std::uint64_t rowBytes = mSourceInfo.dims[0] * voxelBytes(mSourceInfo.type);
        const std::uint64_t outRowBytes = rowBytes * mTiles[0];
        for (std::uint64_t y = 0; y < mSourceInfo.dims[1]; ++y) {
            std::byte* row = dst + y * outRowBytes;
            for (std::uint64_t i = 0; i < mTiles[0]; ++i)
                std::memcpy(row + i * rowBytes, src + y * rowBytes, rowBytes);
        }
        const std::uint64_t blockBytes = outRowBytes * mSourceInfo.dims[1];
        for (std::uint64_t j = 1; j < mTiles[1]; ++j)
            std::memcpy(dst + j * blockBytes, dst, blockBytes);
    }

    std::function<std::unique_ptr<VolumeSource>()> mOpen;
    std::array<std::uint64_t, 3> mTiles;
    std::unique_ptr<VolumeSource> mSource;
    VolumeInfo mSourceInfo;
    VolumeInfo mInfo;
    std::vector<std::byte> mScratch; ///< at most kScratchBytes (or one source slice)
    std::uint64_t mSourceZ = 0;      ///< next slice of mSource
};

} // namespace

std::unique_ptr<VolumeSource> makeMosaic(std::function<std::unique_ptr<VolumeSource>()> open,
                                         const std::array<std::uint64_t, 3>& tiles) {
    return std::make_unique<MosaicVolume>(std::move(open), tiles);
}

} // namespace bc::brickstore
