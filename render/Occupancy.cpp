#include "render/Occupancy.h"

#include "brickstore/BrickStore.h"
#include "brickstore/Error.h"
#include "render/TransferFunction.h"

#include <tbb/blocked_range.h>
#include <tbb/parallel_for.h>

#include <algorithm>
#include <bit>
#include <chrono>
#include <cmath>
#include <limits>
#include <stdexcept>

namespace bc::render {
namespace {

/// First bit of octree level l (>= 1) in a brick's words.
constexpr std::uint64_t bitOffset(std::uint32_t l) {
    return ((std::uint64_t(1) << (3 * l)) - 8) / 7;
}

std::uint64_t nodeIndex(const std::array<std::uint32_t, 3>& p, std::uint32_t perAxis) {
    return (std::uint64_t(p[2]) * perAxis + p[1]) * perAxis + p[0];
}

} // namespace

void OccupancyConfig::validate() const {
    if (!(ratioThreshold >= 0.0 && ratioThreshold <= 1.0))
        throw std::invalid_argument("octree ratio threshold must lie in [0, 1], got " +
                                    std::to_string(ratioThreshold));
}

OccupancyTrees::OccupancyTrees(const brickstore::BrickStore& store, std::uint32_t level)
    : mLevel(level) {
    const auto& layout = store.layout();
    const auto& l = layout.levels().at(level);
    mLeaves = layout.leavesPerAxis();
    mLeafVoxels = layout.geometry().leafVoxels;
    mDepth = std::uint32_t(std::bit_width(std::bit_ceil(mLeaves)) - 1);
    mWordsPerBrick = std::uint32_t((bitOffset(mDepth + 1) + 31) / 32);
    mBricks = l.brickCount();
    const std::uint64_t leafCount = layout.leafCount();
    mStored.assign(mBricks, 0);
    mBrickRange.resize(mBricks);
    mLeafRange.resize(mBricks * leafCount);
    mLeafFull.assign(mBricks * leafCount, 0);
    for (std::uint64_t b = 0; b < mBricks; ++b) {
        const brickstore::BrickKey key = layout.keyOf(l.firstBrick + b);
        const auto& record = store.record(key);
        mBrickRange[b] = {record.range.min, record.range.max};
        if (!record.stored()) continue;
        mStored[b] = 1;
        try {
            const auto leaves = store.leafRanges(key);
            for (std::uint64_t i = 0; i < leafCount; ++i)
                mLeafRange[b * leafCount + i] = {leaves[i].min, leaves[i].max};
        } catch (const brickstore::StoreCorrupt& e) {
            mFaults.push_back(e.what());
            std::fill_n(mLeafFull.begin() + std::ptrdiff_t(b * leafCount), leafCount, 1);
        }
    }
    mLeafUpper.resize(mLeafRange.size());
    mLeafLower.resize(mLeafRange.size());
    for (std::uint64_t b = 0; b < mBricks; ++b)
        for (std::uint64_t i = b * leafCount; i < (b + 1) * leafCount; ++i) {
            const auto& r = mStored[b] ? mLeafRange[i] : mBrickRange[b];
            const bool bounded = mLeafFull[i] == 0;
            constexpr float kInf = std::numeric_limits<float>::infinity();
            mLeafUpper[i] = bounded ? interpolatedUpper(r[0], r[1]) : kInf;
            mLeafLower[i] = bounded ? interpolatedLower(r[0], r[1]) : -kInf;
        }
    mNonEmpty.assign(mBricks * leafCount, 1);
    mRoot.assign(mBricks, 1);
    mWhole.assign(mBricks, 1);
    mWords.assign(mBricks * mWordsPerBrick, ~0u);
    mBoxes.assign(mBricks, SampledBox{{0, 0, 0}, {mLeaves - 1, mLeaves - 1, mLeaves - 1}});
}

std::uint64_t OccupancyTrees::bytes() const {
    auto of = [](const auto& v) { return std::uint64_t(v.capacity() * sizeof(v[0])); };
    std::uint64_t n = of(mStored) + of(mBrickRange) + of(mLeafRange) + of(mLeafUpper) +
                      of(mLeafLower) + of(mLeafEntries) + of(mLeafFull) + of(mNonEmpty) +
                      of(mRoot) + of(mWhole) + of(mWords) + of(mBoxes) + of(mChanged) +
                      of(mVisible);
    for (const auto& f : mFaults)
        n += f.capacity();
    return n + sizeof(*this);
}

OccupancyRebuild OccupancyTrees::update(const TransferFunctionTable& table,
                                        const OccupancyConfig& config) {
    config.validate();
    const auto start = std::chrono::steady_clock::now();
    OccupancyRebuild result;
    std::vector<std::uint8_t> visible(table.entries);
    for (std::uint32_t i = 0; i < table.entries; ++i)
        visible[i] = table.rgba[4 * std::size_t(i) + 3] > 0.0f;
    const bool newDomain = !mBuilt || table.entries != mEntries || table.domainMin != mDomainMin ||
                           table.domainMax != mDomainMax;
    const bool full = newDomain || config != mConfig;
    if (newDomain) { // entry spans depend on the domain alone
        const std::uint64_t leafCount = std::uint64_t(mLeaves) * mLeaves * mLeaves;
        mLeafEntries.resize(mLeafRange.size());
        for (std::uint64_t b = 0; b < mBricks; ++b)
            for (std::uint64_t i = b * leafCount; mStored[b] && i < (b + 1) * leafCount; ++i)
                mLeafEntries[i] = entrySpan(mLeafRange[i][0], mLeafRange[i][1], table.domainMin,
                                            table.domainMax, table.entries);
    }
    // The entries whose emptiness changed, as one span [changedLo, changedHi].
    std::uint32_t changedLo = 0, changedHi = table.entries - 1;
    if (!full) {
        changedLo = table.entries;
        changedHi = 0;
        for (std::uint32_t i = 0; i < table.entries; ++i)
            if (visible[i] != mVisible[i]) {
                changedLo = std::min(changedLo, i);
                changedHi = i;
            }
    }
    mChanged.clear();
    for (std::uint64_t b = 0; b < mBricks; ++b) {
        if (!mStored[b]) continue;
        ++result.bricksStored;
        const auto span = entrySpan(mBrickRange[b][0], mBrickRange[b][1], table.domainMin,
                                    table.domainMax, table.entries);
        if (span[1] >= changedLo && span[0] <= changedHi) mChanged.push_back(b);
    }
    std::vector<std::uint32_t> prefix(table.entries + 1, 0);
    for (std::uint32_t i = 0; i < table.entries; ++i)
        prefix[i + 1] = prefix[i] + visible[i];
    mConfig = config;
    tbb::parallel_for(tbb::blocked_range<std::size_t>(0, mChanged.size(), 16),
                      [&](const tbb::blocked_range<std::size_t>& r) {
                          for (std::size_t i = r.begin(); i != r.end(); ++i)
                              rebuildBrick(mChanged[i], prefix);
                      });
    mVisible = std::move(visible);
    mEntries = table.entries;
    mDomainMin = table.domainMin;
    mDomainMax = table.domainMax;
    mBuilt = true;
    result.full = full;
    result.bricksRebuilt = mChanged.size();
    result.ms =
        std::chrono::duration<double, std::milli>(std::chrono::steady_clock::now() - start).count();
    return result;
}

void OccupancyTrees::rebuildBrick(std::uint64_t brick, const std::vector<std::uint32_t>& prefix) {
    const std::uint32_t n = mLeaves, side = 1u << mDepth;
    const std::uint64_t leafCount = std::uint64_t(n) * n * n;
    // Non-empty and real leaf counts per node, level by level (level mDepth: the leaves, padded
    // to a power-of-two grid).
    std::vector<std::vector<std::uint32_t>> nonEmpty(mDepth + 1), real(mDepth + 1);
    nonEmpty[mDepth].assign(std::size_t(side) * side * side, 0);
    real[mDepth].assign(std::size_t(side) * side * side, 0);
    for (std::uint32_t z = 0; z < n; ++z)
        for (std::uint32_t y = 0; y < n; ++y)
            for (std::uint32_t x = 0; x < n; ++x) {
                const std::uint64_t leaf = (std::uint64_t(z) * n + y) * n + x;
                const std::uint64_t at = brick * leafCount + leaf;
                const auto [i, j] = mLeafEntries[at];
                const bool ne = mLeafFull[at] || prefix[j + 1] != prefix[i];
                mNonEmpty[at] = ne;
                const std::uint64_t node = nodeIndex({x, y, z}, side);
                nonEmpty[mDepth][node] = ne;
                real[mDepth][node] = 1;
            }
    for (std::uint32_t l = mDepth; l-- > 0;) {
        const std::uint32_t s = 1u << l;
        nonEmpty[l].assign(std::size_t(s) * s * s, 0);
        real[l].assign(std::size_t(s) * s * s, 0);
        for (std::uint32_t z = 0; z < 2 * s; ++z)
            for (std::uint32_t y = 0; y < 2 * s; ++y)
                for (std::uint32_t x = 0; x < 2 * s; ++x) {
                    const auto child = nodeIndex({x, y, z}, 2 * s);
                    const auto parent = nodeIndex({x / 2, y / 2, z / 2}, s);
                    nonEmpty[l][parent] += nonEmpty[l + 1][child];
                    real[l][parent] += real[l + 1][child];
                }
    }
    // Top down: a node is sampled when its parent is drawn whole or it holds a non-empty leaf;
    // it is drawn whole at the level limit or when its ratio reaches the threshold.
    const std::uint32_t limit = std::min(mConfig.levelLimit, mDepth);
    auto drawnWhole = [&](std::uint32_t l, std::uint64_t node) {
        return nonEmpty[l][node] > 0 &&
               (l >= limit || double(nonEmpty[l][node]) >= mConfig.ratioThreshold * real[l][node]);
    };
    mRoot[brick] = nonEmpty[0][0] > 0;
    std::vector<std::uint8_t> whole{std::uint8_t(drawnWhole(0, 0))};
    mWhole[brick] = whole[0];
    std::uint32_t* words = &mWords[brick * mWordsPerBrick];
    std::fill_n(words, mWordsPerBrick, 0u);
    for (std::uint32_t l = 1; l <= mDepth; ++l) {
        const std::uint32_t s = 1u << l;
        std::vector<std::uint8_t> next(std::size_t(s) * s * s);
        for (std::uint32_t z = 0; z < s; ++z)
            for (std::uint32_t y = 0; y < s; ++y)
                for (std::uint32_t x = 0; x < s; ++x) {
                    const auto node = nodeIndex({x, y, z}, s);
                    const bool parentWhole = whole[nodeIndex({x / 2, y / 2, z / 2}, s / 2)];
                    const bool sampled = parentWhole || nonEmpty[l][node] > 0;
                    next[node] = parentWhole || drawnWhole(l, node);
                    if (sampled) {
                        const std::uint64_t bit = bitOffset(l) + node;
                        words[bit / 32] |= 1u << (bit % 32);
                    }
                }
        whole = std::move(next);
    }
    SampledBox box{{n, n, n}, {0, 0, 0}};
    if (mDepth == 0 && mRoot[brick]) box = {{0, 0, 0}, {n - 1, n - 1, n - 1}};
    for (std::uint32_t z = 0; mDepth > 0 && z < n; ++z)
        for (std::uint32_t y = 0; y < n; ++y)
            for (std::uint32_t x = 0; x < n; ++x) {
                const std::uint64_t bit = bitOffset(mDepth) + nodeIndex({x, y, z}, side);
                if (((words[bit / 32] >> (bit % 32)) & 1u) == 0u) continue;
                box.lo = {std::min(box.lo[0], x), std::min(box.lo[1], y), std::min(box.lo[2], z)};
                box.hi = {std::max(box.hi[0], x), std::max(box.hi[1], y), std::max(box.hi[2], z)};
            }
    mBoxes[brick] = box;
}

bool OccupancyTrees::leafNonEmpty(std::uint64_t brick, std::uint32_t leaf) const {
    return mStored[brick] &&
           mNonEmpty[brick * std::uint64_t(mLeaves) * mLeaves * mLeaves + leaf] != 0;
}

double OccupancyTrees::ratio(std::uint64_t brick, std::uint32_t octLevel,
                             const std::array<std::uint32_t, 3>& node) const {
    if (brick >= mBricks || octLevel > mDepth)
        throw std::out_of_range("octree node outside the level");
    const std::uint32_t span = 1u << (mDepth - octLevel);
    std::uint32_t count = 0, total = 0;
    for (std::uint32_t z = node[2] * span; z < std::min(mLeaves, (node[2] + 1) * span); ++z)
        for (std::uint32_t y = node[1] * span; y < std::min(mLeaves, (node[1] + 1) * span); ++y)
            for (std::uint32_t x = node[0] * span; x < std::min(mLeaves, (node[0] + 1) * span);
                 ++x) {
                ++total;
                count += !mStored[brick] || leafNonEmpty(brick, (z * mLeaves + y) * mLeaves + x);
            }
    return total ? double(count) / total : 0.0;
}

bool OccupancyTrees::occupied(std::uint64_t brick, std::uint32_t octLevel,
                              const std::array<std::uint32_t, 3>& node) const {
    if (brick >= mBricks || octLevel > mDepth)
        throw std::out_of_range("octree node outside the level");
    if (octLevel == 0) return mRoot[brick] != 0;
    const std::uint64_t bit = bitOffset(octLevel) + nodeIndex(node, 1u << octLevel);
    return (mWords[brick * mWordsPerBrick + bit / 32] >> (bit % 32)) & 1u;
}

} // namespace bc::render
