#include "server/Log.h"
#include "server/detail/Tls.h"
#include "server/detail/Transport.h"

#include <boost/asio/ssl.hpp>

#include <array>

namespace bc::server::detail {
namespace {

using TlsStream = asio::ssl::stream<asio::ip::tcp::socket>;

/// The protocol's bytes on a stream: a TCP socket, or TLS over one. The stream is shared with
/// pending operations, which may complete after the transport is gone.
template <class Stream> class StreamTransport final : public Transport {
  public:
    StreamTransport(std::shared_ptr<Stream> stream, const char* kind,
                    std::shared_ptr<TlsContext> tls = nullptr)
        : mStream(std::move(stream)), mTls(std::move(tls)), mKind(kind) {}

    asio::any_io_executor executor() override { return mStream->get_executor(); }

    void read(ReadHandler handler) override {
        mStream->async_read_some(
            asio::buffer(mBuffer),
            [this, s = mStream, handler = std::move(handler)](const IoError& ec, std::size_t n) {
                if (ec == asio::error::eof || ec == asio::ssl::error::stream_truncated)
                    return handler("peer closed", {});
                if (ec) return handler("read: " + ec.message(), {});
                handler({}, std::span<const std::uint8_t>(mBuffer.data(), n));
            });
    }

    void write(std::span<const std::uint8_t> bytes, WriteHandler handler) override {
        asio::async_write(
            *mStream, asio::buffer(bytes.data(), bytes.size()),
            [s = mStream, handler = std::move(handler)](const IoError& ec, std::size_t n) {
                handler(ec ? "write: " + ec.message() : std::string(), n);
            });
    }

    void close() override {
        IoError ignored;
        mStream->lowest_layer().shutdown(asio::ip::tcp::socket::shutdown_both, ignored);
        mStream->lowest_layer().close(ignored);
    }

    std::string peer() const override { return peerOf(mStream->lowest_layer()); }
    const char* kind() const override { return mKind; }

  private:
    std::shared_ptr<Stream> mStream;
    std::shared_ptr<TlsContext> mTls; ///< outlives the stream that uses it
    const char* mKind;
    std::array<std::uint8_t, 64 * 1024> mBuffer{};
};

} // namespace

std::unique_ptr<Transport> makeTcpTransport(asio::ip::tcp::socket socket) {
    return std::make_unique<StreamTransport<asio::ip::tcp::socket>>(
        std::make_shared<asio::ip::tcp::socket>(std::move(socket)), "tcp");
}

void acceptTls(asio::ip::tcp::socket socket, std::shared_ptr<TlsContext> tls,
               std::uint32_t timeoutMs, Log& log,
               std::function<void(std::unique_ptr<Transport>)> onReady) {
    auto stream = std::make_shared<TlsStream>(std::move(socket), *tls);
    auto timer = std::make_shared<asio::steady_timer>(stream->get_executor());
    timer->expires_after(std::chrono::milliseconds(timeoutMs));
    timer->async_wait([stream](const IoError& ec) {
        IoError ignored;
        if (!ec) stream->lowest_layer().close(ignored);
    });
    stream->async_handshake(
        asio::ssl::stream_base::server,
        [stream, timer, tls, &log, onReady = std::move(onReady)](const IoError& ec) {
            timer->cancel();
            if (ec) {
                log.info("tls: " + peerOf(stream->lowest_layer()) +
                         ": handshake failed: " + ec.message());
                IoError ignored;
                stream->lowest_layer().close(ignored);
                return onReady(nullptr);
            }
            onReady(std::make_unique<StreamTransport<TlsStream>>(stream, "tls", tls));
        });
}

std::string peerOf(const asio::ip::tcp::socket::lowest_layer_type& socket) {
    IoError ec;
    const auto ep = socket.remote_endpoint(ec);
    if (ec) return "?";
    return ep.address().to_string() + ":" + std::to_string(ep.port());
}

std::string addressOf(const std::string& peer) {
    const auto colon = peer.rfind(':');
    return colon == std::string::npos ? peer : peer.substr(0, colon);
}

} // namespace bc::server::detail
