#include "client/Client.h"

#include "client/Error.h"

#include <cerrno>
#include <cstring>
#include <netdb.h>
#include <netinet/in.h>
#include <netinet/tcp.h>
#include <poll.h>
#include <sys/socket.h>
#include <unistd.h>

namespace bc::client {

namespace {

using protocol::MessageType;

int connectTo(const std::string& host, std::uint16_t port, const std::string& where) {
    addrinfo hints{};
    hints.ai_family = AF_UNSPEC;
    hints.ai_socktype = SOCK_STREAM;
    addrinfo* list = nullptr;
    const int rc = ::getaddrinfo(host.c_str(), std::to_string(port).c_str(), &hints, &list);
    if (rc != 0) throw ClientError(where + ": " + ::gai_strerror(rc));
    std::string why = "no address";
    for (addrinfo* a = list; a; a = a->ai_next) {
        const int fd = ::socket(a->ai_family, a->ai_socktype | SOCK_CLOEXEC, a->ai_protocol);
        if (fd < 0) continue;
        if (::connect(fd, a->ai_addr, a->ai_addrlen) == 0) {
            const int one = 1;
            ::setsockopt(fd, IPPROTO_TCP, TCP_NODELAY, &one, sizeof one);
            ::freeaddrinfo(list);
            return fd;
        }
        why = std::strerror(errno);
        ::close(fd);
    }
    ::freeaddrinfo(list);
    throw ClientError(where + ": connect: " + why);
}

} // namespace

Client::Client(const ClientConfig& config)
    : mConfig(config), mWhere(config.host + ":" + std::to_string(config.port)),
      mDecoder(config.maxPayloadBytes) {
    mFd = connectTo(config.host, config.port, mWhere);
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

Client::~Client() {
    if (mFd >= 0) ::close(mFd);
}

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
    std::size_t sent = 0;
    while (sent < bytes.size()) {
        const ssize_t n = ::send(mFd, bytes.data() + sent, bytes.size() - sent, MSG_NOSIGNAL);
        if (n < 0 && errno == EINTR) continue;
        if (n <= 0) throw ClientError(mWhere + ": send: " + std::strerror(errno));
        sent += std::size_t(n);
    }
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
    pollfd p{mFd, POLLIN, 0};
    const int ready = ::poll(&p, 1, int(mConfig.timeoutMs));
    if (ready == 0)
        throw ClientError(mWhere + ": no reply in " + std::to_string(mConfig.timeoutMs) + " ms");
    if (ready < 0 && errno != EINTR) throw ClientError(mWhere + ": poll: " + std::strerror(errno));
    std::uint8_t buffer[64 * 1024];
    const ssize_t n = ::recv(mFd, buffer, sizeof buffer, 0);
    if (n == 0) throw ClientError(mWhere + ": the server closed the connection");
    if (n < 0) {
        if (errno == EINTR || errno == EAGAIN) return;
        throw ClientError(mWhere + ": recv: " + std::strerror(errno));
    }
    mBytesReceived += std::uint64_t(n);
    mDecoder.feed(std::span<const std::uint8_t>(buffer, std::size_t(n)));
}

} // namespace bc::client
