#include "server/detail/Transport.h"

#include <array>

namespace bc::server::detail {
namespace {

class TcpTransport final : public Transport {
  public:
    explicit TcpTransport(asio::ip::tcp::socket socket) : mSocket(std::move(socket)) {}

    asio::any_io_executor executor() override { return mSocket.get_executor(); }

    void read(ReadHandler handler) override {
        mSocket.async_read_some(asio::buffer(mBuffer), [this, handler = std::move(handler)](
                                                           const IoError& ec, std::size_t n) {
            if (ec)
                return handler(ec == asio::error::eof ? "peer closed" : "read: " + ec.message(),
                               {});
            handler({}, std::span<const std::uint8_t>(mBuffer.data(), n));
        });
    }

    void write(std::span<const std::uint8_t> bytes, WriteHandler handler) override {
        asio::async_write(mSocket, asio::buffer(bytes.data(), bytes.size()),
                          [handler = std::move(handler)](const IoError& ec, std::size_t n) {
                              handler(ec ? "write: " + ec.message() : std::string(), n);
                          });
    }

    void close() override {
        IoError ignored;
        mSocket.shutdown(asio::ip::tcp::socket::shutdown_both, ignored);
        mSocket.close(ignored);
    }

    std::string peer() const override { return peerOf(mSocket); }
    const char* kind() const override { return "tcp"; }

  private:
    asio::ip::tcp::socket mSocket;
    std::array<std::uint8_t, 64 * 1024> mBuffer{};
};

} // namespace

std::unique_ptr<Transport> makeTcpTransport(asio::ip::tcp::socket socket) {
    return std::make_unique<TcpTransport>(std::move(socket));
}

std::string peerOf(const asio::ip::tcp::socket& socket) {
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
