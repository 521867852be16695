#include "render/BrickPool.h"

#include "render/Error.h"
#include "render/detail/Gl.h"

#include <algorithm>
#include <chrono>
#include <cmath>
#include <cstring>
#include <string>

namespace bc::render {
namespace {

constexpr std::uint64_t kNoKey = ~0ull;

struct TexFormat {
    GLenum internal, format, type;
};

TexFormat texFormat(brickstore::VoxelType t) {
    switch (t) {
    case brickstore::VoxelType::U8:
        return {GL_R8, GL_RED, GL_UNSIGNED_BYTE};
    case brickstore::VoxelType::U16:
        return {GL_R16, GL_RED, GL_UNSIGNED_SHORT};
    case brickstore::VoxelType::I16:
        return {GL_R16, GL_RED, GL_UNSIGNED_SHORT}; // uploaded biased by 32768
    case brickstore::VoxelType::F32:
        return {GL_R32F, GL_RED, GL_FLOAT};
    }
    throw RenderError("unknown voxel type");
}

} // namespace

std::array<std::uint32_t, 3> BrickPool::slotGridFor(std::uint64_t n, std::uint64_t perAxis) {
    // The most slots, at most n, in a grid of at most perAxis a side; of equal counts the one
    // with the shortest longest side. For each depth the rest is a near-square layer.
    std::array<std::uint64_t, 3> best{1, 1, 1};
    auto longest = [](const std::array<std::uint64_t, 3>& g) {
        return std::max({g[0], g[1], g[2]});
    };
    for (std::uint64_t nz = 1; nz <= std::min(perAxis, n); ++nz) {
        const std::uint64_t layer = n / nz;
        const std::uint64_t nx = std::min<std::uint64_t>(
            perAxis, std::max<std::uint64_t>(1, std::uint64_t(std::sqrt(double(layer)))));
        const std::uint64_t ny =
            std::min<std::uint64_t>(perAxis, std::max<std::uint64_t>(1, layer / nx));
        const std::array<std::uint64_t, 3> g{nx, ny, nz};
        const std::uint64_t count = nx * ny * nz, bestCount = best[0] * best[1] * best[2];
        if (count > bestCount || (count == bestCount && longest(g) < longest(best))) best = g;
    }
    return {std::uint32_t(best[0]), std::uint32_t(best[1]), std::uint32_t(best[2])};
}

struct BrickPool::Gpu {
    gl::Texture texture;
};

BrickPool::BrickPool(brickstore::VoxelType type, std::uint32_t edge, const BrickPoolConfig& config)
    : mGpu(std::make_unique<Gpu>()), mType(type), mEdge(edge) {
    GLint max3d = 0;
    glGetIntegerv(GL_MAX_3D_TEXTURE_SIZE, &max3d);
    const std::uint64_t perAxis = edge ? std::uint64_t(max3d) / edge : 0;
    const std::uint64_t wanted = config.budgetBytes / slotBytes();
    if (perAxis == 0 || wanted == 0)
        throw RenderError("GPU budget " + std::to_string(config.budgetBytes >> 20) +
                          " MiB holds no brick slot of " + std::to_string(edge) +
                          "^3 voxels (max 3D texture " + std::to_string(max3d) + ")");
    mSlotGrid = slotGridFor(std::min(wanted, perAxis * perAxis * perAxis), perAxis);
    mCapacity = mSlotGrid[0] * mSlotGrid[1] * mSlotGrid[2];

    const TexFormat f = texFormat(type);
    mGpu->texture = gl::createTexture(GL_TEXTURE_3D);
    const GLuint t = mGpu->texture.get();
    const auto size = textureSize();
    glTextureStorage3D(t, 1, f.internal, GLsizei(size[0]), GLsizei(size[1]), GLsizei(size[2]));
    glTextureParameteri(t, GL_TEXTURE_MIN_FILTER, GL_LINEAR);
    glTextureParameteri(t, GL_TEXTURE_MAG_FILTER, GL_LINEAR);
    for (GLenum w : {GL_TEXTURE_WRAP_S, GL_TEXTURE_WRAP_T, GL_TEXTURE_WRAP_R})
        glTextureParameteri(t, w, GL_CLAMP_TO_EDGE);
    gl::glCheck("allocating the GPU brick pool");

    mKeyOf.assign(mCapacity, kNoKey);
    mPinned.assign(mCapacity, 0);
    mLruPos.resize(mCapacity);
    for (std::uint32_t s = mCapacity; s-- > 0;)
        mFree.push_back(s);
}

BrickPool::~BrickPool() = default;

std::array<std::uint32_t, 3> BrickPool::textureSize() const {
    return {mSlotGrid[0] * mEdge, mSlotGrid[1] * mEdge, mSlotGrid[2] * mEdge};
}

std::uint64_t BrickPool::bytesFor(std::uint64_t bricks, brickstore::VoxelType type,
                                  std::uint32_t edge, std::uint64_t budgetBytes) {
    const std::uint64_t slot = std::uint64_t(edge) * edge * edge * brickstore::voxelBytes(type);
    return std::min(budgetBytes, std::max<std::uint64_t>(bricks, 1) * slot);
}

std::uint64_t BrickPool::slotBytes() const {
    return std::uint64_t(mEdge) * mEdge * mEdge * brickstore::voxelBytes(mType);
}

TexelMapping BrickPool::texelMapping() const {
    switch (mType) {
    case brickstore::VoxelType::U8:
        return {255.0, 0.0};
    case brickstore::VoxelType::U16:
        return {65535.0, 0.0};
    case brickstore::VoxelType::I16:
        return {65535.0, -32768.0};
    case brickstore::VoxelType::F32:
        return {1.0, 0.0};
    }
    return {};
}

unsigned BrickPool::texture() const {
    return mGpu->texture.get();
}

std::optional<std::uint32_t> BrickPool::acquire(std::uint64_t key, const Loader& load) {
    if (auto it = mSlotOf.find(key); it != mSlotOf.end()) {
        const std::uint32_t s = it->second;
        if (!mPinned[s]) {
            mLru.erase(mLruPos[s]);
            mPinned[s] = 1;
        }
        ++mStats.hits;
        return s;
    }
    std::uint32_t slot;
    if (!mFree.empty()) {
        slot = mFree.back();
    } else if (!mLru.empty()) {
        slot = mLru.front();
    } else {
        return std::nullopt;
    }
    const auto voxels = load(); // may throw: nothing has changed yet
    if (mFree.empty()) {
        mLru.pop_front();
        mSlotOf.erase(mKeyOf[slot]);
        mEvicted.insert(mKeyOf[slot]);
        ++mStats.evictions;
    } else {
        mFree.pop_back();
    }
    mKeyOf[slot] = kNoKey;
    upload(slot, voxels);
    if (mEvicted.erase(key) != 0) {
        ++mStats.refetches;
        mStats.bytesRefetched += voxels.size();
    }
    mKeyOf[slot] = key;
    mSlotOf[key] = slot;
    mPinned[slot] = 1;
    return slot;
}

void BrickPool::upload(std::uint32_t slot, std::span<const std::byte> voxels) {
    if (voxels.size() != slotBytes())
        throw RenderError("brick of " + std::to_string(voxels.size()) +
                          " bytes does not fit a slot of " + std::to_string(slotBytes()));
    const auto start = std::chrono::steady_clock::now();
    const void* data = voxels.data();
    if (mType == brickstore::VoxelType::I16) {
        mStaging.resize(voxels.size() / 2);
        std::memcpy(mStaging.data(), voxels.data(), voxels.size());
        for (auto& v : mStaging)
            v ^= 0x8000u; // two's complement -> offset binary
        data = mStaging.data();
    }
    const std::uint32_t sx = slot % mSlotGrid[0], sy = (slot / mSlotGrid[0]) % mSlotGrid[1],
                        sz = slot / (mSlotGrid[0] * mSlotGrid[1]);
    const TexFormat f = texFormat(mType);
    glPixelStorei(GL_UNPACK_ALIGNMENT, 1);
    glTextureSubImage3D(mGpu->texture.get(), 0, GLint(sx * mEdge), GLint(sy * mEdge),
                        GLint(sz * mEdge), GLsizei(mEdge), GLsizei(mEdge), GLsizei(mEdge), f.format,
                        f.type, data);
    gl::glCheck("uploading a brick");
    mStats.uploadMs +=
        std::chrono::duration<double, std::milli>(std::chrono::steady_clock::now() - start).count();
    ++mStats.uploads;
    mStats.bytesUploaded += voxels.size();
}

void BrickPool::unpinAll() {
    for (std::uint32_t s = 0; s < mCapacity; ++s) {
        if (!mPinned[s]) continue;
        mPinned[s] = 0;
        if (mKeyOf[s] != kNoKey) mLruPos[s] = mLru.insert(mLru.end(), s);
    }
}

void BrickPool::clear() {
    mSlotOf.clear();
    mEvicted.clear();
    mLru.clear();
    mFree.clear();
    mKeyOf.assign(mCapacity, kNoKey);
    mPinned.assign(mCapacity, 0);
    for (std::uint32_t s = mCapacity; s-- > 0;)
        mFree.push_back(s);
}

} // namespace bc::render
