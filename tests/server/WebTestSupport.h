#pragma once
// Speaking to the browser viewer's address from a test: a WebSocket client (the browser's
// part), and raw HTTP requests and their answers.
#include "ServerTestSupport.h"

#include <boost/asio.hpp>
#include <boost/beast/core.hpp>
#include <boost/beast/websocket.hpp>

#include <algorithm>
#include <string>

namespace bc::server::test {

namespace asio = boost::asio;
namespace beast = boost::beast;
namespace websocket = beast::websocket;
using protocol::ErrorCode;

/// A WebSocket client of the viewer's address (Beast, synchronous): the browser's part.
class WsClient {
  public:
    explicit WsClient(std::uint16_t port, const std::string& origin = {}) : mWs(mIo) {
        mWs.next_layer().connect({asio::ip::make_address("127.0.0.1"), port});
        const std::string host = "127.0.0.1:" + std::to_string(port);
        mWs.set_option(websocket::stream_base::decorator([origin](websocket::request_type& r) {
            if (!origin.empty()) r.set(beast::http::field::origin, origin);
        }));
        mWs.handshake(host, "/ws");
        mWs.binary(true);
    }
    void send(const protocol::Message& m, std::uint32_t request = 1) {
        const auto bytes = protocol::encode(m, request);
        mWs.write(asio::buffer(bytes));
    }
    /// The next protocol message; each WebSocket message carries exactly one.
    protocol::Message next() {
        beast::flat_buffer b;
        mWs.read(b);
        const auto data = b.cdata();
        protocol::Decoder d(protocol::kDefaultMaxServerPayloadBytes);
        d.feed({static_cast<const std::uint8_t*>(data.data()), data.size()});
        auto r = d.next();
        if (r.status != protocol::Decoder::Status::Message)
            throw std::runtime_error("not one whole message: " + r.error.message);
        if (d.midMessage()) throw std::runtime_error("bytes after the message");
        return std::move(r.message);
    }
    template <class M> M expect() {
        auto m = next();
        if (auto* e = std::get_if<protocol::Error>(&m))
            throw std::runtime_error("Error: " + e->message);
        return std::get<M>(m);
    }
    void handshake(const std::string& token = {}) {
        send(protocol::Hello{}, 1);
        const auto hello = expect<protocol::Hello>();
        if (std::find(hello.codecs.begin(), hello.codecs.end(), protocol::Codec::Png) ==
            hello.codecs.end())
            throw std::runtime_error("the server does not offer PNG");
        if (token.empty()) return;
        send(protocol::Auth{token}, 2);
        expect<protocol::AuthOk>();
    }
    /// Reads until the server closes; the close code it sent (0 when the TCP connection just
    /// ended).
    int closeCode() {
        try {
            for (;;) {
                beast::flat_buffer b;
                mWs.read(b);
            }
        } catch (const boost::system::system_error&) {
        }
        return int(mWs.reason().code);
    }
    websocket::stream<asio::ip::tcp::socket>& ws() { return mWs; }

  private:
    asio::io_context mIo;
    websocket::stream<asio::ip::tcp::socket> mWs;
};

/// An HTTP request with the headers every test sends.
inline std::string get(const std::string& target, const std::string& extra = {}) {
    return "GET " + target + " HTTP/1.1\r\nHost: 127.0.0.1\r\nConnection: close\r\n" + extra +
           "\r\n";
}

inline int statusOf(const std::string& reply) {
    if (!reply.starts_with("HTTP/1.1 ")) return 0;
    return std::stoi(reply.substr(9, 3));
}

inline std::string bodyOf(const std::string& reply) {
    const auto at = reply.find("\r\n\r\n");
    return at == std::string::npos ? std::string() : reply.substr(at + 4);
}

} // namespace bc::server::test
