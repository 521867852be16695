#pragma once
// One client connection of brickcastd (private to server/), over TCP or WebSocket (Transport).
// Runs on the daemon's network thread: reads bytes into the protocol decoder, answers control
// messages at once, hands render requests to its RenderSlot, and writes what comes back through a
// bounded queue. Replies are bounded too: while more than kMaxQueuedReplyBytes of them wait, the
// session reads no further request (the client's own sends block), and a Stats or Histogram
// asked for again while the last one waits is a copy of it. A watchdog enforces the handshake,
// trickle (message started but incomplete), idle and write deadlines. Every error is answered
// with an Error message; a fatal one closes the session.
#include "protocol/Decoder.h"
#include "protocol/Messages.h"
#include "server/Catalog.h"
#include "server/DaemonConfig.h"
#include "server/RenderService.h"

#include "server/detail/Asio.h"
#include "server/detail/AuthThrottle.h"
#include "server/detail/Transport.h"

#include <array>
#include <cstdint>
#include <deque>
#include <functional>
#include <memory>
#include <string>

namespace bc::server {

class Log;

class MetricSet;

namespace detail {

/// What every session of a daemon shares.
struct SessionContext {
    const DaemonConfig& config;
    Catalog& catalog;
    RenderService& render;
    Log& log;
    std::uint32_t capabilities = 0; ///< but the GPU bit (RenderService::gpuUnavailable)
    std::function<void(std::uint64_t id)> onClosed; ///< on the network thread
    /// The whole server's metrics (what GET /metrics serves), on the network thread.
    std::function<void(MetricSet&)> collect;
    std::uint64_t errorsSent = 0;         ///< by every session; network thread only
    AuthThrottle* authThrottle = nullptr; ///< wrong tokens per address; none: no waits
    /// The session completed its handshake (Hello, and Auth when required); false: no room
    /// among the authenticated clients (the session is answered Busy). None: always room.
    std::function<bool(std::uint64_t id)> onReady;
};

class Session : public std::enable_shared_from_this<Session> {
  public:
    /// Replies (all but frames) queued beyond this stop the session reading requests until
    /// the client has taken them: what a client that never reads can make the daemon hold.
    static constexpr std::uint64_t kMaxQueuedReplyBytes = 256 * 1024;

    Session(std::unique_ptr<Transport> transport, SessionContext& context, std::uint64_t id);
    /// Starts reading and the watchdog.
    void start();
    /// Refuses the connection: Error Busy, then close (the session never starts).
    void refuseBusy();
    /// The server is draining: Bye (shutting down), then close once written.
    void shutdown();
    /// A catalog reload was applied. When this session views a volume it reopened with the
    /// same shape (sameShape), the session moves to the new one unasked: new lease, transfer
    /// function placed anew, camera kept, VolumeOpened (request id 0) sent. When it views one
    /// the reload removed, or reopened with another shape, it stops drawing it, drops its
    /// lease and is sent Error UnknownVolume (not fatal; the client may open a volume again).
    void followReload(const CatalogUpdate& update);
    /// `volume` was taken out of service: when this session views it, Error RenderFailed
    /// (request id 0, not fatal) says why. The session keeps it: its frames are refused until
    /// a reload reopens the volume, which moves the session to the new store.
    void volumeFailed(const std::shared_ptr<Volume>& volume);
    std::uint64_t id() const { return mId; }
    /// Messages waiting in the write queue (the one being written included).
    std::size_t queued() const { return mQueue.size(); }
    /// Bytes in the write queue (the message being written included).
    std::uint64_t queuedBytes() const { return mQueueBytes; }
    /// Whether the session has completed its handshake (Hello, and Auth when required).
    bool authenticated() const { return mPhase == Phase::Ready; }
    /// Cuts the connection now, saying why in the log (a newer connection needs its place).
    void cut(const std::string& why) { close(why); }

  private:
    enum class Phase { AwaitHello, AwaitAuth, Ready, Closing, Closed };
    /// Replies whose bytes are kept while one waits in the queue, for a copy to answer the
    /// same request again.
    enum class Reusable { Stats, Histogram, Count, None = Count };
    struct Outgoing {
        std::vector<std::uint8_t> bytes;
        bool fromRenderer = false; ///< a frame or render error: tell the slot when written
        Reusable reusable = Reusable::None;
    };
    struct KeptReply {
        std::vector<std::uint8_t> bytes;
        unsigned queued = 0; ///< copies of it in the queue
    };

    void read();
    void onBytes(std::span<const std::uint8_t> bytes);
    /// Handles what the decoder holds, then reads on, unless replies are backed up or an Auth
    /// waits its turn: then reading stays paused until write() or the Auth timer resumes it.
    void pump();
    bool paused() const { return mReplyBytes > kMaxQueuedReplyBytes || mAuthWaiting; }
    void handle(protocol::Message& message, std::uint32_t request);
    bool admitted(protocol::MessageType type, std::uint32_t request);
    void onHello(const protocol::Hello& hello, std::uint32_t request);
    void onAuth(const protocol::Auth& auth, std::uint32_t request);
    void checkAuth(const std::string& token, std::uint32_t request);
    /// The handshake is complete: Ready, or Busy when the daemon has no room.
    void becomeReady(std::uint8_t type, std::uint32_t request);
    void onOpenVolume(const protocol::OpenVolume& open, std::uint32_t request);
    void onSetTransferFunction(const protocol::SetTransferFunction& tf, std::uint32_t request);
    void onSetRenderOptions(const protocol::SetRenderOptions& options, std::uint32_t request);
    void onSetModeAndClip(const protocol::SetModeAndClip& m, std::uint32_t request);
    void onRequestFrame(const protocol::RequestFrame& frame, std::uint32_t request);
    void onRequestStats(std::uint32_t request);
    void onRequestHistogram(std::uint32_t request);
    /// Views `next`, the reopened volume of the same shape, in place of the current one.
    void moveTo(const std::shared_ptr<Volume>& next);
    /// Stops viewing the current volume and sends UnknownVolume saying `why`.
    void leave(const std::string& why);
    void send(const protocol::Message& message, std::uint32_t request);
    /// A copy of the kept reply of `kind`, answering `request`, when one waits in the queue.
    bool sendKept(Reusable kind, std::uint32_t request);
    void sendKeeping(Reusable kind, const protocol::Message& message, std::uint32_t request);
    void sendError(protocol::ErrorCode code, bool fatal, std::uint8_t type, std::uint32_t request,
                   const std::string& message);
    void enqueue(Outgoing out);
    void write();
    /// The front message was written (or failed).
    void written(const std::string& error, std::size_t bytes);
    void watchdog();
    /// Stops reading; closes once the queue is written (or the write deadline passes).
    void closeAfterFlush(const std::string& why);
    void close(const std::string& why);

    std::unique_ptr<Transport> mTransport;
    asio::steady_timer mTimer;
    asio::steady_timer mAuthTimer; ///< an Auth waiting its turn (AuthThrottle)
    SessionContext& mContext;
    std::uint64_t mId;
    std::string mPeer;
    Phase mPhase = Phase::AwaitHello;
    protocol::Decoder mDecoder;
    std::deque<Outgoing> mQueue;
    std::uint64_t mQueueBytes = 0;
    std::uint64_t mReplyBytes = 0; ///< of mQueueBytes, what is not from the renderer
    std::array<KeptReply, std::size_t(Reusable::Count)> mKept;
    bool mWriting = false;
    bool mReading = false;     ///< a transport read is pending
    bool mAuthWaiting = false; ///< an Auth waits for its turn (mAuthTimer)
    std::shared_ptr<RenderSlot> mSlot;
    VolumeLease mLease;
    protocol::SetTransferFunction mTfMessage;
    bool mHaveTf = false;
    protocol::RenderOptions mOptions;
    Clock::time_point mStarted, mLastMessage, mWriteStarted, mClosingSince;
    std::optional<Clock::time_point> mMidMessageSince;
    std::string mCloseReason;
    std::uint64_t mFramesSent = 0, mBytesSent = 0, mBytesReceived = 0, mErrorsSent = 0;
};

} // namespace detail
} // namespace bc::server
