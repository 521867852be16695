#include "server/RenderSlot.h"

#include "server/RenderService.h"
#include "server/ViewRequest.h"

namespace bc::server {

// ---- RenderSlot: the network side ----------------------------------------------------------

RenderSlot::RenderSlot(RenderService& service, Deliver deliver, std::uint32_t queueFrames,
                       std::uint64_t queueBytes)
    : mService(service), mDeliver(std::move(deliver)), mQueueFrames(queueFrames),
      mQueueBytes(queueBytes) {}

void RenderSlot::setVolume(std::shared_ptr<Volume> volume) {
    {
        std::lock_guard lock(mMutex);
        markChanged();
        mState.volume = std::move(volume);
        mState.camera.reset(); // a camera for the old volume means nothing for the new one
        mDirty = true;
        mResetDelta = true;
    }
    changed();
}

void RenderSlot::moveTo(std::shared_ptr<Volume> volume,
                        std::shared_ptr<const render::TransferFunction> tf,
                        const protocol::SetTransferFunction& message) {
    {
        std::lock_guard lock(mMutex);
        markChanged();
        mState.volume = std::move(volume); // the camera stays: the volume has the same shape
        mState.tf = std::move(tf);
        mState.tfMessage = message;
        mDirty = true;
        mResetDelta = true; // the next delta frame is a keyframe
    }
    changed();
}

void RenderSlot::setCamera(const protocol::SetCamera& camera) {
    {
        std::lock_guard lock(mMutex);
        markChanged();
        mState.camera = toCamera(camera); // latest wins: an undrawn camera is simply replaced
        mState.cameraId = camera.cameraId;
        mLastCamera = Clock::now();
        mCameraMoved = true;
        mDirty = true;
    }
    changed();
}

void RenderSlot::setTransferFunction(std::shared_ptr<const render::TransferFunction> tf,
                                     const protocol::SetTransferFunction& message) {
    {
        std::lock_guard lock(mMutex);
        markChanged();
        mState.tf = std::move(tf);
        mState.tfMessage = message;
        mDirty = true;
    }
    changed();
}

void RenderSlot::setOptions(const protocol::RenderOptions& options) {
    changeDrawing([&](State& s) { s.options = options; });
}

void RenderSlot::setModeAndClip(const protocol::SetModeAndClip& modeAndClip) {
    changeDrawing([&](State& s) { s.modeAndClip = modeAndClip; });
}

void RenderSlot::changeDrawing(const std::function<void(State&)>& change) {
    {
        std::lock_guard lock(mMutex);
        markChanged();
        change(mState);
        mDirty = true;
        mResetDelta = true;
    }
    changed();
}

void RenderSlot::setFrameBudget(const protocol::SetFrameBudget& budget) {
    std::lock_guard lock(mMutex);
    mState.budget = budget;
}

void RenderSlot::continueRefinement(std::uint32_t pass) {
    {
        std::lock_guard lock(mMutex);
        if (mClosed || mDirty || mOnce || !mContinuous) return;
        mRefinePass = pass;
    }
    changed();
}

void RenderSlot::request(protocol::FrameMode mode, std::uint32_t requestId) {
    {
        std::lock_guard lock(mMutex);
        markChanged();
        if (mode == protocol::FrameMode::Once) {
            mOnce = true;
            mOnceRequest = requestId;
        } else {
            mContinuous = mode == protocol::FrameMode::ContinuousOn;
            mDirty = mContinuous;
            if (!mContinuous) mNeedsRefine = false;
        }
    }
    changed();
}

void RenderSlot::frameDone(std::uint64_t bytes) {
    {
        std::lock_guard lock(mMutex);
        if (mInFlight > 0) --mInFlight;
        mBytesInFlight -= std::min(bytes, mBytesInFlight);
        mLastDone = Clock::now();
    }
    changed();
}

void RenderSlot::close() {
    {
        std::lock_guard lock(mMutex);
        mClosed = true;
        mDeliver = nullptr;
    }
    changed();
}

void RenderSlot::changed() {
    mService.notify();
}

void RenderSlot::markChanged() {
    if (!mDirty && !mOnce) mChangedAt = Clock::now(); // the oldest undrawn change
    mRefinePass = 0;                                  // what it refined has changed
}

// ---- RenderSlot: the render side -----------------------------------------------------------

std::optional<Clock::time_point> RenderSlot::readyAt(std::uint32_t restMs) const {
    std::lock_guard lock(mMutex);
    if (mClosed || !mState.volume || !mState.camera || !mState.tf) return std::nullopt;
    // frameDone() wakes us; one frame larger than the byte limit still goes, alone
    if (mInFlight >= mQueueFrames || mBytesInFlight >= mQueueBytes) return std::nullopt;
    if (mOnce || (mContinuous && (mDirty || mRefinePass > 0))) return Clock::time_point::min();
    // At rest: rest_ms after the camera last moved and after its last frame went out. Were it
    // after the move alone, an interactive frame that took longer than rest_ms would be
    // followed at once by a refined one, started before the client (which moves once it has
    // the frame) can move again: a slice drawn for nothing, which makes its next interactive
    // frame late too.
    if (mContinuous && mNeedsRefine)
        return std::max(mLastCamera, mLastDone) + std::chrono::milliseconds(restMs);
    return std::nullopt;
}

bool RenderSlot::owesFrame() const {
    std::lock_guard lock(mMutex);
    if (mClosed || !mState.volume || !mState.camera || !mState.tf) return false;
    return mOnce || (mContinuous && (mDirty || mRefinePass > 0 || mNeedsRefine));
}

RenderSlot::Job RenderSlot::take(Clock::time_point now, std::uint32_t restMs) {
    std::lock_guard lock(mMutex);
    Job job;
    job.state = mState;
    const auto quality = mState.options.quality;
    // A camera not drawn yet is a moving camera's, however long it waited for the render
    // thread (a slow frame of this or another session): its frame is interactive, and the
    // refined one follows rest_ms after it. Otherwise a frame that runs longer than rest_ms
    // would make every next camera's frame a refined one.
    const bool resting = !mCameraMoved && now - mLastCamera >= std::chrono::milliseconds(restMs);
    mCameraMoved = false;
    job.refined = quality == protocol::Quality::Refined ||
                  (quality == protocol::Quality::Adaptive && (resting || !mContinuous));
    job.requested = mOnce;
    job.requestId = mOnce ? mOnceRequest : 0;
    job.queuedAt = mChangedAt;
    if (mRefinePass > 0 && !mDirty && !mOnce) { // nothing changed since the pass before
        job.refined = true;
        job.pass = mRefinePass;
        job.queuedAt = now;
    }
    mRefinePass = 0;
    mNeedsRefine = !job.refined && quality == protocol::Quality::Adaptive;
    mDirty = mOnce = false;
    ++mInFlight;
    if (mResetDelta) mEncoder.resetDelta();
    mResetDelta = false;
    return job;
}

bool RenderSlot::superseded() const {
    std::lock_guard lock(mMutex);
    return mClosed || mDirty || mOnce;
}

bool RenderSlot::closed() const {
    std::lock_guard lock(mMutex);
    return mClosed;
}

void RenderSlot::delivering(std::uint64_t bytes) {
    std::lock_guard lock(mMutex);
    mBytesInFlight += bytes;
    mLastDone = Clock::now();
}

} // namespace bc::server
