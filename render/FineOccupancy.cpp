#include "render/FineOccupancy.h"

#include "render/Occupancy.h"
#include "render/TransferFunction.h"

#include <algorithm>
#include <bit>
#include <chrono>
#include <cmath>
#include <cstring>
#include <stdexcept>
#include <string>
#include <thread>

namespace bc::render {
namespace {

constexpr std::int64_t kUnbuilt = -1, kBuilding = -2;

/// Per building thread: the build's buffers, kept between bricks. Fresh ones per brick (a few
/// MB at 1-voxel cells) cost a page fault per page, more than the build itself.
struct BuildScratch {
    std::vector<float> minX, maxX, minY, maxY, mn, mx;
    std::vector<std::uint8_t> dist, padded;
    std::vector<std::uint32_t> words;
};

BuildScratch& scratch() {
    thread_local BuildScratch s;
    return s;
}

/// v + 1 for a distance, 255 staying 255 (far): min(v, 254) + 1.
inline std::uint8_t next(std::uint8_t v) {
    return std::uint8_t(std::min<std::uint8_t>(v, 254) + 1);
}

/// The chessboard (L-infinity) distance, in cells, from each cell of an n^3 grid (x fastest)
/// to the nearest cell holding 0, capped at 255 (cells outside the grid count as far): two
/// raster passes over the 13 neighbours before and after a cell, each one step away, which
/// is exact for this metric. On a grid padded with far cells, so that no neighbour needs a
/// bounds test; per row, the 12 neighbours in earlier rows and slices are taken for the whole
/// row at once (a loop the compiler vectorises), then the one before it in the row, in order.
void chessboardDistances(std::vector<std::uint8_t>& d, int n, std::vector<std::uint8_t>& g) {
    const std::size_t p = std::size_t(n) + 2, row = p, slice = p * p;
    g.assign(p * p * p, 255);
    auto at = [&](std::size_t x, std::size_t y, std::size_t z) { return (z * p + y) * p + x; };
    for (std::size_t z = 0; z < std::size_t(n); ++z)
        for (std::size_t y = 0; y < std::size_t(n); ++y)
            std::memcpy(&g[at(1, y + 1, z + 1)], &d[(z * std::size_t(n) + y) * std::size_t(n)],
                        std::size_t(n));
    std::vector<std::uint8_t> m(p);
    auto pass = [&](std::size_t z, std::size_t y, std::ptrdiff_t dir) {
        std::uint8_t* r = &g[at(0, y, z)];
        // Forward (dir 1): the slice before (9 cells) and the row before (3); backward: after.
        const std::ptrdiff_t dz = -dir * std::ptrdiff_t(slice), dy = -dir * std::ptrdiff_t(row);
        std::fill(m.begin(), m.end(), std::uint8_t(255));
        auto take = [&](std::ptrdiff_t offset) { // m = min(m, the row at offset), vectorised
            const std::uint8_t* q = r + offset;
            for (std::size_t x = 1; x <= std::size_t(n); ++x)
                m[x] = std::min(m[x], q[x]);
        };
        for (std::ptrdiff_t oy : {-std::ptrdiff_t(row), std::ptrdiff_t(0), std::ptrdiff_t(row)})
            for (std::ptrdiff_t ox = -1; ox <= 1; ++ox)
                take(dz + oy + ox);
        for (std::ptrdiff_t ox = -1; ox <= 1; ++ox)
            take(dy + ox);
        if (dir > 0) {
            for (std::size_t x = 1; x <= std::size_t(n); ++x)
                if (r[x] != 0) r[x] = std::min({r[x], next(m[x]), next(r[x - 1])});
        } else {
            for (std::size_t x = std::size_t(n); x >= 1; --x)
                if (r[x] != 0) r[x] = std::min({r[x], next(m[x]), next(r[x + 1])});
        }
    };
    for (std::size_t z = 1; z <= std::size_t(n); ++z)
        for (std::size_t y = 1; y <= std::size_t(n); ++y)
            pass(z, y, 1);
    for (std::size_t z = std::size_t(n); z >= 1; --z)
        for (std::size_t y = std::size_t(n); y >= 1; --y)
            pass(z, y, -1);
    for (std::size_t z = 0; z < std::size_t(n); ++z)
        for (std::size_t y = 0; y < std::size_t(n); ++y)
            std::memcpy(&d[(z * std::size_t(n) + y) * std::size_t(n)], &g[at(1, y + 1, z + 1)],
                        std::size_t(n));
}

} // namespace

FineOccupancy::FineOccupancy(const OccupancyTrees& trees, const TransferFunctionTable& table,
                             std::uint32_t cellVoxels, std::uint64_t budgetBytes)
    : mTrees(trees), mCell(cellVoxels) {
    const std::uint32_t leaf = trees.leafVoxels();
    if (!std::has_single_bit(leaf) || !std::has_single_bit(cellVoxels) || cellVoxels >= leaf)
        throw std::invalid_argument("fine occupancy cells of " + std::to_string(cellVoxels) +
                                    " voxels: a power of two below the leaf's " +
                                    std::to_string(leaf) + " is needed");
    mLevels = std::uint32_t(std::countr_zero(leaf / cellVoxels));
    // Cells sit on the sampler's voxel lattice, half a voxel off the leaves': one more than
    // the leaves hold, so that positions 0 .. leaves * leaf all have one.
    mCellsPerAxis = (trees.leavesPerAxis() << mLevels) + 1;
    const std::uint64_t cells = std::uint64_t(mCellsPerAxis) * mCellsPerAxis * mCellsPerAxis;
    mWordsPerBrick = std::uint32_t((cells + 3) / 4);
    mSlots = std::max<std::uint64_t>(2, budgetBytes / (4ull * mWordsPerBrick));
    mSlots = std::min<std::uint64_t>(mSlots, (std::uint64_t(1) << 31) / mWordsPerBrick);
    // Not zeroed: a slot's pages are touched only when a brick is given it. Slot 0 is all
    // zeros: "take every sample" (a brick without a map is never asked for it).
    mPool.reset(new std::uint32_t[mSlots * mWordsPerBrick]);
    std::fill_n(mPool.get(), mWordsPerBrick, 0u);
    mBricks = trees.sampledBoxes().size();
    mOffsets.reset(new std::atomic<std::int64_t>[std::max<std::uint64_t>(mBricks, 1)]);
    for (std::uint64_t b = 0; b < mBricks; ++b)
        mOffsets[b].store(kUnbuilt, std::memory_order_relaxed);
    mEntries = table.entries;
    mDomainMin = table.domainMin;
    mDomainMax = table.domainMax;
    mPrefix.assign(table.entries + 1, 0);
    for (std::uint32_t i = 0; i < table.entries; ++i)
        mPrefix[i + 1] = mPrefix[i] + (table.rgba[4 * std::size_t(i) + 3] > 0.0f ? 1 : 0);
}

FineOccupancy::~FineOccupancy() = default;

std::uint32_t FineOccupancy::offsetOf(std::uint64_t brick, const void* voxels,
                                      brickstore::VoxelType type, int brickVoxels,
                                      int apronVoxels) {
    if (brick >= mBricks) return 0;
    std::atomic<std::int64_t>& slot = mOffsets[brick];
    for (;;) {
        std::int64_t state = slot.load(std::memory_order_acquire);
        if (state >= 0) return std::uint32_t(state);
        if (state == kUnbuilt &&
            slot.compare_exchange_strong(state, kBuilding, std::memory_order_acquire))
            break;
        std::this_thread::yield(); // another thread builds it
    }
    const auto start = std::chrono::steady_clock::now();
    std::vector<std::uint32_t>& bits = scratch().words; // the map's bytes, 4 to a word
    bits.assign(mWordsPerBrick, 0u);
    bool keep = false;
    switch (type) {
    case brickstore::VoxelType::U8:
        keep = build(brick, static_cast<const std::uint8_t*>(voxels), brickVoxels, apronVoxels,
                     bits.data());
        break;
    case brickstore::VoxelType::U16:
        keep = build(brick, static_cast<const std::uint16_t*>(voxels), brickVoxels, apronVoxels,
                     bits.data());
        break;
    case brickstore::VoxelType::I16:
        keep = build(brick, static_cast<const std::int16_t*>(voxels), brickVoxels, apronVoxels,
                     bits.data());
        break;
    case brickstore::VoxelType::F32:
        keep =
            build(brick, static_cast<const float*>(voxels), brickVoxels, apronVoxels, bits.data());
        break;
    }
    std::int64_t offset = 0;
    if (keep) {
        const std::uint64_t s = mNextSlot.fetch_add(1, std::memory_order_relaxed);
        if (s < mSlots) {
            offset = std::int64_t(s * mWordsPerBrick);
            std::memcpy(mPool.get() + offset, bits.data(), bits.size() * sizeof(std::uint32_t));
            ++mKept;
        }
    }
    ++mBuilt;
    mBuildNs += std::uint64_t(std::chrono::duration_cast<std::chrono::nanoseconds>(
                                  std::chrono::steady_clock::now() - start)
                                  .count());
    slot.store(offset, std::memory_order_release);
    return std::uint32_t(offset);
}

template <class T>
bool FineOccupancy::build(std::uint64_t brick, const T* v, int brickVoxels, int apron,
                          std::uint32_t* bits) const {
    const std::uint32_t depth = mTrees.depth(), leaves = mTrees.leavesPerAxis();
    const int edge = brickVoxels + 2 * apron, s = int(mCell), n = int(mCellsPerAxis);
    // Cell c (per axis) holds the samples at brick-local p in [(c - 1) s + 1/2, c s + 1/2): at
    // stored texel q = p + apron - 1/2 in [(c - 1) s + apron, c s + apron), they read voxels
    // floor(q) and the next, so the cell's reads are voxels [(c - 1) s + apron, c s + apron]
    // (clamped, as fetch() clamps). A position rounded across the cell's face by an ulp reads
    // a voxel beyond them with a weight of about an ulp: its value stays within the table
    // entry of margin that the range test adds on each side.
    auto lo = [&](int c) { return std::clamp((c - 1) * s + apron, 0, edge - 1); };
    auto hi = [&](int c) { return std::clamp(c * s + apron, 0, edge - 1); };
    // Min and max over each cell's reads, one axis at a time.
    const std::size_t e = std::size_t(edge), nc = std::size_t(n);
    BuildScratch& b = scratch();
    std::vector<float>&minX = b.minX, &maxX = b.maxX, &minY = b.minY, &maxY = b.maxY;
    std::vector<float>&mn = b.mn, &mx = b.mx;
    minX.resize(e * e * nc); // every element is written before it is read
    maxX.resize(e * e * nc);
    for (std::size_t row = 0; row < e * e; ++row) {
        const T* r = v + row * e;
        for (int c = 0; c < n; ++c) {
            float mn = float(r[lo(c)]), mx = mn;
            for (int x = lo(c) + 1; x <= hi(c); ++x) {
                mn = std::min(mn, float(r[x]));
                mx = std::max(mx, float(r[x]));
            }
            minX[row * nc + std::size_t(c)] = mn;
            maxX[row * nc + std::size_t(c)] = mx;
        }
    }
    minY.resize(e * nc * nc);
    maxY.resize(e * nc * nc);
    for (std::size_t z = 0; z < e; ++z)
        for (int c = 0; c < n; ++c) {
            float* mn = &minY[(z * nc + std::size_t(c)) * nc];
            float* mx = &maxY[(z * nc + std::size_t(c)) * nc];
            std::copy_n(&minX[(z * e + std::size_t(lo(c))) * nc], nc, mn);
            std::copy_n(&maxX[(z * e + std::size_t(lo(c))) * nc], nc, mx);
            for (int y = lo(c) + 1; y <= hi(c); ++y)
                for (std::size_t x = 0; x < nc; ++x) {
                    mn[x] = std::min(mn[x], minX[(z * e + std::size_t(y)) * nc + x]);
                    mx[x] = std::max(mx[x], maxX[(z * e + std::size_t(y)) * nc + x]);
                }
        }
    mn.resize(nc * nc);
    mx.resize(nc * nc);
    const std::uint32_t leaf = mTrees.leafVoxels();
    // The leaf of a cell's centre, for the share of empty cells among those the octree samples.
    auto leafOf = [&](int c) {
        const int centre = (2 * c - 1) * s + 1; // twice the centre, (c - 1/2) s + 1/2
        return std::uint32_t(std::clamp(centre / int(2 * leaf), 0, int(leaves) - 1));
    };
    // Per cell: 0 where a sample must be taken, else (below) its distance to the nearest such.
    std::vector<std::uint8_t>& dist = b.dist;
    dist.resize(nc * nc * nc); // every cell is written below
    std::uint64_t sampledCells = 0, emptyCells = 0;
    for (int cz = 0; cz < n; ++cz) {
        for (std::size_t i = 0; i < nc * nc; ++i) {
            mn[i] = minY[std::size_t(lo(cz)) * nc * nc + i];
            mx[i] = maxY[std::size_t(lo(cz)) * nc * nc + i];
        }
        for (int z = lo(cz) + 1; z <= hi(cz); ++z)
            for (std::size_t i = 0; i < nc * nc; ++i) {
                mn[i] = std::min(mn[i], minY[std::size_t(z) * nc * nc + i]);
                mx[i] = std::max(mx[i], maxY[std::size_t(z) * nc * nc + i]);
            }
        for (int cy = 0; cy < n; ++cy)
            for (int cx = 0; cx < n; ++cx) {
                const std::size_t i = std::size_t(cy) * nc + std::size_t(cx);
                const auto [e0, e1] = entrySpan(mn[i], mx[i], mDomainMin, mDomainMax, mEntries);
                const bool take = mPrefix[e1 + 1] != mPrefix[e0];
                dist[(std::size_t(cz) * nc + std::size_t(cy)) * nc + std::size_t(cx)] =
                    take ? 0 : 255;
                if (!mTrees.occupied(brick, depth, {leafOf(cx), leafOf(cy), leafOf(cz)})) continue;
                ++sampledCells;
                emptyCells += take ? 0 : 1;
            }
    }
    if (sampledCells == 0 || double(emptyCells) < kMinEmptyShare * double(sampledCells))
        return false;
    chessboardDistances(dist, n, b.padded);
    std::memcpy(bits, dist.data(), dist.size());
    return true;
}

std::int64_t FineOccupancy::builtOffset(std::uint64_t brick) const {
    if (brick >= mBricks) return 0;
    const std::int64_t state = mOffsets[brick].load(std::memory_order_acquire);
    return state >= 0 ? state : -1;
}

FineOccupancyStats FineOccupancy::stats() const {
    FineOccupancyStats s;
    s.bricksBuilt = mBuilt.load();
    s.bricksKept = mKept.load();
    s.bytes = std::min(mNextSlot.load(), mSlots) * mWordsPerBrick * 4ull;
    s.buildMs = double(mBuildNs.load()) * 1e-6;
    return s;
}

std::uint64_t FineOccupancy::bytes() const {
    return stats().bytes + mBricks * sizeof(std::atomic<std::int64_t>) +
           mPrefix.size() * sizeof(std::uint32_t) + sizeof(*this);
}

} // namespace bc::render
