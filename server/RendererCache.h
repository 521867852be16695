#pragma once
// What the render thread keeps between turns (RenderService). Per volume: its bricks resident on
// the GPU, in one pool its sessions share at the volume's share of the GPU budget, and the
// renderers that hold nothing of one viewer (RendererKind::sharedPerVolume). Per session: its
// own renderers (each keeps what is the session's: its previous frame's occlusion frustums and
// ray feedback), its frame in progress and what it prefetches next. Renderers are made at their
// first frame and go with their session; a volume's pool and shared renderers go when nobody
// views it. Render thread only (GL objects are made and destroyed there).
#include "render/EglContext.h"
#include "render/RenderTypes.h"
#include "render/Renderer.h"
#include "render/RendererChoice.h"
#include "render/View.h"
#include "server/FrameDrawing.h"
#include "server/Prefetch.h"
#include "server/RenderSlot.h"

#include <cstdint>
#include <functional>
#include <map>
#include <memory>
#include <optional>
#include <string>
#include <vector>

namespace bc::brickstore {
class BrickStore;
}

namespace bc::render {
class BrickPool;
struct RendererKind;
} // namespace bc::render

namespace bc::server {

class Catalog;
struct Volume;

/// Whether a pool made for a budget of `poolBytes` is made anew for a share of `shareBytes`:
/// when the share moved by more than an eighth, so that sessions coming and going do not make
/// every brick upload again. The daemon's pools and the MPI ranks' follow this one rule.
bool poolOutgrown(std::uint64_t poolBytes, std::uint64_t shareBytes);

/// `pool`, made for `poolBytes`, at `volume`'s share of `shareBytes`: as it is, or made anew
/// when there is none or poolOutgrown (the old texture goes before the new one is allocated;
/// `poolBytes` follows). Needs the GL context.
const std::shared_ptr<render::BrickPool>& fitPool(std::shared_ptr<render::BrickPool>& pool,
                                                  std::uint64_t& poolBytes, const Volume& volume,
                                                  std::uint64_t shareBytes);

/// Bytes of one stored brick (apron included), as the pool and the host cache hold it.
std::uint64_t slotBytesOf(const brickstore::BrickStore& store);

using RendererMap = std::map<std::string, std::unique_ptr<render::Renderer>, std::less<>>;

/// What the sessions of one volume share.
struct VolumeRenderers {
    /// Held until pruned: the map is keyed by its address, which must not be reused meanwhile.
    std::shared_ptr<Volume> volume;
    std::shared_ptr<render::BrickPool> pool;
    std::uint64_t poolBudgetBytes = 0;
    RendererMap shared;
};

/// What the render thread keeps of one session: bricks come from the volume's shared pool and
/// classifications from the service's cache.
struct SessionRenderers {
    std::weak_ptr<RenderSlot> slot;
    std::unique_ptr<FrameDrawing> drawing; ///< the frame in progress, if any
    RendererMap own;
    SessionPrefetch prefetch; ///< its GPU renderer's last two views and what to prefetch next
    /// When its last interactive frame started (budget sharing, InteractiveBudget::choose).
    std::optional<Clock::time_point> lastInteractive;
    /// The last refinement pass drawn under an error bound (8-bit RGBA), which the next pass is
    /// estimated against; empty once any other frame is drawn.
    std::vector<std::uint8_t> lastPass;
    std::uint32_t lastPassIndex = 0;
};

/// After refinement pass `d` (complete) of `session` at rest under the error bound `boundDb`
/// (> 0): sets the pass's estimate, against the sparse frame it was checked against or the
/// session's pass before, and keeps it as the session's last pass. Returns the pass to draw
/// next at half the step, or 0 when the estimate meets the bound.
std::uint32_t afterPass(SessionRenderers& session, FrameDrawing& d, double boundDb);

class RendererCache {
  public:
    /// Told the name of each volume whose pool is replaced or freed.
    using Retired = std::function<void(const std::string& volume)>;
    /// Pools get each volume's share of `gpuBudgetBytes` (Catalog::shareOf).
    RendererCache(const Catalog& catalog, std::uint64_t gpuBudgetBytes, Retired retired);

    /// Renderers of closed sessions and pools of volumes nobody views go. Returns the frames
    /// in progress that went with their sessions.
    std::uint32_t prune();
    /// `slot`'s session (a new one when another slot had the address).
    SessionRenderers& of(const std::shared_ptr<RenderSlot>& slot);
    /// Whether `slot` has a frame in progress.
    bool drawing(const RenderSlot* slot) const;
    /// Frames in progress, over every session.
    std::size_t framesInProgress() const;
    /// Sessions (other than `except`) that started an interactive frame within `within` of `now`
    /// or are drawing one.
    std::uint32_t interactiveSessions(Clock::time_point now, Clock::duration within,
                                      const RenderSlot* except = nullptr) const;

    /// What draws a frame: the renderer, and the GPU pool it draws from (null: none).
    struct Drawer {
        render::Renderer& renderer;
        const render::BrickPool* pool = nullptr;
    };
    /// The renderer of `kind` for `slot`'s frame of `volume`: the volume's or the session's
    /// own, made at its first frame; a GPU renderer draws from the volume's pool (fitPool).
    Drawer rendererFor(const std::shared_ptr<RenderSlot>& slot, const render::RendererKind& kind,
                       const std::shared_ptr<Volume>& volume);

    // GL objects (renderers, pools) go before the context: declared after it.
    std::unique_ptr<render::EglContext> context;
    /// What `auto` draws with on this server: decided at its first frame, once.
    std::optional<render::RendererChoice> autoChoice;
    std::map<const Volume*, VolumeRenderers> volumes;
    std::map<const RenderSlot*, SessionRenderers> sessions;

  private:
    const Catalog& mCatalog;
    std::uint64_t mGpuBudgetBytes;
    Retired mRetired;
};

} // namespace bc::server
