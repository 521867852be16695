#include "brickstore/detail/LevelBuilder.h"

#include "brickstore/detail/BrickSummary.h"

#include <algorithm>
#include <chrono>
#include <cstring>

namespace bc::brickstore::detail {

std::uint64_t LevelBuilder::ringSlices(const StoreLayout& layout, std::uint32_t level,
                                       std::uint64_t extra) {
    const std::uint64_t depth = layout.levels().at(level).dims[2];
    return std::max<std::uint64_t>(1, std::min(layout.storedEdge() + extra, depth));
}

std::uint64_t LevelBuilder::pipelinedExtra(const StoreLayout& layout, std::uint32_t level) {
    const std::uint64_t b = layout.geometry().brickVoxels;
    return level == 0 ? b : (b + 1) / 2;
}

LevelBuilder::LevelBuilder(const StoreLayout& layout, std::uint32_t level, VoxelType type,
                           Sink sink, LevelBuilder* next, std::uint64_t extraSlices)
    : mLayout(layout), mLevel(level), mType(type), mVoxelBytes(voxelBytes(type)),
      mDims(layout.levels().at(level).dims), mRingSlices(ringSlices(layout, level, extraSlices)),
      mSink(std::move(sink)), mNext(next),
      mUncut(layout.levels().at(level).bricks[2], kNotHandedOut) {
    mRing.resize(std::size_t(mRingSlices) * mDims[0] * mDims[1] * mVoxelBytes);
    if (mNext) mDown.resize(((mDims[0] + 1) / 2) * ((mDims[1] + 1) / 2) * mVoxelBytes);
}

bool LevelBuilder::finished() const {
    return mReceived == mDims[2];
}

const std::byte* LevelBuilder::slice(std::int64_t z) const {
    z = std::clamp<std::int64_t>(z, 0, std::int64_t(mDims[2]) - 1);
    std::size_t sliceBytes = mDims[0] * mDims[1] * mVoxelBytes;
    return mRing.data() + std::size_t(std::uint64_t(z) % mRingSlices) * sliceBytes;
}

void LevelBuilder::pushSlice(const std::byte* data) {
    const std::uint64_t z = mReceived;
    const std::uint32_t b = mLayout.geometry().brickVoxels, a = mLayout.geometry().apronVoxels;
    if (z >= mRingSlices) {
        // Slice z takes the slot of slice z - ring, which rows up to (z - ring + A) / B read
        // (all handed out already: the ring holds B slices more than a row reads).
        const std::uint64_t old = z - mRingSlices;
        const auto last = std::uint32_t(
            std::min<std::uint64_t>((old + a) / b, mLayout.levels()[mLevel].bricks[2] - 1));
        if (!waitForRowsCut(last)) return;
    }
    ++mReceived;
    const std::size_t sliceBytes = mDims[0] * mDims[1] * mVoxelBytes;
    std::memcpy(mRing.data() + std::size_t(z % mRingSlices) * sliceBytes, data, sliceBytes);

    // The next level's slice z/2 averages slices z-1 and z (or z twice at an odd end).
    bool last = z + 1 == mDims[2];
    if (mNext && (z % 2 == 1 || last)) {
        const std::byte* first = z % 2 == 1 ? slice(std::int64_t(z) - 1) : slice(z);
        downsampleSlices(mType, first, slice(z), mDims[0], mDims[1], mDown.data());
        mNext->pushSlice(mDown.data());
    }
    // A row of bricks is ready once every slice its aprons read has arrived.
    const auto& level = mLayout.levels()[mLevel];
    while (mNextRow < level.bricks[2] &&
           std::min<std::uint64_t>(std::uint64_t(mNextRow + 1) * b + a, mDims[2]) <= z + 1)
        emitRow(mNextRow++);
}

void LevelBuilder::emitRow(std::uint32_t bz) {
    const auto& level = mLayout.levels()[mLevel];
    {
        std::lock_guard lock(mMutex);
        mUncut[bz] = level.bricks[0] * level.bricks[1];
    }
    for (std::uint32_t by = 0; by < level.bricks[1]; ++by)
        for (std::uint32_t bx = 0; bx < level.bricks[0]; ++bx)
            mSink(BrickJob{this, mLayout.indexOf({mLevel, {bx, by, bz}}), bx, by, bz});
}

void LevelBuilder::cut(const BrickJob& job, std::byte* out) {
    cutBrick(job.bx, job.by, job.bz, out);
    std::lock_guard lock(mMutex);
    if (--mUncut[job.bz] != 0) return;
    while (mRowsCut < mUncut.size() && mUncut[mRowsCut] == 0)
        ++mRowsCut;
    mRowCut.notify_all();
}

bool LevelBuilder::waitForRowsCut(std::uint32_t row) {
    std::unique_lock lock(mMutex);
    if (mRowsCut > row) return !mAborted;
    const auto start = std::chrono::steady_clock::now();
    mRowCut.wait(lock, [&] { return mAborted || mRowsCut > row; });
    mWaitedNs += std::uint64_t(std::chrono::duration_cast<std::chrono::nanoseconds>(
                                   std::chrono::steady_clock::now() - start)
                                   .count());
    return !mAborted;
}

void LevelBuilder::abort() {
    std::lock_guard lock(mMutex);
    mAborted = true;
    mRowCut.notify_all();
}

namespace {

/// `count` copies of the voxel at `value` (1, 2 or 4 bytes): a typed fill the compiler
/// vectorises, where a memcpy per voxel cost most of a thin volume's ingest.
void fillVoxels(std::byte* out, const std::byte* value, std::size_t count, std::size_t vb) {
    switch (vb) {
    case 1:
        std::memset(out, int(*value), count);
        return;
    case 2: {
        std::uint16_t v;
        std::memcpy(&v, value, 2);
        std::fill_n(reinterpret_cast<std::uint16_t*>(out), count, v);
        return;
    }
    default: {
        std::uint32_t v;
        std::memcpy(&v, value, 4);
        std::fill_n(reinterpret_cast<std::uint32_t*>(out), count, v);
        return;
    }
    }
}

} // namespace

void LevelBuilder::cutBrick(std::uint32_t bx, std::uint32_t by, std::uint32_t bz,
                            std::byte* out) const {
    const std::int64_t b = mLayout.geometry().brickVoxels, a = mLayout.geometry().apronVoxels;
    const std::int64_t edge = mLayout.storedEdge();
    const std::int64_t dx = mDims[0], dy = mDims[1];
    const std::size_t vb = mVoxelBytes, rowBytes = std::size_t(edge) * vb;
    const std::int64_t x0 = bx * b - a;
    // Columns [x0, x0 + edge) map to clamped source columns: a run that is inside the volume
    // is one memcpy; the clamped ends repeat the border voxel.
    const std::int64_t inBegin = std::max<std::int64_t>(x0, 0);
    const std::int64_t inEnd = std::min<std::int64_t>(x0 + edge, dx);
    const std::byte* previousRow = nullptr;
    const std::byte* previousDst = nullptr;
    for (std::int64_t k = 0; k < edge; ++k) {
        const std::byte* src = slice(std::int64_t(bz) * b - a + k);
        for (std::int64_t j = 0; j < edge; ++j) {
            std::int64_t y = std::clamp<std::int64_t>(std::int64_t(by) * b - a + j, 0, dy - 1);
            const std::byte* row = src + std::size_t(y * dx) * vb;
            std::byte* dst = out + std::size_t(k * edge + j) * rowBytes;
            if (row == previousRow) { // a clamped row (or slice) repeats the one just cut
                std::memcpy(dst, previousDst, rowBytes);
                previousDst = dst;
                continue;
            }
            const std::int64_t before = inBegin - x0;
            fillVoxels(dst, row, std::size_t(before), vb);
            std::int64_t i = before;
            if (inEnd > inBegin) {
                std::memcpy(dst + i * vb, row + inBegin * vb, std::size_t(inEnd - inBegin) * vb);
                i += inEnd - inBegin;
            }
            fillVoxels(dst + i * vb, row + (dx - 1) * vb, std::size_t(edge - i), vb);
            previousRow = row;
            previousDst = dst;
        }
    }
}

} // namespace bc::brickstore::detail
