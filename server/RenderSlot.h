#pragma once
// A session's side of the render thread: what the session wants drawn (volume, camera,
// transfer function, options, frame budget, requests), written from its network thread and
// taken as snapshots by the render thread (RenderService), with the frames it has in flight.
// Camera updates coalesce (the latest wins); a slot is due when something changed and its
// write queue has room, or when its camera has rested long enough for the refined frame.
#include "protocol/FrameCodec.h"
#include "protocol/Messages.h"
#include "render/Camera.h"
#include "render/TransferFunction.h"

#include <chrono>
#include <cstdint>
#include <functional>
#include <memory>
#include <mutex>
#include <optional>
#include <vector>

namespace bc::server {

struct Volume;
class RenderService;
struct FrameDrawing;

using Clock = std::chrono::steady_clock;

/// What a session wants drawn. Setters are called from the session's network thread; the
/// render thread takes snapshots. Thread-safe.
class RenderSlot {
  public:
    /// Receives each encoded message (a Frame or an Error) on the render thread; it must not
    /// block (the session posts it to its own thread).
    using Deliver = std::function<void(std::vector<std::uint8_t> message)>;
    /// At most `queueFrames` frames and (beyond the first) `queueBytes` bytes delivered and not
    /// yet written.
    RenderSlot(RenderService& service, Deliver deliver, std::uint32_t queueFrames,
               std::uint64_t queueBytes);

    void setVolume(std::shared_ptr<Volume> volume);
    /// The volume was reopened as `volume` (same shape, sameShape()): the camera stays, the
    /// transfer function is `tf` placed anew, and the next delta frame is a keyframe.
    void moveTo(std::shared_ptr<Volume> volume, std::shared_ptr<const render::TransferFunction> tf,
                const protocol::SetTransferFunction& message);
    void setCamera(const protocol::SetCamera& camera);
    void setTransferFunction(std::shared_ptr<const render::TransferFunction> tf,
                             const protocol::SetTransferFunction& message);
    /// New options; the next delta frame is a keyframe (how a client asks for one).
    void setOptions(const protocol::RenderOptions& options);
    /// The session's mode, iso value, crop box and clip planes; like setOptions.
    void setModeAndClip(const protocol::SetModeAndClip& modeAndClip);
    /// The session's frame-time target and error bound at rest; from the next frame on (it
    /// draws nothing by itself).
    void setFrameBudget(const protocol::SetFrameBudget& budget);
    void request(protocol::FrameMode mode, std::uint32_t requestId);
    /// A frame this slot delivered (`bytes` long) has been written or dropped: room for the next.
    void frameDone(std::uint64_t bytes);
    /// The session is gone: the render thread forgets the slot.
    void close();

  private:
    friend class RenderService;
    friend struct FrameDrawing;
    struct State {
        std::shared_ptr<Volume> volume;
        /// The renderer's camera, converted once when its SetCamera arrived (the decoder
        /// checked it: protocol/MessageRules.cpp).
        std::optional<render::Camera> camera;
        std::uint32_t cameraId = 0; ///< the client's, echoed by the frame that draws it
        std::shared_ptr<const render::TransferFunction> tf;
        protocol::SetTransferFunction tfMessage;
        protocol::RenderOptions options;
        protocol::SetModeAndClip modeAndClip;
        protocol::SetFrameBudget budget;
    };
    /// A frame to draw: the state and whether it is the refined one.
    struct Job {
        State state;
        bool refined = true;
        bool requested = false; ///< a RequestFrame(Once): owed an answer, never superseded
        std::uint32_t requestId = 0;
        Clock::time_point queuedAt{}; ///< the oldest change this frame answers
        /// Refinement pass at rest under an error bound: 0 the first refined frame, k drawn at
        /// the session's step over 2^k (render/RefinementEstimate.h).
        std::uint32_t pass = 0;
    };
    /// When the slot can next be drawn (nullopt: not until something changes).
    std::optional<Clock::time_point> readyAt(std::uint32_t restMs) const;
    /// Whether the slot owes its session a frame, now or once its camera rests, whatever room
    /// its write queue has.
    bool owesFrame() const;
    Job take(Clock::time_point now, std::uint32_t restMs);
    /// Whether what a continuous frame in progress answers has changed (a newer camera,
    /// transfer function, options or volume, or a request), or the session has gone.
    bool superseded() const;
    bool closed() const;
    /// `bytes` are on their way to the session (render thread, before delivering).
    void delivering(std::uint64_t bytes);
    /// Refinement pass `pass` is to be drawn next, unless anything has changed since the pass
    /// before it was taken (render thread, after delivering that pass).
    void continueRefinement(std::uint32_t pass);
    void changed();
    void markChanged(); ///< with mMutex held
    /// Applies `change` to the state; the next frame is due and the next delta frame a
    /// keyframe (how new options, modes and cuts take effect).
    void changeDrawing(const std::function<void(State&)>& change);

    RenderService& mService;
    Deliver mDeliver;
    std::uint32_t mQueueFrames;
    std::uint64_t mQueueBytes;
    mutable std::mutex mMutex;
    State mState;
    bool mClosed = false, mContinuous = false, mDirty = false, mNeedsRefine = false;
    bool mOnce = false, mResetDelta = false;
    bool mCameraMoved = false; ///< a SetCamera since the last frame was taken
    std::uint32_t mOnceRequest = 0, mInFlight = 0;
    std::uint32_t mRefinePass = 0;    ///< > 0: that refinement pass is due (continueRefinement)
    std::uint64_t mBytesInFlight = 0; ///< delivered, not yet written
    Clock::time_point mLastCamera{}, mChangedAt{};
    /// When its last frame was handed over and written (delivering, frameDone): a camera
    /// rests rest_ms from then or from
    /// its last move, whichever is later, since a client that waits for each frame before it
    /// moves cannot have moved sooner.
    Clock::time_point mLastDone{};
    // render thread only
    protocol::FrameEncoder mEncoder;
    std::uint32_t mNextFrameId = 1;
};

} // namespace bc::server
