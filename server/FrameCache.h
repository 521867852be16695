#pragma once
// Frames answered again: a frame is a function of what its session asked for (camera,
// transfer function, render options, codec) and of the store it is drawn from, so an identical
// request (a second viewer of the same view, a client that reconnects, a refined frame asked for
// again) is answered with the bytes drawn before instead of being drawn again. Shared by every
// session of the daemon, bounded in bytes (LRU). A change of transfer function, options or
// camera is another key; a store reopened (CatalogUpdate) is another store instance, and the
// entries of a volume gone or out of service are dropped.
//
// What "identical" means is exact: the key holds the renderer's camera (every field, bit for
// bit) and the options as encoded on the wire (every field, bit for bit, but the renderer and
// quality, which it holds as what they decide: the renderer that draws the frame, auto resolved,
// and whether the frame is refined), the shading resolved for it, and the placed transfer
// function (compared by TransferFunction::sameFunction, not by a hash alone). A frame that
// depends on more (drawn at a coarser level than asked for because level 0 exceeded the GPU
// pool's share) is not kept.
#include "protocol/Messages.h"
#include "protocol/Wire.h"

#include <cstdint>
#include <list>
#include <memory>
#include <mutex>
#include <string>
#include <unordered_map>
#include <vector>

namespace bc::protocol {
struct Frame;
class FrameEncoder;
struct RenderOptions;
} // namespace bc::protocol

namespace bc::render {
struct Camera;
class TransferFunction;
} // namespace bc::render

namespace bc::server {

struct Volume;

struct FrameCacheConfig {
    /// Bytes of frames kept (0: no cache). A frame over a quarter of it is not kept.
    std::uint64_t budgetBytes = 64ull << 20;
};

/// Everything that determines a frame's pixels and its encoding.
struct FrameKey {
    std::uint64_t storeInstance = 0; ///< BrickStore::instance(): another file is another store
    std::string renderer;            ///< the registry name that draws it (auto resolved)
    bool refined = true;
    bool shading = false; ///< as resolved from the preset, the options and the client
    /// The camera's fields' bits, then the SetRenderOptions message as encoded on the wire.
    std::vector<std::uint8_t> request;
    std::shared_ptr<const render::TransferFunction> tf; ///< the placed function
    /// Equal keys, the functions compared by TransferFunction::sameFunction.
    bool matches(const FrameKey& other) const;
    std::uint64_t hash() const;
};

/// The key of a frame drawn from store `storeInstance` (BrickStore::instance()) by `renderer`
/// (auto resolved), refined or not, with `shading` as resolved for it, from `camera` and the
/// session's `options` (their renderer and quality aside: `renderer` and `refined` say what they
/// decide) under the placed function `tf`.
FrameKey frameKeyOf(std::uint64_t storeInstance, const std::string& renderer, bool refined,
                    bool shading, const render::Camera& camera,
                    const protocol::RenderOptions& options,
                    std::shared_ptr<const render::TransferFunction> tf,
                    const protocol::SetModeAndClip& modeAndClip = {});

/// A frame as kept. Delta frames depend on each connection's previous frame, so for ZstdDelta
/// the pixels are kept and each session encodes them against its own base; every other codec
/// is the same bytes for every session, kept encoded.
struct CachedFrame {
    std::uint16_t width = 0, height = 0;
    protocol::Codec codec = protocol::Codec::Raw;
    std::uint8_t level = 0;
    std::uint8_t quality = 0; ///< the codec quality it was encoded with (FrameEncoder::encode)
    /// ZstdDelta: width*height*4 RGBA bytes; other codecs: the encoded image.
    std::vector<std::uint8_t> bytes;
    bool pixels() const { return codec == protocol::Codec::ZstdDelta; }
};

/// `kept` answering a session whose encoder is `encoder`: its image (a delta frame encoded anew
/// against the session's previous frame; other codecs' bytes as kept, after which the next delta
/// frame is a keyframe, as after a frame encoded in another codec) and the header's size, codec,
/// level, keyframe and encodeMs, marked cached.
protocol::Frame frameFrom(const CachedFrame& kept, protocol::FrameEncoder& encoder);

/// Counters since the cache was made, and what it holds now.
struct FrameCacheStats {
    std::uint64_t hits = 0, misses = 0, insertions = 0;
    std::uint64_t evictions = 0; ///< by the budget
    std::uint64_t dropped = 0;   ///< of volumes gone or out of service
    std::uint64_t tooLarge = 0;  ///< frames over a quarter of the budget, not kept
    std::uint64_t bytes = 0, entries = 0, budgetBytes = 0;
};

/// Thread-safe. Frames are handed out as shared pointers: one evicted while a session sends it
/// stays valid.
class FrameCache {
  public:
    explicit FrameCache(const FrameCacheConfig& config);
    ~FrameCache();
    FrameCache(const FrameCache&) = delete;
    FrameCache& operator=(const FrameCache&) = delete;

    bool enabled() const { return mConfig.budgetBytes > 0; }
    /// The frame kept for `key`, or null (counted as a hit or a miss).
    std::shared_ptr<const CachedFrame> find(const FrameKey& key);
    /// Keeps `frame` for `key`, drawn from `volume`, evicting the least recently used beyond
    /// the budget. Entries of volumes gone (expired) or out of service are dropped first.
    void insert(FrameKey key, CachedFrame frame, const std::shared_ptr<Volume>& volume);
    FrameCacheStats stats() const;

  private:
    struct Entry;
    using Entries = std::list<Entry>;
    void erase(Entries::iterator it); ///< with mMutex held
    void dropStale();                 ///< with mMutex held

    FrameCacheConfig mConfig;
    mutable std::mutex mMutex;
    Entries mEntries; ///< most recently used first
    std::unordered_multimap<std::uint64_t, Entries::iterator> mByHash;
    FrameCacheStats mStats;
};

} // namespace bc::server
