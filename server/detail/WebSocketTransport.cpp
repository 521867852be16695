#include "server/detail/WebSocketTransport.h"

#include "protocol/Wire.h"
#include "server/Log.h"

#include <boost/asio/ssl.hpp>
#include <boost/beast/core.hpp>
#include <boost/beast/websocket.hpp>
#include <boost/beast/websocket/ssl.hpp>

#include <chrono>

namespace bc::server::detail {
namespace {

namespace beast = boost::beast;
namespace http = beast::http;
namespace websocket = beast::websocket;
using Clock = std::chrono::steady_clock;

/// How long a closing handshake may take before the socket is closed under it.
constexpr auto kCloseHandshake = std::chrono::seconds(1);

/// One connection's state, shared by the transport and its pending operations (a closing
/// handshake outlives the session). `Stream`: a TCP socket, or a TLS stream over one.
template <class Stream> struct Connection {
    explicit Connection(Stream stream) : ws(std::move(stream)), timer(ws.get_executor()) {}

    /// Closes the socket under the WebSocket: pending operations complete with an error.
    void cut() {
        IoError ignored;
        beast::get_lowest_layer(ws).shutdown(asio::ip::tcp::socket::shutdown_both, ignored);
        beast::get_lowest_layer(ws).close(ignored);
    }

    websocket::stream<Stream> ws;
    beast::flat_buffer buffer;
    asio::steady_timer timer; ///< the handshake's, then the closing handshake's deadline
    websocket::close_code closeCode = websocket::close_code::normal;
    std::string failure; ///< why the transport itself ended the connection (a ping flood)
    Clock::time_point pingWindow;
    unsigned pings = 0;
    bool writing = false, closed = false;
};

template <class Stream> class WebSocketTransport final : public Transport {
  public:
    explicit WebSocketTransport(std::shared_ptr<Connection<Stream>> c)
        : mC(std::move(c)), mPeer(peerOf(beast::get_lowest_layer(mC->ws))) {}
    ~WebSocketTransport() override { close(); }

    asio::any_io_executor executor() override { return mC->ws.get_executor(); }

    void read(ReadHandler handler) override {
        mC->buffer.consume(mC->buffer.size());
        mC->ws.async_read(
            mC->buffer, [c = mC, handler = std::move(handler)](const IoError& ec, std::size_t) {
                if (!c->failure.empty()) return handler(c->failure, {});
                if (ec == websocket::error::closed || ec == asio::error::eof ||
                    ec == asio::error::connection_reset || ec == asio::error::not_connected ||
                    ec == asio::ssl::error::stream_truncated)
                    return handler("peer closed", {}); // a page closed or reloaded
                if (ec == websocket::error::message_too_big)
                    return handler("read: a WebSocket message over " +
                                       std::to_string(c->ws.read_message_max()) + " bytes",
                                   {});
                if (ec) return handler("read: " + ec.message(), {});
                if (!c->ws.got_binary()) {
                    c->closeCode = websocket::close_code::unknown_data;
                    return handler("read: a text message (the protocol's messages are binary)", {});
                }
                const auto data = c->buffer.cdata();
                handler({}, {static_cast<const std::uint8_t*>(data.data()), data.size()});
            });
    }

    void write(std::span<const std::uint8_t> bytes, WriteHandler handler) override {
        mC->writing = true;
        mC->ws.binary(true);
        mC->ws.async_write(
            asio::buffer(bytes.data(), bytes.size()),
            [c = mC, handler = std::move(handler)](const IoError& ec, std::size_t n) {
                c->writing = false;
                handler(ec ? "write: " + ec.message() : std::string(), n);
            });
    }

    /// A closing handshake when nothing is being written (a write cannot overlap it), under a
    /// deadline; else the socket is closed at once.
    void close() override {
        if (mC->closed) return;
        mC->closed = true;
        if (mC->writing || !mC->ws.is_open() || !mC->failure.empty()) return mC->cut();
        mC->timer.expires_after(kCloseHandshake);
        mC->timer.async_wait([c = mC](const IoError& ec) {
            if (!ec) c->cut();
        });
        mC->ws.async_close(mC->closeCode, [c = mC](const IoError&) {
            c->timer.cancel();
            c->cut();
        });
    }

    std::string peer() const override { return mPeer; }
    const char* kind() const override {
        return std::is_same_v<Stream, asio::ip::tcp::socket> ? "websocket" : "websocket+tls";
    }

  private:
    std::shared_ptr<Connection<Stream>> mC;
    std::string mPeer;
};

/// Counts pings; one over kMaxPingsPerSecond in a second ends the connection.
template <class Stream> void limitPings(const std::shared_ptr<Connection<Stream>>& c) {
    c->ws.control_callback([weak = std::weak_ptr<Connection<Stream>>(c)](websocket::frame_type kind,
                                                                         beast::string_view) {
        const auto c = weak.lock();
        if (!c || kind != websocket::frame_type::ping || !c->failure.empty()) return;
        const auto now = Clock::now();
        if (now - c->pingWindow > std::chrono::seconds(1)) {
            c->pingWindow = now;
            c->pings = 0;
        }
        if (++c->pings <= kMaxPingsPerSecond) return;
        c->failure =
            "ping flood: over " + std::to_string(kMaxPingsPerSecond) + " pings in a second";
        asio::post(c->ws.get_executor(), [c] { c->cut(); });
    });
}

} // namespace

template <class Stream>
void acceptWebSocket(Stream stream, UpgradeRequest request, std::uint32_t timeoutMs, Log& log,
                     std::function<void(std::unique_ptr<Transport>)> onOpen) {
    auto c = std::make_shared<Connection<Stream>>(std::move(stream));
    c->ws.read_message_max(protocol::kHeaderBytes + protocol::kMaxClientPayloadBytes);
    c->ws.auto_fragment(false);
    c->ws.set_option(websocket::stream_base::decorator(
        [](websocket::response_type& res) { res.set(http::field::server, "brickcastd"); }));
    limitPings(c);
    c->timer.expires_after(std::chrono::milliseconds(timeoutMs));
    c->timer.async_wait([c](const IoError& ec) {
        if (!ec) c->cut();
    });
    auto req = std::make_shared<UpgradeRequest>(std::move(request));
    c->ws.async_accept(*req, [c, req, &log, onOpen = std::move(onOpen)](const IoError& ec) {
        c->timer.cancel();
        if (ec) {
            log.info("web: " + peerOf(beast::get_lowest_layer(c->ws)) +
                     ": WebSocket handshake refused: " + ec.message());
            return c->cut();
        }
        onOpen(std::make_unique<WebSocketTransport<Stream>>(c));
    });
}

template void acceptWebSocket(asio::ip::tcp::socket, UpgradeRequest, std::uint32_t, Log&,
                              std::function<void(std::unique_ptr<Transport>)>);
template void acceptWebSocket(asio::ssl::stream<asio::ip::tcp::socket>, UpgradeRequest,
                              std::uint32_t, Log&, std::function<void(std::unique_ptr<Transport>)>);

} // namespace bc::server::detail
