#include "server/detail/MetricsEndpoint.h"

#include "server/detail/Acceptor.h"
#include "server/detail/WebHosts.h"

#include "server/Log.h"

#include <algorithm>
#include <array>
#include <cctype>
#include <chrono>
#include <optional>

namespace bc::server::detail {

namespace {

/// The value of the Host header of a request head, if it has one.
std::optional<std::string> hostHeader(const std::string& head) {
    std::string lower(head);
    std::transform(lower.begin(), lower.end(), lower.begin(),
                   [](unsigned char c) { return char(std::tolower(c)); });
    const auto at = lower.find("\r\nhost:");
    if (at == std::string::npos) return std::nullopt;
    const auto from = head.find_first_not_of(" \t", at + 7), to = head.find("\r\n", at + 2);
    if (from == std::string::npos || from >= to) return std::string();
    return head.substr(from, head.find_last_not_of(" \t", to - 1) + 1 - from);
}

} // namespace

/// One scrape: read the request head, answer, close.
class MetricsEndpoint::Connection : public std::enable_shared_from_this<Connection> {
  public:
    Connection(asio::ip::tcp::socket socket, std::function<std::string()>& body,
               std::shared_ptr<int> open, std::shared_ptr<const WebHosts> hosts)
        : mSocket(std::move(socket)), mTimer(mSocket.get_executor()), mBody(body),
          mOpen(std::move(open)), mHosts(std::move(hosts)) {
        ++*mOpen;
    }
    ~Connection() { --*mOpen; }

    void start() {
        mTimer.expires_after(std::chrono::milliseconds(kRequestTimeoutMs));
        mTimer.async_wait([self = shared_from_this()](const IoError& ec) {
            if (!ec && !self->mAnswered)
                self->answer(408, "Request Timeout", "request not complete within 2 s\n");
        });
        read();
    }

  private:
    void read() {
        mSocket.async_read_some(asio::buffer(mBuffer),
                                [self = shared_from_this()](const IoError& ec, std::size_t n) {
                                    if (ec || self->mAnswered) return self->close();
                                    self->mRequest.append(self->mBuffer.data(), n);
                                    self->onBytes();
                                });
    }

    void onBytes() {
        const auto end = mRequest.find("\r\n\r\n");
        if (end == std::string::npos) {
            if (mRequest.size() > kMaxRequestBytes)
                return answer(431, "Request Header Fields Too Large",
                              "request head over 8192 bytes\n");
            return read();
        }
        const std::string line = mRequest.substr(0, mRequest.find("\r\n"));
        const auto sp1 = line.find(' '), sp2 = line.rfind(' ');
        if (sp1 == std::string::npos || sp2 == sp1 || !line.substr(sp2 + 1).starts_with("HTTP/1."))
            return answer(400, "Bad Request", "malformed request line\n");
        const std::string method = line.substr(0, sp1),
                          target = line.substr(sp1 + 1, sp2 - sp1 - 1);
        const std::string path = target.substr(0, target.find('?'));
        // A browser's request always names the page's host: one whose name was rebound to
        // this address is refused. Scrapers that send no Host are no page.
        if (const auto host = hostHeader(mRequest.substr(0, end + 2)))
            if (auto why = mHosts->hostProblem(*host)) return answer(403, "Forbidden", *why + "\n");
        if (path != "/metrics") return answer(404, "Not Found", "only /metrics is served here\n");
        if (method != "GET" && method != "HEAD")
            return answer(405, "Method Not Allowed", "use GET /metrics\n", "Allow: GET, HEAD\r\n");
        std::string body;
        try {
            body = mBody();
        } catch (const std::exception& e) {
            return answer(500, "Internal Server Error", std::string(e.what()) + "\n");
        }
        answer(200, "OK", method == "HEAD" ? std::string() : body, "",
               "text/plain; version=0.0.4; charset=utf-8", body.size());
    }

    void answer(int status, const char* reason, std::string body, const std::string& extra = "",
                const char* type = "text/plain; charset=utf-8",
                std::size_t length = std::string::npos) {
        mAnswered = true;
        mTimer.cancel();
        mResponse = "HTTP/1.1 " + std::to_string(status) + " " + reason +
                    "\r\nContent-Type: " + type + "\r\nContent-Length: " +
                    std::to_string(length == std::string::npos ? body.size() : length) +
                    "\r\nConnection: close\r\n" + extra + "\r\n" + body;
        // The write is bounded like the read: a scraper that stops reading is cut.
        mTimer.expires_after(std::chrono::milliseconds(kRequestTimeoutMs));
        mTimer.async_wait([self = shared_from_this()](const IoError& ec) {
            if (!ec) self->close();
        });
        asio::async_write(
            mSocket, asio::buffer(mResponse),
            [self = shared_from_this()](const IoError&, std::size_t) { self->close(); });
    }

    void close() {
        IoError ignored;
        mTimer.cancel();
        mSocket.shutdown(asio::ip::tcp::socket::shutdown_both, ignored);
        mSocket.close(ignored);
    }

    asio::ip::tcp::socket mSocket;
    asio::steady_timer mTimer;
    std::function<std::string()>& mBody;
    std::shared_ptr<int> mOpen;
    std::shared_ptr<const WebHosts> mHosts;
    std::array<char, 2048> mBuffer{};
    std::string mRequest, mResponse;
    bool mAnswered = false;
};

MetricsEndpoint::MetricsEndpoint(asio::io_context& io, const std::string& host, std::uint16_t port,
                                 Log& log, std::function<std::string()> body,
                                 const std::string& source)
    : mIo(io), mAcceptor(io), mLog(log), mBody(std::move(body)), mOpen(std::make_shared<int>(0)) {
    listenOn(mAcceptor, host, port, source + ": metrics");
    mHosts = std::make_shared<const WebHosts>(host, mAcceptor.local_endpoint().address(),
                                              std::vector<std::string>{});
    mLog.info("metrics on http://" + host + ":" + std::to_string(this->port()) + "/metrics");
}

MetricsEndpoint::~MetricsEndpoint() = default;

std::uint16_t MetricsEndpoint::port() const {
    return mAcceptor.local_endpoint().port();
}

void MetricsEndpoint::start() {
    accept();
}

void MetricsEndpoint::stop() {
    mStopped = true;
    IoError ignored;
    mAcceptor.close(ignored);
}

void MetricsEndpoint::accept() {
    mAcceptor.async_accept([this](const IoError& ec, asio::ip::tcp::socket socket) {
        if (ec) {
            if (ec != asio::error::operation_aborted) mLog.error("metrics accept: " + ec.message());
            if (!mStopped && mAcceptor.is_open()) accept();
            return;
        }
        if (*mOpen >= kMaxConnections) {
            IoError ignored;
            socket.close(ignored);
        } else {
            std::make_shared<Connection>(std::move(socket), mBody, mOpen, mHosts)->start();
        }
        accept();
    });
}

} // namespace bc::server::detail
