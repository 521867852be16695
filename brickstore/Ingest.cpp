#include "brickstore/Ingest.h"

#include "brickstore/Error.h"
#include "brickstore/detail/BrickSummary.h"
#include "brickstore/detail/LevelBuilder.h"
#include "brickstore/detail/StoreFile.h"
#include "brickstore/detail/StoreFormat.h"

#include <algorithm>
#include <array>
#include <chrono>
#include <cmath>
#include <condition_variable>
#include <cstring>
#include <deque>
#include <exception>
#include <limits>
#include <mutex>
#include <optional>
#include <thread>
#include <zstd.h>

#include <sys/resource.h>
#include <unistd.h>

namespace bc::brickstore {
namespace {

using Clock = std::chrono::steady_clock;

std::uint64_t nsSince(Clock::time_point t) {
    return std::uint64_t(
        std::chrono::duration_cast<std::chrono::nanoseconds>(Clock::now() - t).count());
}

struct CCtxDeleter {
    void operator()(ZSTD_CCtx* c) const { ZSTD_freeCCtx(c); }
};

std::size_t zstdCheck(std::size_t code, const char* what) {
    if (ZSTD_isError(code))
        throw StoreIoError(std::string("zstd ") + what + ": " + ZSTD_getErrorName(code));
    return code;
}

/// The bricks of finished rows, from the reading thread to the compression workers. Jobs are
/// indices (a worker cuts its brick from the level's ring), so the queue holds a row or two's
/// worth of them at most: the rings bound how far the reading thread runs ahead.
class JobQueue {
  public:
    /// Returns false if the queue was aborted.
    bool push(detail::BrickJob&& job) {
        std::lock_guard lock(mMutex);
        if (mClosed) return false;
        mJobs.push_back(job);
        mNotEmpty.notify_one();
        return true;
    }
    std::optional<detail::BrickJob> pop() {
        std::unique_lock lock(mMutex);
        mNotEmpty.wait(lock, [&] { return !mJobs.empty() || mClosed || mDone; });
        if (mClosed || mJobs.empty()) return std::nullopt;
        detail::BrickJob job = mJobs.front();
        mJobs.pop_front();
        return job;
    }
    /// No more jobs will come; workers drain what is queued.
    void finish() {
        std::lock_guard lock(mMutex);
        mDone = true;
        mNotEmpty.notify_all();
    }
    /// Stop now (an error): pending jobs are dropped.
    void abort() {
        std::lock_guard lock(mMutex);
        mClosed = true;
        mJobs.clear();
        mNotEmpty.notify_all();
    }

  private:
    std::mutex mMutex;
    std::condition_variable mNotEmpty;
    std::deque<detail::BrickJob> mJobs;
    bool mDone = false, mClosed = false;
};

/// Everything the workers share while an ingest runs.
struct IngestState {
    IngestState(const StoreLayout& layout_, VoxelType type_, int zstdLevel_,
                detail::StoreFile& file_)
        : layout(layout_), type(type_), zstdLevel(zstdLevel_), file(file_) {}

    const StoreLayout& layout;
    VoxelType type;
    int zstdLevel;
    detail::StoreFile& file;
    std::vector<BrickRecord> records;
    /// Per worker: level-0 voxels counted per raw value as they are compressed (8- and
    /// 16-bit integer types; empty otherwise), binned once the value range is known.
    std::vector<std::vector<std::uint64_t>> valueCounts;
    /// Every level's builder: a failed worker aborts them, releasing a waiting reader.
    std::vector<detail::LevelBuilder*> levels;
    std::atomic<std::uint64_t> bricksDone{0};
    std::atomic<std::uint64_t> uncompressedBytes{0};
    std::atomic<std::uint64_t> brickCutNs{0}, compressNs{0}, writeNs{0};
    std::uint64_t readNs = 0, cutNs = 0; ///< the reading thread's
    std::mutex errorMutex;
    std::exception_ptr error;

    void fail(std::exception_ptr e) {
        {
            std::lock_guard lock(errorMutex);
            if (!error) error = e;
        }
        for (detail::LevelBuilder* level : levels)
            level->abort();
    }
};

/// Counts a level-0 brick's own voxels (its payload, no apron) per value.
void countBrick(IngestState& s, const detail::BrickJob& job, std::span<const std::byte> voxels,
                bool constant, std::vector<std::uint64_t>& counts) {
    if (counts.empty() || job.index >= s.layout.levels()[0].brickCount()) return;
    const auto extent = s.layout.payloadExtent(s.layout.keyOf(job.index));
    if (constant) {
        std::uint16_t raw = 0; // the value's bits, read as unsigned (little-endian host)
        std::memcpy(&raw, voxels.data(), voxelBytes(s.type));
        counts[raw] += extent[0] * extent[1] * extent[2];
        return;
    }
    const std::uint32_t a = s.layout.geometry().apronVoxels;
    detail::countValues(s.type, voxels, s.layout.storedEdge(), {a, a, a}, extent, counts);
}

/// Compresses `job`'s brick, cut into `voxels`, and appends it to the store file.
void compressBrick(IngestState& s, ZSTD_CCtx* cctx, const detail::BrickJob& job,
                   std::span<const std::byte> voxels, std::vector<std::byte>& buf,
                   std::vector<std::uint64_t>& counts) {
    const auto start = Clock::now();
    BrickRecord& rec = s.records[job.index];
    const std::size_t vb = voxelBytes(s.type);
    if (detail::isConstant(voxels, vb)) {
        rec.range = detail::brickRange(s.type, voxels.first(vb));
        countBrick(s, job, voxels, true, counts);
        s.compressNs += nsSince(start);
        return;
    }
    countBrick(s, job, voxels, false, counts);
    // Only the leaves inside the volume are kept (FORMAT.md "Leaf table"). Their windows
    // still reach every value of the stored brick (what lies past the volume's far border is
    // clamped copies of the voxels at it): the brick's range is theirs; verify checks it.
    auto leafRanges = detail::leafRanges(s.type, voxels, s.layout.geometry(),
                                         s.layout.leavesInside(s.layout.keyOf(job.index)));
    rec.range = leafRanges.front();
    for (const auto& r : leafRanges) {
        rec.range.min = std::min(rec.range.min, r.min);
        rec.range.max = std::max(rec.range.max, r.max);
    }
    auto leaves = detail::encodeLeafTable(leafRanges);
    buf.resize(ZSTD_compressBound(voxels.size()) + leaves.size());
    std::size_t n = zstdCheck(
        ZSTD_compress2(cctx, buf.data(), buf.size() - leaves.size(), voxels.data(), voxels.size()),
        "compress");
    std::copy(leaves.begin(), leaves.end(), buf.begin() + std::ptrdiff_t(n));
    rec.flags = kBrickStored;
    rec.compressedBytes = static_cast<std::uint32_t>(n);
    rec.leafBytes = static_cast<std::uint32_t>(leaves.size());
    rec.payloadChecksum = detail::checksum(buf.data(), n);
    rec.leafChecksum = detail::checksum(leaves);
    const auto writeStart = Clock::now();
    s.compressNs += std::uint64_t(
        std::chrono::duration_cast<std::chrono::nanoseconds>(writeStart - start).count());
    rec.offset = s.file.append(std::span(buf).first(n + leaves.size()));
    s.writeNs += nsSince(writeStart);
    s.uncompressedBytes += voxels.size();
}

void workerLoop(IngestState& s, JobQueue& queue, std::vector<std::uint64_t>& counts) {
    std::unique_ptr<ZSTD_CCtx, CCtxDeleter> cctx(ZSTD_createCCtx());
    std::vector<std::byte> buf;
    std::vector<std::byte> voxels(s.layout.storedVoxels() * voxelBytes(s.type));
    try {
        zstdCheck(ZSTD_CCtx_setParameter(cctx.get(), ZSTD_c_compressionLevel, s.zstdLevel),
                  "level");
        zstdCheck(ZSTD_CCtx_setParameter(cctx.get(), ZSTD_c_checksumFlag, 1), "checksum flag");
        while (auto job = queue.pop()) {
            const auto cutStart = Clock::now();
            job->level->cut(*job, voxels.data());
            s.brickCutNs += nsSince(cutStart);
            compressBrick(s, cctx.get(), *job, voxels, buf, counts);
            ++s.bricksDone;
        }
    } catch (...) {
        s.fail(std::current_exception());
        queue.abort();
    }
}

/// Level-0 histogram over [lo, hi]: from the workers' counts per value where they kept them,
/// else by reading every stored brick back and decompressing it.
std::vector<std::uint64_t> buildHistogram(IngestState& s, std::uint32_t bins, double lo, double hi,
                                          unsigned threads) {
    if (detail::countsValues(s.type)) {
        const detail::HistogramBinner binner(s.type, lo, hi, bins);
        std::vector<std::uint64_t> total(bins);
        for (const auto& counts : s.valueCounts)
            binner.addValueCounts(counts, total);
        return total;
    }
    const auto& level0 = s.layout.levels()[0];
    const std::uint32_t a = s.layout.geometry().apronVoxels, edge = s.layout.storedEdge();
    std::vector<std::vector<std::uint64_t>> partial(threads, std::vector<std::uint64_t>(bins));
    std::atomic<std::uint64_t> next{0};
    const detail::HistogramBinner binner(s.type, lo, hi, bins);
    auto worker = [&](unsigned t) {
        std::unique_ptr<ZSTD_DCtx, decltype(&ZSTD_freeDCtx)> dctx(ZSTD_createDCtx(), ZSTD_freeDCtx);
        std::vector<std::byte> frame, voxels(s.layout.storedVoxels() * voxelBytes(s.type));
        for (std::uint64_t i = next++; i < level0.brickCount(); i = next++) {
            const BrickRecord& r = s.records[i];
            auto extent = s.layout.payloadExtent(s.layout.keyOf(i));
            if (!r.stored()) {
                partial[t][detail::histogramBin(r.range.min, lo, hi, bins)] +=
                    extent[0] * extent[1] * extent[2];
                continue;
            }
            frame.resize(r.compressedBytes);
            s.file.readAt(r.offset, frame);
            zstdCheck(ZSTD_decompressDCtx(dctx.get(), voxels.data(), voxels.size(), frame.data(),
                                          frame.size()),
                      "decompress for histogram");
            binner.add(voxels, edge, {a, a, a}, extent, partial[t]);
        }
    };
    {
        std::vector<std::jthread> pool;
        for (unsigned t = 0; t < threads; ++t)
            pool.emplace_back(worker, t);
    }
    std::vector<std::uint64_t> total(bins);
    for (const auto& p : partial)
        for (std::uint32_t b = 0; b < bins; ++b)
            total[b] += p[b];
    return total;
}

/// Bytes of source slices read at a time (at least one slice).
constexpr std::uint64_t kStagingBytes = 8ull << 20;

/// Slices per staging slab.
std::uint64_t stagingSlices(const VolumeInfo& info) {
    const std::uint64_t chunk = std::max<std::uint64_t>(1, kStagingBytes / info.sliceBytes());
    return std::min(chunk, info.dims[2]);
}

void throwIfCancelled(const IngestConfig& config) {
    if (config.cancel && config.cancel->load())
        throw IngestCancelled("ingest cancelled; the partial store was removed");
}

/// The source's slices read in staging slabs, in order, on a thread of its own, one slab ahead
/// of the consumer: a reader that waits on the disk or on its sandboxed parser (TIFF, HDF5,
/// DICOM, OpenVDB) then waits beside the cutting instead of before it. Two slabs: the one
/// handed out and the one being read.
class SlabReader {
  public:
    SlabReader(VolumeSource& source, std::uint64_t slabSlices)
        : mSource(source), mSlabSlices(slabSlices), mSliceBytes(source.info().sliceBytes()) {
        for (auto& slab : mSlabs)
            slab.resize(slabSlices * mSliceBytes);
        mThread = std::jthread([this] { run(); });
    }
    ~SlabReader() {
        {
            std::lock_guard lock(mMutex);
            mStopping = true;
        }
        mChanged.notify_all();
        // The jthread joins here, after the read in progress (which cannot be interrupted).
    }
    SlabReader(const SlabReader&) = delete;
    SlabReader& operator=(const SlabReader&) = delete;

    /// Slab `handedOut()`'s slices (the slab before it goes back to the reader); rethrows
    /// the reader's error (the source's FormatError).
    std::span<const std::byte> next() {
        std::unique_lock lock(mMutex);
        if (mHandedOut > 0) { // the consumer is done with the last slab
            ++mFreed;
            mChanged.notify_all();
        }
        mChanged.wait(lock, [&] { return mRead > mHandedOut || mError; });
        if (mError && mRead == mHandedOut) std::rethrow_exception(mError);
        const std::uint64_t k = mHandedOut++;
        const std::uint64_t z = k * mSlabSlices;
        const std::uint64_t n = std::min(mSlabSlices, mSource.info().dims[2] - z);
        return std::span(mSlabs[k % 2]).first(n * mSliceBytes);
    }

  private:
    void run() {
        const std::uint64_t depth = mSource.info().dims[2];
        for (std::uint64_t k = 0, z = 0; z < depth; ++k, z += mSlabSlices) {
            {
                std::unique_lock lock(mMutex);
                // Slab k reuses the buffer of slab k - 2: wait until it is handed back.
                mChanged.wait(lock, [&] { return mStopping || k < mFreed + 2; });
                if (mStopping) return;
            }
            const std::uint64_t n = std::min(mSlabSlices, depth - z);
            try {
                mSource.readSlices(n, std::span(mSlabs[k % 2]).first(n * mSliceBytes));
            } catch (...) {
                std::lock_guard lock(mMutex);
                mError = std::current_exception();
                mChanged.notify_all();
                return;
            }
            std::lock_guard lock(mMutex);
            ++mRead;
            mChanged.notify_all();
        }
    }

    VolumeSource& mSource;
    const std::uint64_t mSlabSlices, mSliceBytes;
    std::array<std::vector<std::byte>, 2> mSlabs;
    std::mutex mMutex;
    std::condition_variable mChanged;
    std::uint64_t mRead = 0, mHandedOut = 0, mFreed = 0; ///< slabs
    bool mStopping = false;
    std::exception_ptr mError;
    std::jthread mThread; ///< last: it starts once the rest is built and joins first
};

/// Reads every slice of the source into the level chain (SlabReader), reporting progress.
void streamSlices(VolumeSource& source, detail::LevelBuilder& level0, IngestState& s,
                  const IngestConfig& config,
                  const std::function<void(const IngestProgress&)>& progress,
                  Clock::time_point start) {
    const VolumeInfo& info = source.info();
    const std::uint64_t sliceBytes = info.sliceBytes();
    SlabReader reader(source, stagingSlices(info));
    for (std::uint64_t z = 0; z < info.dims[2];) {
        throwIfCancelled(config);
        const auto readStart = Clock::now();
        const std::span<const std::byte> slab = reader.next(); // the reader's FormatError
        const auto cutStart = Clock::now();
        s.readNs += std::uint64_t(
            std::chrono::duration_cast<std::chrono::nanoseconds>(cutStart - readStart).count());
        const std::uint64_t n = slab.size() / sliceBytes;
        for (std::uint64_t i = 0; i < n; ++i)
            level0.pushSlice(slab.data() + i * sliceBytes);
        s.cutNs += nsSince(cutStart); // the rings' waits included: ingest() takes them out
        z += n;
        {
            std::lock_guard lock(s.errorMutex);
            if (s.error) return;
        }
        if (progress) {
            IngestProgress p;
            p.bricksDone = s.bricksDone;
            p.bricksTotal = s.layout.brickCount();
            p.sourceBytesRead = z * sliceBytes;
            p.sourceBytesTotal = info.dims[2] * sliceBytes;
            p.seconds = std::chrono::duration<double>(Clock::now() - start).count();
            progress(p);
        }
    }
}

struct MemoryPlan {
    std::uint64_t bytes = 0, budget = 0;
    bool pipelined = true; ///< rings of LevelBuilder::pipelinedExtra() more than B + 2A slices
};

/// The rings pipelined when that fits the memory budget, else the least; refuses an ingest
/// whose buffers would exceed the budget either way, before any is allocated.
MemoryPlan planMemory(const VolumeInfo& info, const IngestConfig& config,
                      const std::string& inputName) {
    const std::uint64_t budget =
        config.memoryBudgetBytes ? config.memoryBudgetBytes : defaultIngestMemoryBudgetBytes();
    const std::uint64_t pipelined = ingestMemoryBytes(info, config, true);
    if (pipelined <= budget) return {pipelined, budget, true};
    const std::uint64_t need = ingestMemoryBytes(info, config, false);
    if (need <= budget) return {need, budget, false};
    throw FormatError(inputName, "dims",
                      dimsText(info.dims) + " " + std::string(voxelTypeName(info.type)) +
                          " needs " + bytesText(double(need)) +
                          " of slab buffers and bricks in flight, over the ingest memory budget "
                          "of " +
                          bytesText(double(budget)) + " (--memory-budget-mb)");
}

} // namespace

std::uint64_t defaultIngestMemoryBudgetBytes() {
    const long pages = ::sysconf(_SC_PHYS_PAGES), pageBytes = ::sysconf(_SC_PAGESIZE);
    std::uint64_t budget = pages > 0 && pageBytes > 0
                               ? std::uint64_t(pages) * std::uint64_t(pageBytes) / 2
                               : std::uint64_t(4) << 30;
    rlimit limit{};
    if (::getrlimit(RLIMIT_AS, &limit) == 0 && limit.rlim_cur != RLIM_INFINITY)
        budget = std::min<std::uint64_t>(budget, limit.rlim_cur / 2);
    return std::max<std::uint64_t>(budget, std::uint64_t(64) << 20);
}

std::uint64_t ingestMemoryBytes(const VolumeInfo& info, const IngestConfig& config,
                                bool pipelined) {
    const StoreLayout layout(info.dims, config.geometry);
    const double vb = double(voxelBytes(info.type));
    const double slice = double(info.dims[0]) * double(info.dims[1]) * vb;
    // Slab rings of every level (B + 2A slices and the pipelined extra, or the level's depth), the
    // half-resolution slice each feeds the next, the two staging slabs (one cut while the next is
    // read), and one slice for the reader's own decoding (DICOM, mosaic).
    double slabs = 2.0 * double(stagingSlices(info)) * slice + slice;
    const auto& levels = layout.levels();
    for (std::size_t l = 0; l < levels.size(); ++l) {
        const double dx = double(levels[l].dims[0]), dy = double(levels[l].dims[1]);
        const std::uint64_t extra =
            pipelined ? detail::LevelBuilder::pipelinedExtra(layout, std::uint32_t(l)) : 0;
        slabs += double(detail::LevelBuilder::ringSlices(layout, std::uint32_t(l), extra)) * dx *
                 dy * vb;
        if (l + 1 < levels.size()) slabs += std::ceil(dx / 2) * std::ceil(dy / 2) * vb;
    }
    // Per worker a brick cut from a ring and a compression buffer (the histogram pass of f32
    // holds a brick and a frame per worker, after them); the queued jobs are indices.
    const double threads =
        config.threads ? config.threads : std::max(1u, std::thread::hardware_concurrency());
    const double brick = double(layout.storedVoxels()) * vb;
    const double bricks = 2 * threads * brick;
    // The records and the index encoded from them; the workers' counts per value.
    const double index = 2.0 * double(layout.brickCount()) * double(sizeof(BrickRecord));
    const double counts = threads * double(detail::valueCountSize(info.type)) * 8.0;
    const double total = slabs + bricks + index + counts;
    return total >= 1.8e19 ? std::numeric_limits<std::uint64_t>::max() : std::uint64_t(total);
}

IngestReport ingest(VolumeSource& source, const std::string& storePath, const IngestConfig& config,
                    const std::function<void(const IngestProgress&)>& progress) {
    const auto start = Clock::now();
    const VolumeInfo& info = source.info();
    const std::string inputName = !config.inputName.empty()  ? config.inputName
                                  : info.description.empty() ? storePath
                                                             : info.description;
    validateVolumeInfo(info, inputName);
    StoreLayout layout(info.dims, config.geometry); // throws std::invalid_argument
    const MemoryPlan memory = planMemory(info, config, inputName);
    const std::uint32_t bins =
        std::clamp<std::uint32_t>(config.histogramBins, 1, detail::kMaxHistogramBins);
    const unsigned threads =
        config.threads ? config.threads : std::max(1u, std::thread::hardware_concurrency());

    detail::StoreFile file(storePath);
    if (config.staleFileRemoved)
        for (const std::string& stale : file.removedStalePartials())
            config.staleFileRemoved(stale);
    IngestState s{layout, info.type, config.zstdLevel, file};
    s.records.resize(layout.brickCount());
    s.valueCounts.assign(threads, std::vector<std::uint64_t>(detail::valueCountSize(info.type)));
    JobQueue queue;

    // One builder per level, each feeding the next; jobs go to the shared queue.
    const auto nLevels = static_cast<std::uint32_t>(layout.levels().size());
    std::vector<std::unique_ptr<detail::LevelBuilder>> levels(nLevels);
    auto sink = [&](detail::BrickJob&& job) {
        throwIfCancelled(config); // between bricks too: a row of wide bricks takes a while
        queue.push(std::move(job));
    };
    for (std::uint32_t l = nLevels; l-- > 0;)
        levels[l] = std::make_unique<detail::LevelBuilder>(
            layout, l, info.type, sink, l + 1 < nLevels ? levels[l + 1].get() : nullptr,
            memory.pipelined ? detail::LevelBuilder::pipelinedExtra(layout, l) : 0);
    for (const auto& level : levels)
        s.levels.push_back(level.get());
    {
        std::vector<std::jthread> workers;
        for (unsigned t = 0; t < threads; ++t)
            workers.emplace_back([&, t] { workerLoop(s, queue, s.valueCounts[t]); });
        try {
            streamSlices(source, *levels[0], s, config, progress, start);
            queue.finish();
        } catch (...) {
            s.fail(std::current_exception());
            queue.abort();
        }
    }
    if (s.error) std::rethrow_exception(s.error);

    IngestReport report;
    double lo = s.records[0].range.min, hi = s.records[0].range.max;
    for (std::uint64_t i = 0; i < layout.levels()[0].brickCount(); ++i) {
        lo = std::min<double>(lo, s.records[i].range.min);
        hi = std::max<double>(hi, s.records[i].range.max);
    }
    throwIfCancelled(config);
    const auto histogramStart = Clock::now();
    auto histogram = buildHistogram(s, bins, lo, hi, threads);
    report.times.histogram = std::chrono::duration<double>(Clock::now() - histogramStart).count();
    throwIfCancelled(config);
    const auto finishStart = Clock::now();

    detail::StoreHeader h;
    h.volume = info;
    h.geometry = config.geometry;
    h.levelCount = nLevels;
    h.histogramBins = bins;
    h.valueMin = lo;
    h.valueMax = hi;
    h.brickCount = layout.brickCount();
    for (const auto& r : s.records) {
        if (!r.stored()) continue;
        ++h.storedBricks;
        h.storedBytes += r.compressedBytes + r.leafBytes;
        report.leafTableBytes += r.leafBytes;
    }
    auto index = detail::encodeIndex(layout, s.records, histogram, info.description);
    h.indexOffset = file.end();
    h.indexBytes = index.size();
    h.indexChecksum = detail::checksum(index);
    h.fileBytes = h.indexOffset + h.indexBytes;
    file.writeAt(h.indexOffset, index);
    file.writeAt(0, detail::encodeHeader(h));
    file.commit();

    const std::uint64_t brickBytes = layout.storedVoxels() * voxelBytes(info.type);
    report.sourceBytes = info.voxelCount() * voxelBytes(info.type);
    report.bricks = layout.brickCount();
    report.storedBricks = h.storedBricks;
    report.constantBricks = report.bricks - report.storedBricks;
    report.storedBytes = h.storedBytes;
    report.uncompressedBrickBytes = s.uncompressedBytes;
    report.constantBrickBytes = report.constantBricks * brickBytes;
    report.fileBytes = h.fileBytes;
    report.memoryBytes = memory.bytes;
    report.memoryBudgetBytes = memory.budget;
    report.seconds = std::chrono::duration<double>(Clock::now() - start).count();
    report.times.finish = std::chrono::duration<double>(Clock::now() - finishStart).count();
    report.times.read = 1e-9 * double(s.readNs);
    for (const auto& level : levels)
        report.times.ringWait += level->waitedSeconds();
    report.times.cut = std::max(0.0, 1e-9 * double(s.cutNs) - report.times.ringWait);
    report.times.brickCut = 1e-9 * double(s.brickCutNs.load());
    report.times.compress = 1e-9 * double(s.compressNs.load());
    report.times.write = 1e-9 * double(s.writeNs.load());
    return report;
}

} // namespace bc::brickstore
