#pragma once
// One pyramid level of a store as a forward slice stream: the inverse of ingest. Used by
// `extract` and by tests that compare a store with its source voxel for voxel.
#include "brickstore/VolumeSource.h"

#include <memory>

namespace bc::brickstore {

class BrickStore;

/// Streams level `level` of `store` (which must outlive the stream); decompresses one row of
/// bricks at a time on `threads` workers (0 = all cores). Memory: B slices of the level.
/// @throw std::out_of_range for a level the store lacks; reads throw StoreCorrupt.
std::unique_ptr<VolumeSource> openStoreLevel(const BrickStore& store, std::uint32_t level,
                                             unsigned threads = 0);

} // namespace bc::brickstore
