#pragma once
// Ingest: one pass over a VolumeSource, cutting each pyramid level into overlapped bricks,
// summarising them, compressing them on parallel workers and writing a store that is either
// whole or absent (temporary name, fsync, rename).
#include "brickstore/StoreLayout.h"
#include "brickstore/VolumeSource.h"

#include <cstdint>
#include <functional>
#include <string>

namespace bc::brickstore {

struct IngestConfig {
    BrickGeometry geometry;
    unsigned threads = 0; ///< compression workers; 0 = hardware concurrency
    int zstdLevel = 3;
    std::uint32_t histogramBins = 256;
    std::uint32_t queueBricks = 0; ///< bricks in flight; 0 = 4 per worker
};

struct IngestProgress {
    std::uint64_t bricksDone = 0;
    std::uint64_t bricksTotal = 0;
    std::uint64_t sourceBytesRead = 0;
    std::uint64_t sourceBytesTotal = 0;
    double seconds = 0.0;
};

struct IngestReport {
    std::uint64_t sourceBytes = 0; ///< level-0 voxels in native type
    std::uint64_t bricks = 0;      ///< all levels
    std::uint64_t storedBricks = 0;
    std::uint64_t constantBricks = 0;         ///< not stored: every voxel (apron too) one value
    std::uint64_t storedBytes = 0;            ///< compressed payloads plus leaf tables
    std::uint64_t uncompressedBrickBytes = 0; ///< stored bricks before compression
    std::uint64_t constantBrickBytes = 0;     ///< bytes the constant bricks would have taken
    std::uint64_t fileBytes = 0;
    double seconds = 0.0;
};

/// Ingests `source` into a new store at `storePath`. An existing file there is replaced only
/// when the new store is complete; on any failure it is left untouched and no partial store
/// remains. `progress` (may be empty) is called from the ingesting thread.
/// @throw FormatError from the source, StoreIoError on write failures.
IngestReport ingest(VolumeSource& source, const std::string& storePath, const IngestConfig& config,
                    const std::function<void(const IngestProgress&)>& progress = {});

} // namespace bc::brickstore
