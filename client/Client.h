#pragma once
// The thin client library: one blocking connection to brickcastd (POSIX sockets, poll-based
// timeouts; TLS through OpenSSL when asked), speaking protocol/ only. Not thread-safe; one per
// thread.
#include "protocol/Decoder.h"
#include "protocol/FrameCodec.h"
#include "protocol/Messages.h"

#include <chrono>
#include <cstdint>
#include <memory>
#include <optional>
#include <string>
#include <vector>

namespace bc::client {

namespace detail {
class Channel;
}

struct ClientConfig {
    std::string host = "127.0.0.1";
    std::uint16_t port = 7411;
    std::string token; ///< sent when the server requires one
    bool tls = false;  ///< the server has tls_cert: speak TLS
    /// With tls: the PEM file of the certificate authority (or the self-signed certificate)
    /// to trust; empty: the system's. The certificate must name `host`.
    std::string tlsCaFile;
    bool tlsVerify = true;           ///< false: accept any certificate (encryption, no identity)
    std::uint32_t timeoutMs = 30000; ///< any single wait (connect, a reply, a frame)
    std::uint32_t maxPayloadBytes = protocol::kDefaultMaxServerPayloadBytes;
};

/// A received frame, decoded.
struct ReceivedFrame {
    protocol::FrameHeader header;
    std::uint32_t request = 0;
    std::vector<std::uint8_t> rgba; ///< width * height * 4
    std::uint64_t wireBytes = 0;    ///< header + payload as received
};

class Client {
  public:
    /// Connects, exchanges Hello, and authenticates when the server asks for it.
    /// @throw ClientError (connection), ServerError (refused: Busy, AuthFailed...).
    explicit Client(const ClientConfig& config);
    ~Client();
    Client(const Client&) = delete;
    Client& operator=(const Client&) = delete;

    /// The server's Hello.
    const protocol::Hello& server() const { return mServer; }
    std::vector<protocol::VolumeInfo> listVolumes();
    protocol::VolumeInfo openVolume(const std::string& name);
    /// Control messages are sent without waiting; errors they cause arrive with the next
    /// reply (and throw there).
    void setCamera(const protocol::SetCamera& camera);
    void setTransferFunction(const protocol::SetTransferFunction& tf);
    void setRenderOptions(const protocol::RenderOptions& options);
    /// The session's frame-time target and error bound at rest (servers with
    /// protocol::kCapFrameBudget; older ones answer UnknownType).
    void setFrameBudget(const protocol::SetFrameBudget& budget);
    /// The session's mode, iso value, crop box and clip planes (servers with
    /// protocol::kCapModesAndClips; older ones answer UnknownType).
    void setModeAndClip(const protocol::SetModeAndClip& modeAndClip);
    /// Sends RequestFrame; returns its request id.
    std::uint32_t requestFrame(protocol::FrameMode mode = protocol::FrameMode::Once);
    /// The next Frame (decoded). @throw ServerError when an Error arrives first.
    ReceivedFrame nextFrame();
    std::vector<std::pair<std::string, double>> stats();
    /// Sends Bye and waits (briefly) for the server's.
    void bye();
    /// Bytes received on this connection so far.
    std::uint64_t bytesReceived() const { return mBytesReceived; }
    /// Sends raw bytes (tests of bad input).
    void sendRaw(const std::vector<std::uint8_t>& bytes);
    /// The next message of any type, and its request id (tests).
    protocol::Message nextMessage(std::uint32_t* request = nullptr);

  private:
    void send(const protocol::Message& message, std::uint32_t request);
    std::uint32_t nextId() { return ++mLastRequest; }
    /// Waits for the reply of `type` to `request`; throws on an Error message.
    protocol::Message await(protocol::MessageType type, std::uint32_t request);
    void receiveSome();

    ClientConfig mConfig;
    std::unique_ptr<detail::Channel> mChannel;
    std::string mWhere;
    protocol::Decoder mDecoder;
    protocol::FrameImageDecoder mImages;
    protocol::Hello mServer;
    std::vector<ReceivedFrame> mPendingFrames; ///< frames that arrived while awaiting a reply
    std::uint32_t mLastRequest = 0;
    std::uint64_t mBytesReceived = 0;
};

} // namespace bc::client
