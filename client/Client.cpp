#include "client/Client.h"

#include "client/Error.h"
#include "client/detail/Channel.h"

namespace bc::client {

namespace {

using protocol::MessageType;

} // namespace

Client::Client(const ClientConfig& config)
    : mConfig(config), mWhere(config.host + ":" + std::to_string(config.port)),
      mDecoder(config.maxPayloadBytes) {
    mChannel = detail::openChannel(config, mWhere);
    protocol::Hello hello;
    hello.codecs = {protocol::Codec::Raw, protocol::Codec::Zstd, protocol::Codec::ZstdDelta,
                    protocol::Codec::Jpeg, protocol::Codec::Png};
    hello.software = "brickcast-client 0.1";
    const std::uint32_t id = nextId();
    send(hello, id);
    mServer = std::get<protocol::Hello>(await(MessageType::Hello, id));
    if (mServer.capabilities & protocol::kCapAuthRequired) {
        const std::uint32_t auth = nextId();
        send(protocol::Auth{config.token}, auth);
        await(MessageType::AuthOk, auth);
    }
}

Client::~Client() = default;

std::vector<protocol::VolumeInfo> Client::listVolumes() {
    const std::uint32_t id = nextId();
    send(protocol::ListVolumes{}, id);
    return std::get<protocol::VolumeList>(await(MessageType::VolumeList, id)).volumes;
}

protocol::VolumeInfo Client::openVolume(const std::string& name) {
    const std::uint32_t id = nextId();
    send(protocol::OpenVolume{name}, id);
    return std::get<protocol::VolumeOpened>(await(MessageType::VolumeOpened, id)).info;
}

void Client::setCamera(const protocol::SetCamera& camera) {
    send(camera, nextId());
}

void Client::setTransferFunction(const protocol::SetTransferFunction& tf) {
    send(tf, nextId());
}

void Client::setRenderOptions(const protocol::RenderOptions& options) {
    send(protocol::SetRenderOptions{options}, nextId());
}

void Client::setFrameBudget(const protocol::SetFrameBudget& budget) {
    send(budget, nextId());
}

void Client::setModeAndClip(const protocol::SetModeAndClip& modeAndClip) {
    send(modeAndClip, nextId());
}

std::uint32_t Client::requestFrame(protocol::FrameMode mode) {
    const std::uint32_t id = nextId();
    send(protocol::RequestFrame{mode}, id);
    return id;
}

ReceivedFrame Client::nextFrame() {
    if (!mPendingFrames.empty()) {
        ReceivedFrame f = std::move(mPendingFrames.front());
        mPendingFrames.erase(mPendingFrames.begin());
        return f;
    }
    std::uint32_t request = 0;
    const std::uint64_t before = mBytesReceived;
    for (;;) {
        protocol::Message m = nextMessage(&request);
        if (auto* e = std::get_if<protocol::Error>(&m))
            throw ServerError(e->code, e->fatal, e->message);
        auto* frame = std::get_if<protocol::Frame>(&m);
        if (!frame) continue; // e.g. a Stats reply nobody waits for
        ReceivedFrame out;
        out.header = frame->header;
        out.request = request;
        out.rgba = mImages.decode(frame->header.codec, frame->header.width, frame->header.height,
                                  frame->header.keyframe, frame->image);
        out.wireBytes = mBytesReceived - before;
        return out;
    }
}

std::vector<std::pair<std::string, double>> Client::stats() {
    const std::uint32_t id = nextId();
    send(protocol::RequestStats{}, id);
    return std::get<protocol::Stats>(await(MessageType::Stats, id)).counters;
}

void Client::bye() {
    send(protocol::Bye{}, nextId());
    try {
        for (;;)
            if (std::holds_alternative<protocol::Bye>(nextMessage())) return;
    } catch (const std::exception&) { // the server may close first: that is a goodbye too
    }
}

void Client::sendRaw(const std::vector<std::uint8_t>& bytes) {
    mChannel->sendAll(bytes);
}

void Client::send(const protocol::Message& message, std::uint32_t request) {
    sendRaw(protocol::encode(message, request));
}

protocol::Message Client::nextMessage(std::uint32_t* request) {
    for (;;) {
        auto r = mDecoder.next();
        if (r.status == protocol::Decoder::Status::Message) {
            if (request) *request = r.request;
            return std::move(r.message);
        }
        if (r.status == protocol::Decoder::Status::Error)
            throw ClientError(mWhere + ": bad message from the server: " + r.error.message);
        receiveSome();
    }
}

protocol::Message Client::await(MessageType type, std::uint32_t request) {
    for (;;) {
        std::uint32_t id = 0;
        protocol::Message m = nextMessage(&id);
        if (auto* e = std::get_if<protocol::Error>(&m))
            throw ServerError(e->code, e->fatal, e->message);
        if (protocol::typeOf(m) == type && id == request) return m;
        if (auto* f = std::get_if<protocol::Frame>(&m)) { // continuous frames keep coming
            ReceivedFrame out;
            out.header = f->header;
            out.request = id;
            out.rgba = mImages.decode(f->header.codec, f->header.width, f->header.height,
                                      f->header.keyframe, f->image);
            mPendingFrames.push_back(std::move(out));
        }
        if (std::holds_alternative<protocol::Bye>(m))
            throw ClientError(mWhere + ": the server said goodbye");
    }
}

void Client::receiveSome() {
    std::uint8_t buffer[64 * 1024];
    const std::size_t n = mChannel->receive(buffer, mConfig.timeoutMs);
    mBytesReceived += n;
    mDecoder.feed(std::span<const std::uint8_t>(buffer, n));
}

} // namespace bc::client
