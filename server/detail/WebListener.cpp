#include "server/detail/WebListener.h"

#include "server/DaemonConfig.h"
#include "server/Log.h"
#include "server/Metrics.h"
#include "server/detail/Acceptor.h"
#include "server/detail/Tls.h"
#include "server/detail/WebAssets.h"
#include "server/detail/WebHosts.h"
#include "server/detail/WebSocketTransport.h"

#include <boost/asio/ssl.hpp>
#include <boost/beast/core.hpp>
#include <boost/beast/http.hpp>
#include <boost/beast/websocket/rfc6455.hpp>

#include <list>
#include <map>
#include <optional>

namespace bc::server::detail {

namespace beast = boost::beast;
namespace http = beast::http;

const WebAsset* findWebAsset(std::string_view path) {
    for (std::size_t i = 0; i < kWebAssetCount; ++i)
        if (kWebAssets[i].path == path) return &kWebAssets[i];
    return nullptr;
}

namespace {

using TlsStream = asio::ssl::stream<asio::ip::tcp::socket>;

/// What the connection limits see of an HTTP connection, over TCP or TLS.
class HttpPeer {
  public:
    virtual ~HttpPeer() = default;
    virtual const std::string& address() const = 0;
    /// Closes the connection while it waits for a request, to make room for a newer one.
    virtual void cutForNewer() = 0;
};

} // namespace

struct WebListener::Impl {
    Impl(asio::io_context& io, const DaemonConfig& c, Log& l,
         std::function<void(std::unique_ptr<Transport>)> open, std::shared_ptr<TlsContext> t)
        : acceptor(io), config(c), log(l), onOpen(std::move(open)), tls(std::move(t)) {}

    asio::ip::tcp::acceptor acceptor;
    const DaemonConfig& config;
    Log& log;
    std::function<void(std::unique_ptr<Transport>)> onOpen;
    std::shared_ptr<TlsContext> tls;             ///< null: plain HTTP
    std::optional<WebHosts> hosts;               ///< set once the address is bound
    std::size_t open = 0;                        ///< HTTP connections open (not upgraded)
    std::map<std::string, std::size_t> openFrom; ///< by peer address
    /// Connections waiting for (the rest of) a request, the longest waiting first: where a
    /// connection over the limits takes its place from.
    std::list<std::weak_ptr<HttpPeer>> waiting;
    std::map<unsigned, double> responses; ///< by status
    double upgrades = 0, refused = 0, cutForNewer = 0;
    bool stopped = false;
};

namespace {

/// Headers every response carries: the page's scripts come from this server only, and it
/// may only talk to this server.
template <class Body> void secure(http::response<Body>& res) {
    res.set(http::field::server, "brickcastd");
    res.set("X-Content-Type-Options", "nosniff");
    res.set(http::field::cache_control, "no-cache");
    res.set("Content-Security-Policy",
            "default-src 'self'; connect-src 'self'; img-src 'self' blob: data:; "
            "frame-ancestors 'none'; base-uri 'none'; form-action 'none'");
    res.set("Referrer-Policy", "no-referrer");
}

/// One HTTP connection over `Stream`: a TCP socket, or TLS over one (after its handshake).
template <class Stream>
class HttpConnection final : public HttpPeer,
                             public std::enable_shared_from_this<HttpConnection<Stream>> {
  public:
    HttpConnection(Stream stream, std::shared_ptr<WebListener::Impl> listener)
        : mStream(std::move(stream)), mTimer(mStream.get_executor()), mL(std::move(listener)),
          mPeer(peerOf(beast::get_lowest_layer(mStream))), mAddress(addressOf(mPeer)) {
        ++mL->open;
        ++mL->openFrom[mAddress];
    }
    ~HttpConnection() {
        stopWaiting();
        --mL->open;
        if (--mL->openFrom[mAddress] == 0) mL->openFrom.erase(mAddress);
    }

    const std::string& address() const override { return mAddress; }

    void cutForNewer() override {
        ++mL->cutForNewer;
        stopWaiting();
        cut();
    }

    /// Shakes hands first over TLS (within the handshake deadline), then reads requests.
    void start() {
        if constexpr (std::is_same_v<Stream, asio::ip::tcp::socket>) {
            readRequest();
        } else {
            startWaiting();
            cutAfter(mL->config.handshakeTimeoutMs);
            mStream.async_handshake(asio::ssl::stream_base::server,
                                    [self = this->shared_from_this()](const IoError& ec) {
                                        self->mTimer.cancel();
                                        if (ec) return self->cut();
                                        self->readRequest();
                                    });
        }
    }

    void readRequest() {
        startWaiting();
        mParser.emplace();
        mParser->header_limit(WebListener::kMaxHeaderBytes);
        mParser->body_limit(0);
        // The whole request (every header) within the handshake timeout: a client that
        // trickles bytes holds a connection that long at most.
        cutAfter(mL->config.handshakeTimeoutMs);
        http::async_read(mStream, mBuffer, *mParser,
                         [self = this->shared_from_this()](const IoError& ec, std::size_t) {
                             self->mTimer.cancel();
                             self->stopWaiting();
                             self->onRequest(ec);
                         });
    }

  private:
    /// Cuts the connection unless mTimer is cancelled within `ms`.
    void cutAfter(std::uint32_t ms) {
        mTimer.expires_after(std::chrono::milliseconds(ms));
        mTimer.async_wait([weak = this->weak_from_this()](const IoError& ec) {
            if (auto self = weak.lock(); self && !ec) self->cut();
        });
    }

    /// The connection waits for a request (or its TLS handshake): a newer one may take its
    /// place (makeRoom).
    void startWaiting() {
        stopWaiting();
        mWaiting = mL->waiting.insert(mL->waiting.end(), this->weak_from_this());
    }

    void stopWaiting() {
        if (!mWaiting) return;
        mL->waiting.erase(*mWaiting);
        mWaiting.reset();
    }

    void onRequest(const IoError& ec) {
        if (ec == http::error::end_of_stream || ec == asio::error::operation_aborted ||
            !beast::get_lowest_layer(mStream).is_open())
            return cut();
        if (ec == http::error::header_limit)
            return fail(http::status::request_header_fields_too_large,
                        "request headers over " + std::to_string(WebListener::kMaxHeaderBytes) +
                            " bytes");
        if (ec == http::error::body_limit)
            return fail(http::status::payload_too_large, "requests have no body here");
        if (ec) return fail(http::status::bad_request, "malformed request: " + ec.message());
        const auto& req = mParser->get();
        const auto host = req[http::field::host];
        if (auto why = mL->hosts->hostProblem(std::string_view(host.data(), host.size())))
            return fail(http::status::forbidden, *why);
        const std::string_view target(req.target().data(), req.target().size());
        const std::string_view path = target.substr(0, target.find('?'));
        if (beast::websocket::is_upgrade(req)) return upgrade(path);
        if (req.method() != http::verb::get && req.method() != http::verb::head)
            return fail(http::status::method_not_allowed, "only GET and HEAD");
        const WebAsset* asset = findWebAsset(path);
        if (!asset) return notFound(path, req.version(), req.keep_alive());
        http::response<http::span_body<const char>> res{http::status::ok, req.version()};
        res.set(http::field::content_type,
                beast::string_view(asset->contentType.data(), asset->contentType.size()));
        res.body() = {asset->body.data(), asset->body.size()};
        res.prepare_payload();
        if (req.method() == http::verb::head) res.body() = {};
        res.keep_alive(req.keep_alive());
        send(std::move(res));
    }

    void upgrade(std::string_view path) {
        if (path != "/ws") return notFound(path, 11, false);
        const auto& req = mParser->get();
        // A page from another origin must not drive the daemon from its user's browser
        // (cross-site WebSocket hijacking): an Origin, when sent, is this server's own.
        // Browsers always send one; a program that sends none is no page.
        const auto origin = req[http::field::origin];
        const auto host = req[http::field::host];
        if (req.find(http::field::origin) != req.end())
            if (auto why = WebHosts::originProblem(std::string_view(origin.data(), origin.size()),
                                                   std::string_view(host.data(), host.size())))
                return fail(http::status::forbidden, "cross-origin WebSocket refused: " + *why);
        ++mL->upgrades;
        acceptWebSocket(std::move(mStream), mParser->release(), mL->config.handshakeTimeoutMs,
                        mL->log, mL->onOpen);
    }

    void notFound(std::string_view path, unsigned version, bool keepAlive) {
        mL->log.info("web: " + mPeer + ": 404 " + std::string(path.substr(0, 200)));
        respond(http::status::not_found, "not found\n", version, keepAlive);
    }

    /// Answers `status` saying why, then closes.
    void fail(http::status status, const std::string& why) {
        mL->log.info("web: " + mPeer + ": " + std::to_string(unsigned(status)) + " " + why);
        respond(status, why + "\n", 11, false);
    }

    void respond(http::status status, const std::string& text, unsigned version, bool keepAlive) {
        http::response<http::string_body> res{status, version};
        res.set(http::field::content_type, "text/plain; charset=utf-8");
        if (status == http::status::method_not_allowed) res.set(http::field::allow, "GET, HEAD");
        res.body() = text;
        res.prepare_payload();
        res.keep_alive(keepAlive);
        send(std::move(res));
    }

    template <class Body> void send(http::response<Body>&& response) {
        secure(response);
        mL->responses[unsigned(response.result())] += 1;
        auto res = std::make_shared<http::response<Body>>(std::move(response));
        // A reader that stops reading is cut at the write deadline.
        cutAfter(mL->config.writeTimeoutMs);
        http::async_write(mStream, *res,
                          [self = this->shared_from_this(), res](const IoError& ec, std::size_t) {
                              self->mTimer.cancel();
                              if (ec || !res->keep_alive()) return self->cut();
                              self->readRequest();
                          });
    }

    void cut() {
        IoError ignored;
        beast::get_lowest_layer(mStream).shutdown(asio::ip::tcp::socket::shutdown_both, ignored);
        beast::get_lowest_layer(mStream).close(ignored);
    }

    Stream mStream;
    asio::steady_timer mTimer;
    std::shared_ptr<WebListener::Impl> mL;
    std::string mPeer, mAddress;
    std::optional<std::list<std::weak_ptr<HttpPeer>>::iterator> mWaiting;
    beast::flat_buffer mBuffer{WebListener::kMaxHeaderBytes + 1024};
    std::optional<http::request_parser<http::empty_body>> mParser;
};

/// Cuts the connection that has waited longest for its request, of `address` when given.
bool cutLongestWaiting(WebListener::Impl& l, const std::string* address) {
    for (const auto& weak : l.waiting)
        if (auto c = weak.lock(); c && (!address || c->address() == *address)) {
            c->cutForNewer();
            return true;
        }
    return false;
}

/// Whether a connection from `address` may be taken: under both limits, or once the one that
/// waited longest for its request (from that address, when its own limit is the one reached)
/// is cut. A slow client holds a place only until newer ones need it, and one that sends a
/// request at once is served however many slow ones there are.
bool makeRoom(WebListener::Impl& l, const std::string& address) {
    const auto from = l.openFrom.find(address);
    if (from != l.openFrom.end() && from->second >= WebListener::kMaxConnectionsPerAddress &&
        !cutLongestWaiting(l, &address))
        return false;
    return l.open < WebListener::kMaxConnections || cutLongestWaiting(l, nullptr);
}

void accept(const std::shared_ptr<WebListener::Impl>& l) {
    l->acceptor.async_accept([l](const IoError& ec, asio::ip::tcp::socket socket) {
        if (l->stopped) return;
        if (ec) {
            if (ec != asio::error::operation_aborted) l->log.error("web: accept: " + ec.message());
            if (l->acceptor.is_open()) accept(l);
            return;
        }
        if (!makeRoom(*l, addressOf(peerOf(socket)))) {
            ++l->refused; // closed unanswered: answering would cost what the limit saves
        } else {
            IoError ignored;
            socket.set_option(asio::ip::tcp::no_delay(true), ignored);
            if (l->tls)
                std::make_shared<HttpConnection<TlsStream>>(TlsStream(std::move(socket), *l->tls),
                                                            l)
                    ->start();
            else
                std::make_shared<HttpConnection<asio::ip::tcp::socket>>(std::move(socket), l)
                    ->start();
        }
        accept(l);
    });
}

} // namespace

WebListener::WebListener(asio::io_context& io, const std::string& host, std::uint16_t port,
                         const DaemonConfig& config, Log& log,
                         std::function<void(std::unique_ptr<Transport>)> onOpen,
                         std::shared_ptr<TlsContext> tls)
    : mImpl(std::make_shared<Impl>(io, config, log, std::move(onOpen), std::move(tls))) {
    listenOn(mImpl->acceptor, host, port, config.source + ": web");
    mImpl->hosts.emplace(host, mImpl->acceptor.local_endpoint().address(), config.webHosts);
}

WebListener::~WebListener() {
    stop();
}

void WebListener::start() {
    accept(mImpl);
}

void WebListener::stop() {
    mImpl->stopped = true;
    IoError ignored;
    mImpl->acceptor.close(ignored);
}

std::uint16_t WebListener::port() const {
    IoError ec;
    return mImpl->acceptor.local_endpoint(ec).port();
}

std::string WebListener::url() const {
    IoError ec;
    const auto ep = mImpl->acceptor.local_endpoint(ec);
    const std::string host = ep.address().to_string();
    return std::string(mImpl->tls ? "https://" : "http://") +
           (ep.address().is_v6() ? "[" + host + "]" : host) + ":" + std::to_string(ep.port()) + "/";
}

void WebListener::collect(MetricSet& m) const {
    for (const auto& [status, n] : mImpl->responses)
        m.counter("web_responses_total", "HTTP responses of the viewer's address, by status", n,
                  {{"status", std::to_string(status)}});
    m.counter("web_upgrades_total", "WebSocket upgrades asked for", mImpl->upgrades);
    m.counter("web_connections_refused_total",
              "HTTP connections closed unanswered (over the connection limit)", mImpl->refused);
    m.counter("web_connections_cut_total",
              "HTTP connections cut while waiting for a request, to make room for a newer one",
              mImpl->cutForNewer);
    m.gauge("web_connections", "HTTP connections open", double(mImpl->open));
}

} // namespace bc::server::detail
