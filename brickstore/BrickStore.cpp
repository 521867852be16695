#include "brickstore/BrickStore.h"

#include "brickstore/Error.h"
#include "brickstore/detail/BrickSummary.h"
#include "brickstore/detail/StoreFormat.h"
#include "brickstore/detail/StoreReadFile.h"

#include <algorithm>
#include <atomic>
#include <mutex>
#include <thread>
#include <zstd.h>

namespace bc::brickstore {
namespace {

using detail::kHeaderBytes;

struct DCtxDeleter {
    void operator()(ZSTD_DCtx* c) const { ZSTD_freeDCtx(c); }
};

/// One decompression context per thread, reused (zstd's advice).
ZSTD_DCtx* threadDCtx() {
    thread_local std::unique_ptr<ZSTD_DCtx, DCtxDeleter> ctx(ZSTD_createDCtx());
    return ctx.get();
}

/// Compressed bytes of one frame or leaf table, read into a buffer kept per thread (its
/// size is bounded by the index checks: a frame is at most ZSTD_compressBound of a brick).
std::span<std::byte> threadBuffer(std::size_t bytes) {
    thread_local std::vector<std::byte> buffer;
    if (buffer.size() < bytes) buffer.resize(bytes);
    return {buffer.data(), bytes};
}

void checkIndexPlacement(const detail::StoreHeader& h, std::uint64_t fileBytes,
                         const std::string& path) {
    if (h.fileBytes != fileBytes)
        throw StoreCorrupt(path + ": truncated or extended: header says " +
                           std::to_string(h.fileBytes) + " bytes, file has " +
                           std::to_string(fileBytes));
    std::uint64_t minIndex = detail::indexBytesFor(h.levelCount, h.brickCount, h.histogramBins, 0);
    if (h.indexOffset < kHeaderBytes || h.indexOffset > fileBytes ||
        h.indexBytes != fileBytes - h.indexOffset || h.indexBytes < minIndex ||
        h.indexBytes > minIndex + detail::kMaxDescriptionBytes)
        throw StoreCorrupt(path + ": index offset/size out of range");
}

/// Stored bricks lie in [header, index) and do not overlap one another.
void checkPayloadPlacement(const std::vector<BrickRecord>& records, const StoreLayout& layout,
                           const detail::StoreHeader& h, const std::string& path) {
    struct Extent {
        std::uint64_t begin, end, index;
    };
    std::vector<Extent> extents;
    std::uint64_t storedBytes = 0;
    for (std::uint64_t i = 0; i < records.size(); ++i) {
        const auto& r = records[i];
        if (!r.stored()) continue;
        std::uint64_t end = r.offset + r.compressedBytes + r.leafBytes;
        if (r.offset < kHeaderBytes || end < r.offset || end > h.indexOffset)
            throw StoreCorrupt(path + ": brick " + layout.keyOf(i).toString() +
                               ": payload outside the payload region");
        extents.push_back({r.offset, end, i});
        storedBytes += end - r.offset;
    }
    std::sort(extents.begin(), extents.end(),
              [](const Extent& a, const Extent& b) { return a.begin < b.begin; });
    for (std::size_t i = 1; i < extents.size(); ++i)
        if (extents[i].begin < extents[i - 1].end)
            throw StoreCorrupt(path + ": brick " + layout.keyOf(extents[i].index).toString() +
                               " overlaps brick " + layout.keyOf(extents[i - 1].index).toString());
    if (extents.size() != h.storedBricks || storedBytes != h.storedBytes)
        throw StoreCorrupt(path + ": header's stored brick count or bytes disagree with the index");
}

} // namespace

BrickStore::~BrickStore() = default;

std::unique_ptr<BrickStore> BrickStore::open(const std::string& path) {
    static std::atomic<std::uint64_t> nextInstance{1};
    std::unique_ptr<BrickStore> s(new BrickStore());
    s->mPath = path;
    s->mInstance = nextInstance.fetch_add(1);
    s->mFile = std::make_unique<detail::StoreReadFile>(path);
    const std::uint64_t fileBytes = s->mFile->size();
    std::vector<std::byte> header(std::min<std::uint64_t>(fileBytes, kHeaderBytes));
    s->mFile->readAt(0, header);
    detail::StoreHeader h = detail::decodeHeader(header, path);
    checkIndexPlacement(h, fileBytes, path);
    try {
        validateVolumeInfo(h.volume, path);
        s->mLayout = std::make_unique<StoreLayout>(h.volume.dims, h.geometry);
    } catch (const std::exception& e) {
        throw StoreCorrupt(path + ": header: " + e.what());
    }
    if (s->mLayout->brickCount() != h.brickCount)
        throw StoreCorrupt(path + ": header: brick count does not match dims and brick size");
    // The index is parsed into memory once; later reads touch frames and leaf tables only.
    std::vector<std::byte> index(h.indexBytes); // within the file: checkIndexPlacement
    s->mFile->readAt(h.indexOffset, index);
    if (detail::checksum(std::span<const std::byte>(index)) != h.indexChecksum)
        throw StoreCorrupt(path + ": index checksum mismatch");
    detail::DecodedIndex decoded = detail::decodeIndex(index, h, *s->mLayout, path);
    checkPayloadPlacement(decoded.records, *s->mLayout, h, path);

    s->mRecords = std::move(decoded.records);
    for (std::uint64_t i = 0; const LevelLayout& level : s->mLayout->levels()) { // level-major
        std::uint64_t stored = 0;
        for (const std::uint64_t end = i + level.brickCount(); i < end; ++i)
            stored += s->mRecords[i].stored();
        s->mStoredPerLevel.push_back(stored);
    }
    s->mInfo.formatVersion = h.version;
    s->mInfo.volume = h.volume;
    s->mInfo.volume.description = decoded.description;
    s->mInfo.geometry = h.geometry;
    s->mInfo.valueMin = h.valueMin;
    s->mInfo.valueMax = h.valueMax;
    s->mInfo.fileBytes = h.fileBytes;
    s->mInfo.storedBricks = h.storedBricks;
    s->mInfo.storedBytes = h.storedBytes;
    s->mInfo.histogram = std::move(decoded.histogram);
    return s;
}

const BrickRecord& BrickStore::record(const BrickKey& key) const {
    return mRecords[mLayout->indexOf(key)];
}

std::uint64_t BrickStore::storedBricks(std::uint32_t level) const {
    return level < mStoredPerLevel.size() ? mStoredPerLevel[level] : 0;
}

std::optional<std::string> BrickStore::fileChange(bool changeTime) const {
    return mFile->changeAtPath(changeTime);
}

std::uint64_t BrickStore::brickBytes() const {
    return mLayout->storedVoxels() * voxelBytes(mInfo.volume.type);
}

void BrickStore::readBrick(const BrickKey& key, std::span<std::byte> out) const {
    const BrickRecord& r = record(key);
    if (out.size() != brickBytes())
        throw std::invalid_argument("readBrick: buffer of " + std::to_string(out.size()) +
                                    " bytes, brick needs " + std::to_string(brickBytes()));
    if (!r.stored()) {
        detail::fillConstant(mInfo.volume.type, r.range.min, out);
        return;
    }
    mFile->checkUnchanged(); // a store rewritten in place must not decode as another volume
    const auto frame = threadBuffer(r.compressedBytes);
    mFile->readAt(r.offset, frame);
    auto fail = [&](const std::string& why) {
        throw StoreCorrupt(mPath + ": brick " + key.toString() + ": " + why);
    };
    if (detail::checksum(std::span<const std::byte>(frame)) != r.payloadChecksum)
        fail("payload checksum mismatch");
    std::size_t n =
        ZSTD_decompressDCtx(threadDCtx(), out.data(), out.size(), frame.data(), frame.size());
    if (ZSTD_isError(n)) fail(std::string("cannot decompress: ") + ZSTD_getErrorName(n));
    if (n != out.size())
        fail("decompressed to " + std::to_string(n) + " bytes, expected " +
             std::to_string(out.size()));
}

std::vector<ValueRange> BrickStore::leafRanges(const BrickKey& key) const {
    const BrickRecord& r = record(key);
    if (!r.stored()) return std::vector<ValueRange>(mLayout->leafCount(), r.range);
    mFile->checkUnchanged();
    const auto table = threadBuffer(r.leafBytes);
    mFile->readAt(r.offset + r.compressedBytes, table);
    if (detail::checksum(std::span<const std::byte>(table)) != r.leafChecksum)
        throw StoreCorrupt(mPath + ": brick " + key.toString() + ": leaf table checksum mismatch");
    auto leaves = detail::decodeLeafTable(std::span<const std::byte>(table));
    if (mInfo.formatVersion < 2) return leaves;
    return detail::expandLeafTable(leaves, mLayout->leavesPerAxis(), mLayout->leavesInside(key));
}

std::vector<std::string> BrickStore::verify(unsigned threads) const {
    if (threads == 0) threads = std::max(1u, std::thread::hardware_concurrency());
    std::atomic<std::uint64_t> next{0};
    std::mutex mutex;
    std::vector<std::pair<std::uint64_t, std::string>> faults;
    auto worker = [&] {
        std::vector<std::byte> buffer(brickBytes());
        for (std::uint64_t i = next++; i < mRecords.size(); i = next++) {
            if (!mRecords[i].stored()) continue; // nothing on disk to check
            BrickKey key = mLayout->keyOf(i);
            try {
                readBrick(key, buffer);
                auto leaves = leafRanges(key);
                auto range = detail::brickRange(mInfo.volume.type, buffer);
                // What the table must read as: version 1 stored every leaf.
                const std::uint32_t n = mLayout->leavesPerAxis();
                const auto inside = mInfo.formatVersion >= 2
                                        ? mLayout->leavesInside(key)
                                        : std::array<std::uint32_t, 3>{n, n, n};
                auto expect = detail::expandLeafTable(
                    detail::leafRanges(mInfo.volume.type, buffer, mInfo.geometry, inside), n,
                    inside);
                bool leavesOk =
                    std::equal(leaves.begin(), leaves.end(), expect.begin(), expect.end(),
                               [](const ValueRange& a, const ValueRange& b) {
                                   return a.min == b.min && a.max == b.max;
                               });
                if (range.min != mRecords[i].range.min || range.max != mRecords[i].range.max)
                    throw StoreCorrupt(mPath + ": brick " + key.toString() +
                                       ": value range differs from the index");
                if (!leavesOk)
                    throw StoreCorrupt(mPath + ": brick " + key.toString() +
                                       ": leaf ranges differ from the voxels");
            } catch (const StoreCorrupt& e) {
                std::lock_guard lock(mutex);
                faults.emplace_back(i, e.what());
            }
        }
    };
    std::vector<std::jthread> pool;
    for (unsigned t = 0; t < threads; ++t)
        pool.emplace_back(worker);
    pool.clear();
    std::sort(faults.begin(), faults.end());
    std::vector<std::string> out;
    for (auto& f : faults)
        out.push_back(std::move(f.second));
    return out;
}

} // namespace bc::brickstore
