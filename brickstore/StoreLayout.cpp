#include "brickstore/StoreLayout.h"

#include <algorithm>
#include <cstdio>
#include <stdexcept>

namespace bc::brickstore {

std::string BrickKey::toString() const {
    char text[64];
    std::snprintf(text, sizeof text, "L%u (%u,%u,%u)", level, pos[0], pos[1], pos[2]);
    return text;
}

StoreLayout::StoreLayout(const std::array<std::uint64_t, 3>& dims, const BrickGeometry& g)
    : mGeometry(g) {
    if (g.brickVoxels < kMinBrickVoxels || g.brickVoxels > kMaxBrickVoxels)
        throw std::invalid_argument("brick size must be in [" + std::to_string(kMinBrickVoxels) +
                                    ", " + std::to_string(kMaxBrickVoxels) + "]");
    if (g.apronVoxels > kMaxApronVoxels || g.apronVoxels >= g.brickVoxels)
        throw std::invalid_argument("apron must be at most " + std::to_string(kMaxApronVoxels) +
                                    " and smaller than the brick");
    if (g.leafVoxels == 0 || g.leafVoxels > g.brickVoxels)
        throw std::invalid_argument("leaf size must be in [1, brick size]");
    for (std::uint64_t d : dims)
        if (d == 0) throw std::invalid_argument("volume dims must be non-zero");

    std::array<std::uint64_t, 3> d = dims;
    for (;;) {
        LevelLayout level;
        level.dims = d;
        for (int a = 0; a < 3; ++a)
            level.bricks[a] =
                static_cast<std::uint32_t>((d[a] + g.brickVoxels - 1) / g.brickVoxels);
        level.firstBrick = mBrickCount;
        mBrickCount += level.brickCount();
        mLevels.push_back(level);
        bool fits = d[0] <= g.brickVoxels && d[1] <= g.brickVoxels && d[2] <= g.brickVoxels;
        if (fits || mLevels.size() == kMaxLevels) break;
        for (auto& v : d)
            v = (v + 1) / 2;
    }
}

std::uint32_t StoreLayout::leavesPerAxis() const {
    return (mGeometry.brickVoxels + mGeometry.leafVoxels - 1) / mGeometry.leafVoxels;
}

std::array<std::uint32_t, 3> StoreLayout::leavesInside(const BrickKey& key) const {
    const auto extent = payloadExtent(key);
    std::array<std::uint32_t, 3> n{};
    for (int a = 0; a < 3; ++a)
        n[a] = static_cast<std::uint32_t>((extent[a] + mGeometry.leafVoxels - 1) /
                                          mGeometry.leafVoxels);
    return n;
}

bool StoreLayout::contains(const BrickKey& key) const {
    if (key.level >= mLevels.size()) return false;
    const auto& l = mLevels[key.level];
    return key.pos[0] < l.bricks[0] && key.pos[1] < l.bricks[1] && key.pos[2] < l.bricks[2];
}

std::uint64_t StoreLayout::indexOf(const BrickKey& key) const {
    if (!contains(key)) throw std::out_of_range("no brick " + key.toString() + " in this store");
    const auto& l = mLevels[key.level];
    return l.firstBrick + (std::uint64_t(key.pos[2]) * l.bricks[1] + key.pos[1]) * l.bricks[0] +
           key.pos[0];
}

BrickKey StoreLayout::keyOf(std::uint64_t index) const {
    for (std::uint32_t li = 0; li < mLevels.size(); ++li) {
        const auto& l = mLevels[li];
        if (index >= l.firstBrick + l.brickCount()) continue;
        std::uint64_t i = index - l.firstBrick;
        BrickKey k;
        k.level = li;
        k.pos[0] = static_cast<std::uint32_t>(i % l.bricks[0]);
        k.pos[1] = static_cast<std::uint32_t>((i / l.bricks[0]) % l.bricks[1]);
        k.pos[2] = static_cast<std::uint32_t>(i / (std::uint64_t(l.bricks[0]) * l.bricks[1]));
        return k;
    }
    throw std::out_of_range("brick index " + std::to_string(index) + " beyond the store");
}

std::array<std::uint64_t, 3> StoreLayout::payloadOrigin(const BrickKey& key) const {
    std::array<std::uint64_t, 3> o{};
    for (int a = 0; a < 3; ++a)
        o[a] = std::uint64_t(key.pos[a]) * mGeometry.brickVoxels;
    return o;
}

std::array<std::uint64_t, 3> StoreLayout::payloadExtent(const BrickKey& key) const {
    const auto& l = mLevels.at(key.level);
    std::array<std::uint64_t, 3> e{};
    for (int a = 0; a < 3; ++a) {
        std::uint64_t o = std::uint64_t(key.pos[a]) * mGeometry.brickVoxels;
        e[a] = std::min<std::uint64_t>(mGeometry.brickVoxels, l.dims[a] - o);
    }
    return e;
}

} // namespace bc::brickstore
