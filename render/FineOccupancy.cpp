#include "render/FineOccupancy.h"

#include "render/Occupancy.h"
#include "render/RenderTypes.h"
#include "render/TransferFunction.h"

#include <algorithm>
#include <bit>
#include <chrono>
#include <cmath>
#include <cstring>
#include <stdexcept>
#include <string>
#include <thread>
#include <type_traits>

namespace bc::render {
namespace {

constexpr std::int64_t kUnbuilt = -1, kBuilding = -2;

/// Per building thread: the build's buffers, kept between bricks. Fresh ones per brick (a few
/// MB at 1-voxel cells) cost a page fault per page, more than the build itself. The value
/// ranges are kept in the voxels' own type (16 or 32 lanes a vector for integers).
template <class T> struct BuildScratch { std::vector<T> minX, maxX, minY, maxY, mn, mx; };

template <class T> BuildScratch<T>& scratch() {
    thread_local BuildScratch<T> s;
    return s;
}

/// The padded grid of distances (cellsPerAxis() + 2 a side) and the distance passes' rows.
struct GridScratch {
    std::vector<std::uint8_t> grid, rowMins;
};

GridScratch& gridScratch() {
    thread_local GridScratch s;
    return s;
}

/// v + 1 for a distance, 255 staying 255 (far): min(v, 254) + 1.
inline std::uint8_t next(std::uint8_t v) {
    return std::uint8_t(std::min<std::uint8_t>(v, 254) + 1);
}

/// The chessboard (L-infinity) distance, in cells, from each cell of an n^3 grid to the
/// nearest cell holding 0, capped at 255, in place on `g`: the grid padded by one far (255)
/// cell on every side, (n + 2)^3, x fastest. Two raster passes, each taking for a cell the
/// least of its 13 neighbours before it (after it, backwards) plus one, which is exact for this
/// metric. Per row, the 9 neighbours in the slice before and the 3 in the row before come
/// from the least of 3 along x of each of those 4 rows, kept per row once it is final (a loop
/// the compiler vectorises); the one before it in the row is taken in order. `rowMins` is
/// scratch.
void chessboardDistances(std::uint8_t* g, int n, std::vector<std::uint8_t>& rowMins) {
    const std::size_t N = std::size_t(n), p = N + 2, slice = p * p;
    rowMins.assign(2 * slice, 255);
    std::uint8_t* before = rowMins.data();  // 3-minima of the slice before, per row
    std::uint8_t* current = before + slice; // of this slice's rows done so far
    auto pass = [&](std::size_t z, std::ptrdiff_t dir) {
        // Rows of this slice in pass order; row 0 / n + 1 (padding) stays 255 in `current`.
        for (std::size_t i = 1; i <= N; ++i) {
            const std::size_t y = dir > 0 ? i : N + 1 - i;
            std::uint8_t* r = g + (z * p + y) * p;
            const std::uint8_t* b0 = before + (y - 1) * p;
            const std::uint8_t* b1 = before + y * p;
            const std::uint8_t* b2 = before + (y + 1) * p;
            const std::uint8_t* c = current + std::size_t(std::ptrdiff_t(y) - dir) * p;
            for (std::size_t x = 1; x <= N; ++x) {
                const std::uint8_t m = std::min({b0[x], b1[x], b2[x], c[x]});
                r[x] = std::min(r[x], next(m));
            }
            if (dir > 0) {
                for (std::size_t x = 1; x <= N; ++x)
                    r[x] = std::min(r[x], next(r[x - 1]));
            } else {
                for (std::size_t x = N; x >= 1; --x)
                    r[x] = std::min(r[x], next(r[x + 1]));
            }
            std::uint8_t* out = current + y * p;
            for (std::size_t x = 1; x <= N; ++x)
                out[x] = std::min({r[x - 1], r[x], r[x + 1]});
        }
        std::swap(before, current);
        std::fill_n(current, slice, std::uint8_t(255));
    };
    for (std::size_t z = 1; z <= N; ++z)
        pass(z, 1);
    std::fill_n(before, slice, std::uint8_t(255));
    for (std::size_t z = N; z >= 1; --z)
        pass(z, -1);
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

void FineOccupancy::prepareType(brickstore::VoxelType type) {
    std::call_once(mTypeOnce, [&] {
        mType = type;
        // Integer voxels: the range test per value, as prefix counts (takes()).
        std::int64_t first = 0, count = 0;
        switch (type) {
        case brickstore::VoxelType::U8:
            count = 256;
            break;
        case brickstore::VoxelType::U16:
            count = 65536;
            break;
        case brickstore::VoxelType::I16:
            first = -32768, count = 65536;
            break;
        case brickstore::VoxelType::F32:
            return;
        }
        mLowPrefix.resize(std::size_t(count));
        mHighPrefix.resize(std::size_t(count));
        for (std::int64_t i = 0; i < count; ++i) {
            const double v = double(first + i);
            const auto [e0, e1] = entrySpan(v, v, mDomainMin, mDomainMax, mEntries);
            mLowPrefix[std::size_t(i)] = mPrefix[e0];
            mHighPrefix[std::size_t(i)] = mPrefix[e1 + 1];
        }
    });
    if (type != mType)
        throw std::logic_error("fine occupancy: voxels of another type than the first brick's");
}

std::uint32_t FineOccupancy::offsetOf(std::uint64_t brick, const void* voxels,
                                      brickstore::VoxelType type, int brickVoxels,
                                      int apronVoxels) {
    if (brick >= mBricks) return 0;
    prepareType(type);
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
    const std::size_t n = mCellsPerAxis, p = n + 2;
    GridScratch& grid = gridScratch();
    // build() writes every cell: only the padding is set here.
    grid.grid.resize(p * p * p);
    std::uint8_t* g = grid.grid.data();
    std::fill_n(g, p * p, std::uint8_t(255));
    std::fill_n(g + (p - 1) * p * p, p * p, std::uint8_t(255));
    for (std::size_t z = 1; z + 1 < p; ++z) {
        std::fill_n(g + z * p * p, p, std::uint8_t(255));
        std::fill_n(g + (z * p + p - 1) * p, p, std::uint8_t(255));
        for (std::size_t y = 1; y + 1 < p; ++y)
            g[(z * p + y) * p] = g[(z * p + y) * p + p - 1] = 255;
    }
    bool keep = false;
    auto cells = [&](const auto* v) {
        switch (mCell) {
        case 1:
            keep = build<1>(brick, v, brickVoxels, apronVoxels, g);
            break;
        case 2:
            keep = build<2>(brick, v, brickVoxels, apronVoxels, g);
            break;
        default:
            keep = build<0>(brick, v, brickVoxels, apronVoxels, g);
            break;
        }
    };
    switch (type) {
    case brickstore::VoxelType::U8:
        cells(static_cast<const std::uint8_t*>(voxels));
        break;
    case brickstore::VoxelType::U16:
        cells(static_cast<const std::uint16_t*>(voxels));
        break;
    case brickstore::VoxelType::I16:
        cells(static_cast<const std::int16_t*>(voxels));
        break;
    case brickstore::VoxelType::F32:
        cells(static_cast<const float*>(voxels));
        break;
    }
    std::int64_t offset = 0;
    // The distances only for a map that gets a slot, written straight into it.
    const std::uint64_t s = keep ? mNextSlot.fetch_add(1, std::memory_order_relaxed) : mSlots;
    if (s < mSlots) {
        chessboardDistances(g, int(n), grid.rowMins);
        offset = std::int64_t(s * mWordsPerBrick);
        auto* map = reinterpret_cast<std::uint8_t*>(mPool.get() + offset);
        for (std::size_t z = 0; z < n; ++z)
            for (std::size_t y = 0; y < n; ++y)
                std::memcpy(map + (z * n + y) * n, g + ((z + 1) * p + y + 1) * p + 1, n);
        std::memset(map + n * n * n, 0, std::size_t(mWordsPerBrick) * 4 - n * n * n);
        ++mKept;
    }
    ++mBuilt;
    mBuildNs += std::uint64_t(std::chrono::duration_cast<std::chrono::nanoseconds>(
                                  std::chrono::steady_clock::now() - start)
                                  .count());
    slot.store(offset, std::memory_order_release);
    return std::uint32_t(offset);
}

template <int S, class T>
bool FineOccupancy::build(std::uint64_t brick, const T* v, int brickVoxels, int apron,
                          std::uint8_t* grid) const {
    const std::uint32_t depth = mTrees.depth(), leaves = mTrees.leavesPerAxis();
    const int edge = brickVoxels + 2 * apron, s = S > 0 ? S : int(mCell), n = int(mCellsPerAxis);
    // Cell c (per axis) holds the samples at brick-local p in [(c - 1) s + 1/2, c s + 1/2): at
    // stored texel q = p + apron - 1/2 in [(c - 1) s + apron, c s + apron), they read voxels
    // floor(q) and the next, so the cell's reads are voxels [(c - 1) s + apron, c s + apron]
    // (clamped, as fetch() clamps). A position rounded across the cell's face by an ulp reads
    // a voxel beyond them with a weight of about an ulp: its value stays within the table
    // entry of margin that the range test adds on each side.
    auto lo = [&](int c) { return std::clamp((c - 1) * s + apron, 0, edge - 1); };
    auto hi = [&](int c) { return std::clamp(c * s + apron, 0, edge - 1); };
    // Cells whose reads need no clamping: [c0, c1].
    const int c0 = std::min(n, std::max(0, (s - apron + s - 1) / s));
    const int c1 = std::max(c0 - 1, std::min(n - 1, (edge - 1 - apron) / s));
    // Min and max over each cell's reads, one axis at a time.
    const std::size_t e = std::size_t(edge), nc = std::size_t(n);
    BuildScratch<T>& b = scratch<T>();
    std::vector<T>&minX = b.minX, &maxX = b.maxX, &minY = b.minY, &maxY = b.maxY;
    std::vector<T>&mn = b.mn, &mx = b.mx;
    minX.resize(e * e * nc); // every element is written before it is read
    maxX.resize(e * e * nc);
    for (std::size_t row = 0; row < e * e; ++row) {
        const T* r = v + row * e;
        T* rMin = &minX[row * nc];
        T* rMax = &maxX[row * nc];
        auto clamped = [&](int c) {
            T lo0 = r[lo(c)], hi0 = lo0;
            for (int x = lo(c) + 1; x <= hi(c); ++x) {
                lo0 = std::min(lo0, r[x]);
                hi0 = std::max(hi0, r[x]);
            }
            rMin[c] = lo0;
            rMax[c] = hi0;
        };
        for (int c = 0; c < c0; ++c)
            clamped(c);
        if (S > 0) { // a fixed stride: the compiler vectorises it
            for (int c = c0; c <= c1; ++c) {
                const int first = (c - 1) * S + apron;
                T lo0 = r[first], hi0 = lo0;
                for (int k = 1; k <= S; ++k) {
                    lo0 = std::min(lo0, r[first + k]);
                    hi0 = std::max(hi0, r[first + k]);
                }
                rMin[c] = lo0;
                rMax[c] = hi0;
            }
        } else {
            for (int c = c0; c <= c1; ++c)
                clamped(c);
        }
        for (int c = c1 + 1; c < n; ++c)
            clamped(c);
    }
    minY.resize(e * nc * nc);
    maxY.resize(e * nc * nc);
    for (std::size_t z = 0; z < e; ++z)
        for (int c = 0; c < n; ++c) {
            T* mnY = &minY[(z * nc + std::size_t(c)) * nc];
            T* mxY = &maxY[(z * nc + std::size_t(c)) * nc];
            std::copy_n(&minX[(z * e + std::size_t(lo(c))) * nc], nc, mnY);
            std::copy_n(&maxX[(z * e + std::size_t(lo(c))) * nc], nc, mxY);
            for (int y = lo(c) + 1; y <= hi(c); ++y) {
                const T* a = &minX[(z * e + std::size_t(y)) * nc];
                const T* z1 = &maxX[(z * e + std::size_t(y)) * nc];
                for (std::size_t x = 0; x < nc; ++x) {
                    mnY[x] = std::min(mnY[x], a[x]);
                    mxY[x] = std::max(mxY[x], z1[x]);
                }
            }
        }
    mn.resize(nc * nc);
    mx.resize(nc * nc);
    // Which leaves the octree samples, and the leaf of each cell's centre along an axis: for
    // the share of empty cells among those it samples.
    const std::uint32_t leaf = mTrees.leafVoxels();
    std::vector<std::uint8_t> leafSet(std::size_t(leaves) * leaves * leaves);
    for (std::uint32_t lz = 0; lz < leaves; ++lz)
        for (std::uint32_t ly = 0; ly < leaves; ++ly)
            for (std::uint32_t lx = 0; lx < leaves; ++lx)
                leafSet[(std::size_t(lz) * leaves + ly) * leaves + lx] =
                    mTrees.occupied(brick, depth, {lx, ly, lz}) ? 1 : 0;
    std::vector<std::uint32_t> leafOf(nc);
    for (int c = 0; c < n; ++c) {
        const int centre = (2 * c - 1) * s + 1; // twice the centre, (c - 1/2) s + 1/2
        leafOf[std::size_t(c)] =
            std::uint32_t(std::clamp(centre / int(2 * leaf), 0, int(leaves) - 1));
    }
    const std::size_t p = nc + 2;
    std::uint64_t sampledCells = 0, emptyCells = 0;
    for (int cz = 0; cz < n; ++cz) {
        const T* zMin = &minY[std::size_t(lo(cz)) * nc * nc];
        const T* zMax = &maxY[std::size_t(lo(cz)) * nc * nc];
        std::copy_n(zMin, nc * nc, mn.data());
        std::copy_n(zMax, nc * nc, mx.data());
        for (int z = lo(cz) + 1; z <= hi(cz); ++z) {
            const T* a = &minY[std::size_t(z) * nc * nc];
            const T* z1 = &maxY[std::size_t(z) * nc * nc];
            for (std::size_t i = 0; i < nc * nc; ++i) {
                mn[i] = std::min(mn[i], a[i]);
                mx[i] = std::max(mx[i], z1[i]);
            }
        }
        const std::uint8_t* leafRows =
            &leafSet[std::size_t(leafOf[std::size_t(cz)]) * leaves * leaves];
        for (int cy = 0; cy < n; ++cy) {
            const std::uint8_t* leafRow = leafRows + std::size_t(leafOf[std::size_t(cy)]) * leaves;
            // 0 where a sample must be taken, else (the distances below) far.
            std::uint8_t* out = grid + ((std::size_t(cz) + 1) * p + std::size_t(cy) + 1) * p + 1;
            for (int cx = 0; cx < n; ++cx) {
                const std::size_t i = std::size_t(cy) * nc + std::size_t(cx);
                const bool take = takes(mn[i], mx[i]);
                out[cx] = take ? 0 : 255;
                if (!leafRow[leafOf[std::size_t(cx)]]) continue;
                ++sampledCells;
                emptyCells += take ? 0 : 1;
            }
        }
    }
    return sampledCells != 0 && double(emptyCells) >= kMinEmptyShare * double(sampledCells);
}

template <class T> bool FineOccupancy::takes(T lo, T hi) const {
    if constexpr (std::is_same_v<T, float>) {
        const auto [e0, e1] = entrySpan(lo, hi, mDomainMin, mDomainMax, mEntries);
        return mPrefix[e1 + 1] != mPrefix[e0];
    } else {
        constexpr std::int64_t first = std::is_same_v<T, std::int16_t> ? -32768 : 0;
        return mHighPrefix[std::size_t(std::int64_t(hi) - first)] !=
               mLowPrefix[std::size_t(std::int64_t(lo) - first)];
    }
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

void FineOccupancy::addFrameCost(const FineOccupancyStats& before, std::uint64_t withMaps,
                                 FrameStats& stats) const {
    const FineOccupancyStats after = this->stats();
    stats.cellBricksBuilt += after.bricksBuilt - before.bricksBuilt;
    stats.cellBuildMs += after.buildMs - before.buildMs;
    stats.cellBricks += withMaps;
}

std::uint64_t FineOccupancy::bytes() const {
    return stats().bytes + mBricks * sizeof(std::atomic<std::int64_t>) +
           mPrefix.size() * sizeof(std::uint32_t) + sizeof(*this);
}

} // namespace bc::render
