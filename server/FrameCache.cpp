#include "server/FrameCache.h"

#include "protocol/FrameCodec.h"
#include "protocol/Messages.h"
#include "render/Camera.h"
#include "render/TransferFunction.h"
#include "server/Catalog.h"

#include <bit>
#include <string_view>

namespace bc::server {

namespace {

/// Appends the bits of `v`, little-endian.
void appendBits(std::vector<std::uint8_t>& out, double v) {
    const auto bits = std::bit_cast<std::uint64_t>(v);
    for (int i = 0; i < 8; ++i)
        out.push_back(std::uint8_t(bits >> (8 * i)));
}

} // namespace

FrameKey frameKeyOf(std::uint64_t storeInstance, const std::string& renderer, bool refined,
                    bool shading, const render::Camera& camera,
                    const protocol::RenderOptions& options,
                    std::shared_ptr<const render::TransferFunction> tf,
                    const protocol::SetModeAndClip& modeAndClip) {
    FrameKey key;
    key.storeInstance = storeInstance;
    key.renderer = renderer;
    key.refined = refined;
    key.shading = shading;
    for (const glm::dvec3* v : {&camera.eye, &camera.target, &camera.up})
        for (int i = 0; i < 3; ++i)
            appendBits(key.request, (*v)[i]);
    appendBits(key.request, camera.fovYDeg);
    key.request.push_back(std::uint8_t(camera.orthographic));
    appendBits(key.request, camera.orthoHeight);
    protocol::SetRenderOptions message{options};
    // What they decide is in the key already: who draws it (key.renderer) and whether it is
    // refined (an adaptive session's frame at rest is a refined session's frame).
    message.options.renderer = protocol::Renderer::Auto;
    message.options.quality = protocol::Quality::Adaptive;
    protocol::encode(message, 0, key.request);
    protocol::encode(modeAndClip, 0, key.request);
    key.tf = std::move(tf);
    return key;
}

bool FrameKey::matches(const FrameKey& other) const {
    if (storeInstance != other.storeInstance || renderer != other.renderer ||
        refined != other.refined || shading != other.shading || request != other.request)
        return false;
    if (tf == other.tf) return true;
    return tf && other.tf && tf->sameFunction(*other.tf);
}

std::uint64_t FrameKey::hash() const {
    const std::string_view bytes(reinterpret_cast<const char*>(request.data()), request.size());
    std::uint64_t h = std::hash<std::string_view>{}(bytes);
    auto mix = [&h](std::uint64_t v) { h ^= v + 0x9e3779b97f4a7c15ull + (h << 6) + (h >> 2); };
    mix(storeInstance);
    mix(std::hash<std::string>{}(renderer));
    mix(std::uint64_t(refined) | std::uint64_t(shading) << 1);
    mix(tf ? tf->contentHash() : 0);
    return h;
}

protocol::Frame frameFrom(const CachedFrame& kept, protocol::FrameEncoder& encoder) {
    protocol::Frame frame;
    auto& h = frame.header;
    if (kept.pixels()) { // a delta against this session's own previous frame
        auto encoded =
            encoder.encode(kept.bytes, kept.width, kept.height, kept.codec, kept.quality);
        h.keyframe = encoded.keyframe;
        h.encodeMs = float(encoded.encodeMs);
        frame.image = std::move(encoded.bytes);
    } else {
        encoder.resetDelta(); // as encoding a frame of another codec does
        frame.image = kept.bytes;
    }
    h.width = kept.width;
    h.height = kept.height;
    h.codec = kept.codec;
    h.level = kept.level;
    h.cached = true;
    return frame;
}

struct FrameCache::Entry {
    FrameKey key;
    std::uint64_t hash = 0;
    std::shared_ptr<const CachedFrame> frame;
    std::weak_ptr<Volume> volume;
};

FrameCache::FrameCache(const FrameCacheConfig& config) : mConfig(config) {
    mStats.budgetBytes = config.budgetBytes;
}

FrameCache::~FrameCache() = default;

std::shared_ptr<const CachedFrame> FrameCache::find(const FrameKey& key) {
    if (!enabled()) return nullptr;
    const std::uint64_t h = key.hash();
    std::lock_guard lock(mMutex);
    const auto [first, last] = mByHash.equal_range(h);
    for (auto it = first; it != last; ++it) {
        const Entries::iterator e = it->second;
        if (!e->key.matches(key)) continue;
        mEntries.splice(mEntries.begin(), mEntries, e); // most recently used
        ++mStats.hits;
        return e->frame;
    }
    ++mStats.misses;
    return nullptr;
}

void FrameCache::insert(FrameKey key, CachedFrame frame, const std::shared_ptr<Volume>& volume) {
    if (!enabled()) return;
    const std::uint64_t bytes = frame.bytes.size();
    const std::uint64_t h = key.hash();
    std::lock_guard lock(mMutex);
    dropStale();
    if (bytes > mConfig.budgetBytes / 4) { // one frame must not flush every other
        ++mStats.tooLarge;
        return;
    }
    const auto [first, last] = mByHash.equal_range(h);
    for (auto it = first; it != last; ++it)
        if (it->second->key.matches(key)) { // drawn twice (two sessions asked at once): keep one
            erase(it->second);
            break;
        }
    mEntries.push_front(
        Entry{std::move(key), h, std::make_shared<const CachedFrame>(std::move(frame)), volume});
    mByHash.emplace(h, mEntries.begin());
    mStats.bytes += bytes;
    ++mStats.entries;
    ++mStats.insertions;
    while (mStats.bytes > mConfig.budgetBytes && !mEntries.empty()) {
        erase(std::prev(mEntries.end()));
        ++mStats.evictions;
    }
}

void FrameCache::erase(Entries::iterator e) {
    const auto [first, last] = mByHash.equal_range(e->hash);
    for (auto it = first; it != last; ++it)
        if (it->second == e) {
            mByHash.erase(it);
            break;
        }
    mStats.bytes -= e->frame->bytes.size();
    --mStats.entries;
    mEntries.erase(e);
}

void FrameCache::dropStale() {
    for (auto it = mEntries.begin(); it != mEntries.end();) {
        const auto volume = it->volume.lock();
        if (volume && !volume->failure()) {
            ++it;
            continue;
        }
        erase(it++);
        ++mStats.dropped;
    }
}

FrameCacheStats FrameCache::stats() const {
    std::lock_guard lock(mMutex);
    return mStats;
}

} // namespace bc::server
