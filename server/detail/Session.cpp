#include "server/detail/Session.h"

#include "server/Metrics.h"

#include "render/Camera.h"
#include "server/Log.h"
#include "server/ViewRequest.h"

#include <algorithm>
#include <sstream>

namespace bc::server::detail {

namespace {

using protocol::ErrorCode;
using protocol::MessageType;

constexpr auto kWatchdogPeriod = std::chrono::milliseconds(50);

std::chrono::milliseconds ms(std::uint32_t v) {
    return std::chrono::milliseconds(v);
}

/// Constant-time comparison: the time taken depends on the lengths only, never on where the
/// first difference lies.
bool tokensEqual(const std::string& given, const std::string& expected) {
    const std::size_t n = std::max(given.size(), expected.size());
    unsigned diff = given.size() == expected.size() ? 0u : 1u;
    for (std::size_t i = 0; i < n; ++i) {
        const unsigned char a = i < given.size() ? static_cast<unsigned char>(given[i]) : 0;
        const unsigned char b = i < expected.size() ? static_cast<unsigned char>(expected[i]) : 0;
        diff |= unsigned(a ^ b);
    }
    return diff == 0;
}

/// The store's histogram as the protocol carries it: at most kMaxHistogramBins equal bins
/// (a finer one is merged k bins at a time; the last merged bin may reach past valueMax).
protocol::Histogram histogramOf(const render::VolumeValueStats& stats) {
    protocol::Histogram h{stats.valueMin, stats.valueMax, {}};
    const std::size_t n = stats.histogram.size();
    if (n == 0) {
        h.counts = {0};
        return h;
    }
    const std::size_t k = (n + protocol::kMaxHistogramBins - 1) / protocol::kMaxHistogramBins;
    h.counts.assign((n + k - 1) / k, 0);
    for (std::size_t i = 0; i < n; ++i)
        h.counts[i / k] += stats.histogram[i];
    h.valueMax = stats.valueMin +
                 (stats.valueMax - stats.valueMin) * double(h.counts.size() * k) / double(n);
    return h;
}

/// Sets the request id of an encoded message (PROTOCOL.md: header bytes 12..15, little-endian).
void setRequestId(std::vector<std::uint8_t>& bytes, std::uint32_t request) {
    for (int i = 0; i < 4; ++i)
        bytes[12 + i] = std::uint8_t(request >> (8 * i));
}

std::string mib(std::uint64_t bytes) {
    std::ostringstream s;
    s.precision(3);
    s << double(bytes) / double(1 << 20) << " MiB";
    return s.str();
}

} // namespace

Session::Session(std::unique_ptr<Transport> transport, SessionContext& context, std::uint64_t id)
    : mTransport(std::move(transport)), mTimer(mTransport->executor()),
      mAuthTimer(mTransport->executor()), mContext(context), mId(id),
      mDecoder(protocol::kMaxClientPayloadBytes) {
    mPeer = mTransport->peer();
    mStarted = mLastMessage = Clock::now();
}

void Session::start() {
    mContext.log.info("session " + std::to_string(mId) + " from " + mPeer + " (" +
                      mTransport->kind() + ") started");
    std::weak_ptr<Session> weak = shared_from_this();
    auto executor = mTransport->executor();
    mSlot = mContext.render.open(
        [weak, executor](std::vector<std::uint8_t> bytes) {
            asio::post(executor, [weak, bytes = std::move(bytes)]() mutable {
                if (auto self = weak.lock()) self->enqueue({std::move(bytes), true});
            });
        },
        mContext.config.writeQueueFrames, mContext.config.writeQueueBytes);
    read();
    watchdog();
}

void Session::refuseBusy() {
    mContext.log.info("session " + std::to_string(mId) + " from " + mPeer +
                      " refused: too many clients");
    sendError(ErrorCode::Busy, true, 0, 0,
              "too many clients (" + std::to_string(mContext.config.maxClients) + ")");
    watchdog();
}

void Session::shutdown() {
    if (mPhase == Phase::Closing || mPhase == Phase::Closed) return;
    send(protocol::Bye{protocol::ByeReason::ShuttingDown}, 0);
    closeAfterFlush("server shutting down");
}

void Session::followReload(const CatalogUpdate& update) {
    if (!mLease || mPhase == Phase::Closing || mPhase == Phase::Closed) return;
    const auto& current = mLease.volume();
    for (const auto& [old, next] : update.reopened) {
        if (old != current) continue;
        if (sameShape(*old, *next)) return moveTo(next);
        return leave("volume '" + old->name +
                     "' was reopened by a catalog reload with another voxel type, dims or "
                     "spacing; open it again");
    }
    if (std::find(update.removed.begin(), update.removed.end(), current) != update.removed.end())
        leave("volume '" + current->name +
              "' was removed by a catalog reload (or could not be reopened); open a volume again");
}

void Session::moveTo(const std::shared_ptr<Volume>& next) {
    VolumeLease lease = mContext.catalog.lease(next->name);
    std::shared_ptr<const render::TransferFunction> tf;
    try {
        tf = toTransferFunction(mTfMessage, next->stats, mContext.catalog.configPresets());
    } catch (const std::exception& e) { // a config preset the reload removed
        return leave("volume '" + next->name +
                     "' was reopened by a catalog reload and the "
                     "session's transfer function no longer applies (" +
                     e.what() + "); open it again");
    }
    if (lease.volume() != next) return leave("volume '" + next->name + "' was reopened");
    mLease = std::move(lease);
    mKept[std::size_t(Reusable::Histogram)].bytes.clear();
    mSlot->moveTo(next, std::move(tf), mTfMessage);
    send(protocol::VolumeOpened{next->info}, 0);
    mContext.log.info("session " + std::to_string(mId) + ": volume '" + next->name +
                      "' was reopened by a catalog reload: the session moved to " +
                      next->store->path());
}

void Session::leave(const std::string& why) {
    mSlot->setVolume(nullptr); // the render thread stops drawing the old store
    mLease = {};
    mKept[std::size_t(Reusable::Histogram)].bytes.clear();
    sendError(ErrorCode::UnknownVolume, false, std::uint8_t(MessageType::OpenVolume), 0, why);
}

void Session::volumeFailed(const std::shared_ptr<Volume>& volume) {
    if (mLease.volume() != volume || mPhase == Phase::Closing || mPhase == Phase::Closed) return;
    sendError(ErrorCode::RenderFailed, false, std::uint8_t(MessageType::RequestFrame), 0,
              "volume '" + volume->name +
                  "' is out of service: " + volume->failure().value_or("its store failed"));
}

// ---- reading -------------------------------------------------------------------------------

void Session::read() {
    mReading = true;
    mTransport->read(
        [self = shared_from_this()](const std::string& error, std::span<const std::uint8_t> bytes) {
            self->mReading = false;
            if (self->mPhase == Phase::Closed) return;
            if (!error.empty()) return self->close(error);
            self->onBytes(bytes);
        });
}

void Session::onBytes(std::span<const std::uint8_t> bytes) {
    mBytesReceived += bytes.size();
    mDecoder.feed(bytes);
    pump();
}

void Session::pump() {
    while (!paused()) {
        auto r = mDecoder.next();
        if (r.status == protocol::Decoder::Status::NeedMore) {
            if (!mDecoder.midMessage())
                mMidMessageSince.reset();
            else if (!mMidMessageSince)
                mMidMessageSince = Clock::now();
            if (!mReading) read();
            return;
        }
        mLastMessage = Clock::now();
        if (r.status == protocol::Decoder::Status::Error) {
            sendError(r.error.code, r.error.fatal, r.error.type, r.error.request, r.error.message);
            if (r.error.fatal) return;
            continue;
        }
        handle(r.message, r.request);
        if (mPhase == Phase::Closing || mPhase == Phase::Closed) return;
    }
}

/// The handshake gate: before Hello only Hello; before a required Auth only Auth (and Bye).
bool Session::admitted(MessageType type, std::uint32_t request) {
    if (type == MessageType::Bye) return true;
    const auto t = std::uint8_t(type);
    if (mPhase == Phase::AwaitHello && type != MessageType::Hello) {
        const bool auth = !mContext.config.token.empty();
        sendError(auth ? ErrorCode::NotAuthenticated : ErrorCode::BadState, true, t, request,
                  auth ? "authenticate first (Hello, then Auth)" : "Hello must come first");
        return false;
    }
    if (mPhase == Phase::AwaitAuth && type != MessageType::Auth) {
        sendError(ErrorCode::NotAuthenticated, true, t, request, "authenticate first");
        return false;
    }
    return true;
}

void Session::handle(protocol::Message& message, std::uint32_t request) {
    const MessageType type = protocol::typeOf(message);
    if (!admitted(type, request)) return;
    const auto t = std::uint8_t(type);
    try {
        std::visit(
            [&](auto& m) {
                using M = std::decay_t<decltype(m)>;
                if constexpr (std::is_same_v<M, protocol::Hello>) {
                    onHello(m, request);
                } else if constexpr (std::is_same_v<M, protocol::Auth>) {
                    onAuth(m, request);
                } else if constexpr (std::is_same_v<M, protocol::ListVolumes>) {
                    send(protocol::VolumeList{mContext.catalog.list()}, request);
                } else if constexpr (std::is_same_v<M, protocol::OpenVolume>) {
                    onOpenVolume(m, request);
                } else if constexpr (std::is_same_v<M, protocol::SetCamera>) {
                    mSlot->setCamera(m); // the decoder validated it (Camera::validate's rules)
                } else if constexpr (std::is_same_v<M, protocol::SetTransferFunction>) {
                    onSetTransferFunction(m, request);
                } else if constexpr (std::is_same_v<M, protocol::SetRenderOptions>) {
                    onSetRenderOptions(m, request);
                } else if constexpr (std::is_same_v<M, protocol::RequestFrame>) {
                    onRequestFrame(m, request);
                } else if constexpr (std::is_same_v<M, protocol::RequestStats>) {
                    onRequestStats(request);
                } else if constexpr (std::is_same_v<M, protocol::SetFrameBudget>) {
                    mSlot->setFrameBudget(m); // the decoder checked its ranges
                } else if constexpr (std::is_same_v<M, protocol::SetModeAndClip>) {
                    onSetModeAndClip(m, request);
                } else if constexpr (std::is_same_v<M, protocol::RequestHistogram>) {
                    onRequestHistogram(request);
                } else if constexpr (std::is_same_v<M, protocol::Bye>) {
                    send(protocol::Bye{protocol::ByeReason::Normal}, request);
                    closeAfterFlush("bye");
                } else if constexpr (std::is_same_v<M, protocol::Error>) {
                    close("client error " +
                          std::string(protocol::errorName(std::uint16_t(m.code))) + ": " +
                          m.message);
                } else {
                    sendError(ErrorCode::BadState, false, t, request,
                              std::string(protocol::typeName(t)) +
                                  " is a server-to-client message");
                }
            },
            message);
    } catch (const std::invalid_argument& e) { // the renderer's own validation
        sendError(ErrorCode::OutOfRange, false, t, request, e.what());
    } catch (const std::exception& e) {
        sendError(ErrorCode::Internal, true, t, request, e.what());
    }
}

void Session::onHello(const protocol::Hello& hello, std::uint32_t request) {
    const auto t = std::uint8_t(MessageType::Hello);
    if (mPhase != Phase::AwaitHello) {
        sendError(ErrorCode::BadState, false, t, request, "Hello was already sent");
        return;
    }
    if (hello.versionMin > protocol::kVersion || hello.versionMax < protocol::kVersion) {
        sendError(ErrorCode::UnsupportedVersion, true, t, request,
                  "this server speaks version " + std::to_string(protocol::kVersion));
        return;
    }
    protocol::Hello reply;
    reply.capabilities = mContext.capabilities;
    if (!mContext.render.gpuUnavailable()) reply.capabilities |= protocol::kCapGpuRenderer;
    reply.codecs = {protocol::Codec::Raw, protocol::Codec::Zstd, protocol::Codec::ZstdDelta,
                    protocol::Codec::Jpeg, protocol::Codec::Png};
    reply.software = "brickcastd 0.1";
    send(reply, request);
    mPhase = Phase::AwaitAuth;
    if (mContext.config.token.empty()) becomeReady(t, request);
}

void Session::onAuth(const protocol::Auth& auth, std::uint32_t request) {
    const auto t = std::uint8_t(MessageType::Auth);
    if (mPhase != Phase::AwaitAuth) {
        sendError(ErrorCode::BadState, false, t, request, "no authentication is pending");
        return;
    }
    const auto now = Clock::now();
    const auto at = mContext.authThrottle ? mContext.authThrottle->admit(addressOf(mPeer), now)
                                          : std::optional(now);
    if (!at)
        return sendError(ErrorCode::Busy, true, t, request,
                         "another authentication from " + addressOf(mPeer) +
                             " waits its turn (wrong tokens came from there); try again later");
    if (*at <= now) return checkAuth(auth.token, request);
    // Reading pauses until the turn comes: the client can queue nothing meanwhile.
    mAuthWaiting = true;
    mAuthTimer.expires_at(*at);
    mAuthTimer.async_wait(
        [self = shared_from_this(), token = auth.token, request](const IoError& ec) {
            if (ec || self->mPhase != Phase::AwaitAuth) return;
            self->mAuthWaiting = false;
            self->checkAuth(token, request);
            if (self->mPhase == Phase::Ready && !self->mReading) self->pump(); // reads on
        });
}

void Session::checkAuth(const std::string& token, std::uint32_t request) {
    const auto t = std::uint8_t(MessageType::Auth);
    const std::string address = addressOf(mPeer);
    if (!tokensEqual(token, mContext.config.token)) {
        if (mContext.authThrottle) {
            const auto wait = mContext.authThrottle->failed(address, Clock::now());
            mContext.log.info("session " + std::to_string(mId) + ": wrong token from " + address +
                              "; its next Auth is checked in " + std::to_string(wait.count()) +
                              " ms at the soonest");
        }
        sendError(ErrorCode::AuthFailed, true, t, request, "authentication failed");
        return;
    }
    if (mContext.authThrottle) mContext.authThrottle->succeeded(address);
    becomeReady(t, request);
    if (mPhase == Phase::Ready) send(protocol::AuthOk{}, request);
}

void Session::becomeReady(std::uint8_t type, std::uint32_t request) {
    if (mContext.onReady && !mContext.onReady(mId)) {
        sendError(ErrorCode::Busy, true, type, request,
                  "too many clients (" + std::to_string(mContext.config.maxClients) + ")");
        return;
    }
    mPhase = Phase::Ready;
}

void Session::onOpenVolume(const protocol::OpenVolume& open, std::uint32_t request) {
    VolumeLease lease = mContext.catalog.lease(open.name);
    if (!lease) {
        sendError(ErrorCode::UnknownVolume, false, std::uint8_t(MessageType::OpenVolume), request,
                  "no volume named '" + open.name + "' in the catalog");
        return;
    }
    const auto volume = lease.volume();
    if (const auto why = volume->failure()) {
        sendError(ErrorCode::UnknownVolume, false, std::uint8_t(MessageType::OpenVolume), request,
                  "volume '" + open.name + "' is out of service: " + *why);
        return;
    }
    // The session's transfer function, placed anew for this volume's values.
    if (!mHaveTf) {
        mTfMessage = {};
        mTfMessage.kind = protocol::TfKind::Preset;
        mTfMessage.preset = "ct-skin";
    }
    auto tf = toTransferFunction(mTfMessage, volume->stats, mContext.catalog.configPresets());
    mLease = std::move(lease);
    mSlot->setVolume(volume);
    mSlot->setTransferFunction(std::move(tf), mTfMessage);
    mSlot->setOptions(mOptions);
    send(protocol::VolumeOpened{volume->info}, request);
}

void Session::onSetTransferFunction(const protocol::SetTransferFunction& m, std::uint32_t request) {
    const auto t = std::uint8_t(MessageType::SetTransferFunction);
    if (!mLease) {
        sendError(ErrorCode::NoVolume, false, t, request, "open a volume first");
        return;
    }
    if (m.kind == protocol::TfKind::Preset && !mContext.catalog.hasPreset(m.preset)) {
        // The name is not repeated: what a client sends never comes back as if it were found.
        std::string list;
        for (const auto& name : mContext.catalog.presetNames())
            list += (list.empty() ? "" : ", ") + name;
        sendError(ErrorCode::NotFound, false, t, request,
                  protocol::fitText("SetTransferFunction.preset: not a preset of this server; "
                                    "presets: " +
                                        list,
                                    protocol::kMaxErrorMessageBytes));
        return;
    }
    try {
        auto tf = toTransferFunction(m, mLease.volume()->stats, mContext.catalog.configPresets());
        mTfMessage = m;
        mHaveTf = true;
        mSlot->setTransferFunction(std::move(tf), m);
    } catch (const std::exception& e) { // RenderInputError naming the preset or point
        sendError(ErrorCode::OutOfRange, false, t, request, e.what());
    }
}

void Session::onSetRenderOptions(const protocol::SetRenderOptions& m, std::uint32_t request) {
    const bool gpu = m.options.renderer == protocol::Renderer::GpuRaycaster ||
                     m.options.renderer == protocol::Renderer::GpuSplatter;
    if (gpu) {
        if (const auto why = mContext.render.gpuUnavailable()) {
            sendError(ErrorCode::OutOfRange, false, std::uint8_t(MessageType::SetRenderOptions),
                      request, "SetRenderOptions.renderer: " + *why);
            return;
        }
    }
    toRenderOptions(m.options, 1).validate();
    mOptions = m.options;
    mSlot->setOptions(mOptions);
}

void Session::onSetModeAndClip(const protocol::SetModeAndClip& m, std::uint32_t request) {
    // The decoder checked the values as render::Clip does; the iso value against the volume
    // open now (a volume opened later is checked by its frames).
    if (m.mode == protocol::BlendMode::Isosurface && mLease) {
        const auto& stats = mLease.volume()->stats;
        if (!(m.isoValue >= stats.valueMin && m.isoValue <= stats.valueMax))
            return sendError(
                ErrorCode::OutOfRange, false, std::uint8_t(MessageType::SetModeAndClip), request,
                "SetModeAndClip.isoValue: " + std::to_string(m.isoValue) +
                    " is outside the volume's values [" + std::to_string(stats.valueMin) + ", " +
                    std::to_string(stats.valueMax) + "]");
    }
    render::RenderOptions check = toRenderOptions(mOptions, 1);
    applyModeAndClip(check, m);
    check.validate();
    mSlot->setModeAndClip(m);
}

void Session::onRequestFrame(const protocol::RequestFrame& m, std::uint32_t request) {
    const auto t = std::uint8_t(MessageType::RequestFrame);
    if (m.mode != protocol::FrameMode::ContinuousOff && !mLease) {
        sendError(ErrorCode::NoVolume, false, t, request, "open a volume first");
        return;
    }
    mSlot->request(m.mode, request);
}

void Session::onRequestHistogram(std::uint32_t request) {
    const auto t = std::uint8_t(MessageType::RequestHistogram);
    if (!mLease) return sendError(ErrorCode::NoVolume, false, t, request, "open a volume first");
    if (sendKept(Reusable::Histogram, request)) return;
    sendKeeping(Reusable::Histogram, histogramOf(mLease.volume()->stats), request);
}

void Session::onRequestStats(std::uint32_t request) {
    if (sendKept(Reusable::Stats, request)) return; // asked again before the last one went
    MetricSet metrics;
    if (mContext.collect) mContext.collect(metrics);
    metrics.counter("session_frames_sent_total", "Frames this session was sent",
                    double(mFramesSent));
    metrics.counter("session_bytes_sent_total", "Bytes this session was sent", double(mBytesSent));
    metrics.counter("session_bytes_received_total", "Bytes this session sent",
                    double(mBytesReceived));
    metrics.gauge("session_write_queue_messages", "Messages in this session's write queue",
                  double(mQueue.size()));
    protocol::Stats stats;
    stats.counters = metrics.statCounters(protocol::kMaxStatNameBytes);
    if (stats.counters.size() > protocol::kMaxStats) stats.counters.resize(protocol::kMaxStats);
    sendKeeping(Reusable::Stats, stats, request);
}

// ---- writing -------------------------------------------------------------------------------

void Session::send(const protocol::Message& message, std::uint32_t request) {
    Outgoing out;
    protocol::encode(message, request, out.bytes);
    enqueue(std::move(out));
}

bool Session::sendKept(Reusable kind, std::uint32_t request) {
    const KeptReply& kept = mKept[std::size_t(kind)];
    if (kept.queued == 0 || kept.bytes.empty()) return false;
    Outgoing out{kept.bytes, false, kind};
    setRequestId(out.bytes, request);
    enqueue(std::move(out));
    return true;
}

void Session::sendKeeping(Reusable kind, const protocol::Message& message, std::uint32_t request) {
    Outgoing out;
    out.reusable = kind;
    protocol::encode(message, request, out.bytes);
    mKept[std::size_t(kind)].bytes = out.bytes;
    enqueue(std::move(out));
}

void Session::sendError(ErrorCode code, bool fatal, std::uint8_t type, std::uint32_t request,
                        const std::string& message) {
    ++mErrorsSent;
    ++mContext.errorsSent;
    mContext.log.info("session " + std::to_string(mId) + ": " +
                      protocol::errorName(std::uint16_t(code)) + (fatal ? " (fatal): " : ": ") +
                      message);
    send(protocol::Error{code, fatal, type,
                         protocol::fitText(message, protocol::kMaxErrorMessageBytes)},
         request);
    if (fatal) closeAfterFlush(std::string(protocol::errorName(std::uint16_t(code))));
}

void Session::enqueue(Outgoing out) {
    if (mPhase == Phase::Closed) {
        if (out.fromRenderer && mSlot) mSlot->frameDone(out.bytes.size());
        return;
    }
    mQueueBytes += out.bytes.size();
    if (!out.fromRenderer) mReplyBytes += out.bytes.size();
    if (out.reusable != Reusable::None) ++mKept[std::size_t(out.reusable)].queued;
    mQueue.push_back(std::move(out));
    if (!mWriting) write();
}

void Session::write() {
    if (mQueue.empty()) {
        mWriting = false;
        if (mPhase == Phase::Closing) close(mCloseReason);
        return;
    }
    mWriting = true;
    mWriteStarted = Clock::now();
    mTransport->write(mQueue.front().bytes,
                      [self = shared_from_this()](const std::string& error, std::size_t n) {
                          if (self->mPhase == Phase::Closed) return;
                          self->written(error, n);
                      });
}

void Session::written(const std::string& error, std::size_t n) {
    Outgoing done = std::move(mQueue.front());
    mQueue.pop_front();
    mQueueBytes -= done.bytes.size();
    if (!done.fromRenderer) mReplyBytes -= done.bytes.size();
    if (done.reusable != Reusable::None) --mKept[std::size_t(done.reusable)].queued;
    if (done.fromRenderer) mSlot->frameDone(done.bytes.size()), ++mFramesSent;
    if (!error.empty()) return close(error);
    mBytesSent += n;
    write();
    // The client took a reply: the requests waiting behind the bound are handled now.
    if (mPhase != Phase::Closing && mPhase != Phase::Closed && !mReading && !paused()) pump();
}

// ---- deadlines and closing -----------------------------------------------------------------

void Session::watchdog() {
    mTimer.expires_after(kWatchdogPeriod);
    mTimer.async_wait([self = shared_from_this()](const IoError& ec) {
        if (ec || self->mPhase == Phase::Closed) return;
        const auto now = Clock::now();
        const auto& c = self->mContext.config;
        if (self->mWriting && now - self->mWriteStarted > ms(c.writeTimeoutMs))
            return self->close("write timeout: the client stopped reading");
        if (self->mPhase == Phase::Closing && now - self->mClosingSince > ms(c.writeTimeoutMs))
            return self->close(self->mCloseReason + " (unsent data dropped)");
        if (self->mPhase == Phase::AwaitHello || self->mPhase == Phase::AwaitAuth) {
            if (now - self->mStarted > ms(c.handshakeTimeoutMs))
                self->sendError(ErrorCode::Timeout, true, 0, 0,
                                "handshake not completed in " +
                                    std::to_string(c.handshakeTimeoutMs) + " ms");
        } else if (self->mPhase == Phase::Ready) {
            if (self->mMidMessageSince && now - *self->mMidMessageSince > ms(c.readTimeoutMs))
                self->sendError(ErrorCode::Timeout, true, 0, 0,
                                "message incomplete after " + std::to_string(c.readTimeoutMs) +
                                    " ms");
            else if (now - self->mLastMessage > ms(c.idleTimeoutMs)) {
                self->send(protocol::Bye{protocol::ByeReason::IdleTimeout}, 0);
                self->closeAfterFlush("idle timeout");
            }
        }
        self->watchdog();
    });
}

void Session::closeAfterFlush(const std::string& why) {
    if (mPhase == Phase::Closing || mPhase == Phase::Closed) return;
    mPhase = Phase::Closing;
    mCloseReason = why;
    mClosingSince = Clock::now();
    if (!mWriting) write();
}

void Session::close(const std::string& why) {
    if (mPhase == Phase::Closed) return;
    mPhase = Phase::Closed;
    mTransport->close();
    mTimer.cancel();
    mAuthTimer.cancel();
    if (mAuthWaiting && mContext.authThrottle) mContext.authThrottle->abandoned(addressOf(mPeer));
    if (mSlot) mSlot->close();
    mLease = {};
    const double seconds = std::chrono::duration<double>(Clock::now() - mStarted).count();
    mContext.log.info("session " + std::to_string(mId) + " ended: " + why + " (" +
                      std::to_string(mFramesSent) + " frames, " + mib(mBytesSent) + " sent, " +
                      std::to_string(int(seconds * 1000)) + " ms)");
    if (mContext.onClosed) mContext.onClosed(mId);
}

} // namespace bc::server::detail
