#pragma once
// Ingest: one pass over a VolumeSource, cutting each pyramid level into overlapped bricks,
// summarising them, compressing them on parallel workers and writing a store that is either
// whole or absent (temporary name, fsync, rename).
#include "brickstore/StoreLayout.h"
#include "brickstore/VolumeSource.h"

#include <atomic>
#include <cstdint>
#include <functional>
#include <stdexcept>
#include <string>

namespace bc::brickstore {

struct IngestConfig {
    BrickGeometry geometry;
    unsigned threads = 0; ///< compression workers; 0 = hardware concurrency
    int zstdLevel = 3;
    std::uint32_t histogramBins = 256;
    /// Most bytes ingest may allocate (slab buffers of every level, bricks in flight, the
    /// brick index); checked before anything is allocated. 0 = defaultIngestMemoryBudgetBytes().
    std::uint64_t memoryBudgetBytes = 0;
    /// Named in errors about the input (the path given on the command line); empty = the
    /// source's description.
    std::string inputName;
    /// Polled between slabs of slices and before the store is committed: once true, ingest
    /// stops, removes its partial file and throws IngestCancelled. May be set from a signal
    /// handler (lock-free). Null = never cancelled.
    const std::atomic<bool>* cancel = nullptr;
    /// Told each stale partial file (of an ingest killed earlier) that was removed. May be empty.
    std::function<void(const std::string&)> staleFileRemoved;
};

/// Thrown by ingest when IngestConfig::cancel was set; the partial file is already gone.
class IngestCancelled : public std::runtime_error {
  public:
    using std::runtime_error::runtime_error;
};

/// Half of physical memory, and at most half of the process's address-space limit
/// (RLIMIT_AS) where one is set; at least 64 MiB.
std::uint64_t defaultIngestMemoryBudgetBytes();

/// What an ingest of `info` with `config` will allocate at its peak, in bytes: the slab ring
/// of every pyramid level and its half-resolution slice, the staging slabs, the reader's
/// slice, the workers' bricks and compression buffers, and the brick index. `pipelined`: rings
/// of 2B + 2A slices at level 0 and 1.5B + 2A below, so that the reading thread fills a row
/// while the workers cut the last (what ingest uses when it fits the budget); else B + 2A (the
/// least it needs: the reader waits for each row to be cut). @throw std::invalid_argument on a
/// geometry outside the accepted ranges.
std::uint64_t ingestMemoryBytes(const VolumeInfo& info, const IngestConfig& config,
                                bool pipelined = true);

struct IngestProgress {
    std::uint64_t bricksDone = 0;
    std::uint64_t bricksTotal = 0;
    std::uint64_t sourceBytesRead = 0;
    std::uint64_t sourceBytesTotal = 0;
    double seconds = 0.0;
};

/// Where an ingest's time went. The reading thread's stages are wall seconds on that thread;
/// the workers' are seconds summed over the workers (they run side by side).
struct IngestTimes {
    double read = 0.0;      ///< waiting for the source's next slab (read on its own thread)
    double cut = 0.0;       ///< slices into the levels' rings, and the coarser levels' averaging
    double ringWait = 0.0;  ///< the reading thread waiting for workers to cut a ring slot free
    double brickCut = 0.0;  ///< workers: cutting bricks from the rings, summed
    double compress = 0.0;  ///< workers: leaf ranges, value counts and zstd, summed
    double write = 0.0;     ///< workers: appending frames to the store file, summed
    double histogram = 0.0; ///< the histogram pass over the stored bricks (wall)
    double finish = 0.0;    ///< the index, the header and the commit (wall)
};

struct IngestReport {
    std::uint64_t sourceBytes = 0; ///< level-0 voxels in native type
    std::uint64_t bricks = 0;      ///< all levels
    std::uint64_t storedBricks = 0;
    std::uint64_t constantBricks = 0;         ///< not stored: every voxel (apron too) one value
    std::uint64_t storedBytes = 0;            ///< compressed payloads plus leaf tables
    std::uint64_t leafTableBytes = 0;         ///< the leaf tables alone (thin volumes: most)
    std::uint64_t memoryBytes = 0;            ///< ingestMemoryBytes: the estimated peak
    std::uint64_t memoryBudgetBytes = 0;      ///< the budget it was checked against
    std::uint64_t uncompressedBrickBytes = 0; ///< stored bricks before compression
    std::uint64_t constantBrickBytes = 0;     ///< bytes the constant bricks would have taken
    std::uint64_t fileBytes = 0;
    double seconds = 0.0;
    IngestTimes times;
};

/// Ingests `source` into a new store at `storePath`. An existing file there is replaced only
/// when the new store is complete; on any failure it is left untouched and no partial store
/// remains. `progress` (may be empty) is called from the ingesting thread.
/// @throw FormatError from the source, or naming the input's dims when the ingest would need
/// more memory than config.memoryBudgetBytes; StoreIoError on write failures; IngestCancelled.
IngestReport ingest(VolumeSource& source, const std::string& storePath, const IngestConfig& config,
                    const std::function<void(const IngestProgress&)>& progress = {});

} // namespace bc::brickstore
