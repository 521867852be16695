#pragma once
// A brickcastd in the test process (its own network and render threads) on a free loopback
// port, over stores ingested into a temporary folder; and helpers to speak raw protocol bytes.
#include "../TestSupport.h"
#include "brickstore/Ingest.h"
#include "brickstore/Readers.h"
#include "client/Client.h"
#include "client/Error.h"
#include "client/Orbit.h"
#include "protocol/Messages.h"
#include "server/Daemon.h"
#include "server/Log.h"

#include <gtest/gtest.h>

#include <cerrno>
#include <cstring>
#include <filesystem>
#include <memory>
#include <netinet/in.h>
#include <optional>
#include <poll.h>
#include <sstream>
#include <sys/inotify.h>
#include <sys/socket.h>
#include <thread>
#include <unistd.h>

namespace bc::server::test {

using bc::test::TempDir;

/// A running daemon; stopped (drained) and joined by the destructor.
struct TestDaemon {
    explicit TestDaemon(DaemonConfig config) {
        config.listenHost = "127.0.0.1";
        config.listenPort = 0;
        daemon = std::make_unique<Daemon>(std::move(config), log);
        port = daemon->port();
        thread = std::thread([this] { daemon->run(); });
    }
    ~TestDaemon() {
        daemon->stop();
        thread.join();
    }
    client::ClientConfig clientConfig(const std::string& token = {}) const {
        client::ClientConfig c;
        c.port = port;
        c.token = token;
        c.timeoutMs = 60000;
        return c;
    }
    Log log{std::getenv("BC_TEST_DAEMON_LOG") == nullptr};
    std::unique_ptr<Daemon> daemon;
    std::uint16_t port = 0;
    std::thread thread;
};

/// A config serving generated volumes (ingested into `dir` once) and nothing else.
inline DaemonConfig generatedConfig(const TempDir& dir,
                                    std::vector<std::pair<std::string, std::uint64_t>> phantoms) {
    DaemonConfig c;
    c.source = "<test>";
    c.storeDir = dir.path().string();
    // Interactive frames at half size, exactly (tests that compare them with direct renders);
    // tests of the frame-time budget set their own.
    c.interactiveMs = 0;
    for (auto& [name, edge] : phantoms) {
        CatalogEntry e;
        e.name = name;
        e.generate = "phantom";
        e.dims = {edge, edge, edge};
        c.volumes.push_back(e);
    }
    return c;
}

/// Header bytes of PROTOCOL.md, any field as given (bad input tests).
inline std::vector<std::uint8_t> rawHeader(std::uint8_t type, std::uint32_t length,
                                           std::uint32_t request = 1,
                                           std::uint32_t magic = 0x54534342,
                                           std::uint8_t version = 1, std::uint16_t flags = 0) {
    std::vector<std::uint8_t> b;
    auto put = [&](std::uint64_t v, int bytes) {
        for (int i = 0; i < bytes; ++i)
            b.push_back(std::uint8_t(v >> (8 * i)));
    };
    put(magic, 4);
    put(version, 1);
    put(type, 1);
    put(flags, 2);
    put(length, 4);
    put(request, 4);
    return b;
}

/// A bare TCP connection speaking raw bytes: for input no well-behaved client sends.
class RawConnection {
  public:
    /// `receiveBuffer` > 0 shrinks SO_RCVBUF (a reader that lets the server's writes stall).
    explicit RawConnection(std::uint16_t port, int receiveBuffer = 0)
        : mDecoder(protocol::kDefaultMaxServerPayloadBytes) {
        mFd = ::socket(AF_INET, SOCK_STREAM | SOCK_CLOEXEC, 0);
        if (receiveBuffer > 0)
            ::setsockopt(mFd, SOL_SOCKET, SO_RCVBUF, &receiveBuffer, sizeof receiveBuffer);
        sockaddr_in a{};
        a.sin_family = AF_INET;
        a.sin_port = htons(port);
        a.sin_addr.s_addr = htonl(INADDR_LOOPBACK);
        if (::connect(mFd, reinterpret_cast<sockaddr*>(&a), sizeof a) != 0)
            throw std::runtime_error("connect failed");
    }
    ~RawConnection() { close(); }
    void close() {
        if (mFd >= 0) ::close(mFd);
        mFd = -1;
    }
    /// Sends bytes; a peer that already closed is not an error here.
    void send(const std::vector<std::uint8_t>& bytes) {
        std::size_t sent = 0;
        while (sent < bytes.size()) {
            const ssize_t n = ::send(mFd, bytes.data() + sent, bytes.size() - sent, MSG_NOSIGNAL);
            if (n <= 0) return;
            sent += std::size_t(n);
        }
    }
    void send(const protocol::Message& m, std::uint32_t request = 1) {
        send(protocol::encode(m, request));
    }
    /// The next message within `timeoutMs`; nullopt when the peer closed or time ran out
    /// (closed() tells which).
    std::optional<protocol::Message> next(std::uint32_t timeoutMs = 10000,
                                          std::uint32_t* request = nullptr) {
        const auto until = std::chrono::steady_clock::now() + std::chrono::milliseconds(timeoutMs);
        for (;;) {
            auto r = mDecoder.next();
            if (r.status == protocol::Decoder::Status::Message) {
                if (request) *request = r.request;
                return std::move(r.message);
            }
            if (r.status == protocol::Decoder::Status::Error) return std::nullopt;
            const auto left = std::chrono::duration_cast<std::chrono::milliseconds>(
                until - std::chrono::steady_clock::now());
            if (left.count() <= 0 || mClosed) return std::nullopt;
            pollfd p{mFd, POLLIN, 0};
            if (::poll(&p, 1, int(left.count())) <= 0) continue;
            std::uint8_t buf[65536];
            const ssize_t n = ::recv(mFd, buf, sizeof buf, 0);
            if (n <= 0) {
                mClosed = true;
                continue;
            }
            mDecoder.feed(std::span<const std::uint8_t>(buf, std::size_t(n)));
        }
    }
    /// The next Error message (skipping others), or nullopt.
    std::optional<protocol::Error> nextError(std::uint32_t timeoutMs = 10000) {
        while (auto m = next(timeoutMs))
            if (auto* e = std::get_if<protocol::Error>(&*m)) return *e;
        return std::nullopt;
    }
    /// Reads (and drops) until the peer closes; false if it is still open after `timeoutMs`.
    bool closedByPeer(std::uint32_t timeoutMs = 10000) {
        while (next(timeoutMs)) {
        }
        return mClosed;
    }
    /// Hello, then Auth when `token` is not empty; expects the server's Hello (and AuthOk).
    void handshake(const std::string& token) {
        protocol::Hello hello;
        send(hello, 1);
        auto reply = next();
        if (!reply || !std::holds_alternative<protocol::Hello>(*reply))
            throw std::runtime_error("no Hello from the server");
        if (token.empty()) return;
        send(protocol::Auth{token}, 2);
        reply = next();
        if (!reply || !std::holds_alternative<protocol::AuthOk>(*reply))
            throw std::runtime_error("no AuthOk from the server");
    }
    bool closed() const { return mClosed; }
    /// The bytes that arrive within `timeoutMs`, raw (an HTTP answer); empty when the peer
    /// closed or nothing came.
    std::string receive(int timeoutMs) {
        pollfd p{mFd, POLLIN, 0};
        if (::poll(&p, 1, timeoutMs) <= 0) return {};
        char buf[4096];
        const ssize_t n = ::recv(mFd, buf, sizeof buf, 0);
        return n > 0 ? std::string(buf, std::size_t(n)) : std::string();
    }
    /// Whether the peer has closed (or reset) the connection, without waiting; what it sent
    /// is dropped.
    bool peerGone() {
        std::uint8_t buf[4096];
        for (;;) {
            const ssize_t n = ::recv(mFd, buf, sizeof buf, MSG_DONTWAIT);
            if (n > 0) continue;
            return n == 0 || (errno != EAGAIN && errno != EWOULDBLOCK);
        }
    }

  private:
    int mFd = -1;
    bool mClosed = false;
    protocol::Decoder mDecoder;
};

/// Sends `request` to a loopback HTTP port and returns everything the server answered.
inline std::string scrape(std::uint16_t port, const std::string& request) {
    const int fd = ::socket(AF_INET, SOCK_STREAM, 0);
    sockaddr_in a{};
    a.sin_family = AF_INET;
    a.sin_port = htons(port);
    a.sin_addr.s_addr = htonl(INADDR_LOOPBACK);
    if (::connect(fd, reinterpret_cast<sockaddr*>(&a), sizeof a) != 0) {
        ::close(fd);
        return "connect failed";
    }
    std::size_t sent = 0;
    while (sent < request.size()) {
        const auto n = ::send(fd, request.data() + sent, request.size() - sent, MSG_NOSIGNAL);
        if (n <= 0) break;
        sent += std::size_t(n);
    }
    std::string reply;
    char buf[4096];
    for (;;) {
        pollfd p{fd, POLLIN, 0};
        if (::poll(&p, 1, 10000) <= 0) break;
        const auto n = ::recv(fd, buf, sizeof buf, 0);
        if (n <= 0) break;
        reply.append(buf, std::size_t(n));
    }
    ::close(fd);
    return reply;
}

/// Watches a folder for any open or read of what is in it.
class OpenWatch {
  public:
    explicit OpenWatch(const std::filesystem::path& folder) {
        mFd = inotify_init1(IN_NONBLOCK | IN_CLOEXEC);
        if (mFd < 0 || inotify_add_watch(mFd, folder.c_str(), IN_OPEN | IN_ACCESS) < 0)
            throw std::runtime_error("inotify: " + std::string(std::strerror(errno)));
    }
    ~OpenWatch() { ::close(mFd); }
    /// Names opened or read since the last call ("." for the folder itself).
    std::vector<std::string> events() {
        std::vector<std::string> names;
        alignas(inotify_event) char buf[4096];
        for (ssize_t n; (n = ::read(mFd, buf, sizeof buf)) > 0;)
            for (char* p = buf; p < buf + n;) {
                const auto* e = reinterpret_cast<const inotify_event*>(p);
                names.emplace_back(e->len ? e->name : ".");
                p += sizeof(inotify_event) + e->len;
            }
        return names;
    }

  private:
    int mFd = -1;
};

/// The server's "sessions" gauge, asked through `c`, once it is `n` or less, or what it still is
/// after `seconds` (asked of the server: reading a stuck client's socket would unstick it).
inline double sessionsDownTo(client::Client& c, double n, int seconds) {
    auto sessions = [&] {
        for (const auto& [name, value] : c.stats())
            if (name == "sessions") return value;
        return -1.0;
    };
    const auto until = std::chrono::steady_clock::now() + std::chrono::seconds(seconds);
    double now = sessions();
    for (; now > n && std::chrono::steady_clock::now() < until; now = sessions())
        std::this_thread::sleep_for(std::chrono::milliseconds(50));
    return now;
}

/// The server's statistic `name` (labels included), asked through `c`; -1 if absent.
inline double serverStat(client::Client& c, const std::string& name) {
    for (const auto& [n, value] : c.stats())
        if (n == name) return value;
    return -1;
}

/// Asks for the statistic `name` until `done(value)` holds or `seconds` have passed; the last
/// value. The server's state is polled, not slept on for a guessed time.
template <typename Done>
double waitForStat(client::Client& c, const std::string& name, Done done, int seconds = 20) {
    const auto until = std::chrono::steady_clock::now() + std::chrono::seconds(seconds);
    double value = serverStat(c, name);
    for (; !done(value) && std::chrono::steady_clock::now() < until; value = serverStat(c, name))
        std::this_thread::sleep_for(std::chrono::milliseconds(10));
    return value;
}

/// Waits until the render thread has nothing left to draw for any session: no frame in
/// progress or owed, no prefetch (the "render_idle" gauge). True when it came.
inline bool renderIdle(client::Client& c, int seconds = 20) {
    return waitForStat(
               c, "render_idle", [](double v) { return v == 1; }, seconds) == 1;
}

/// The value of the sample line `name` (labels included) in a text exposition; -1 if absent.
inline double sampleOf(const std::string& text, const std::string& name) {
    std::istringstream in(text);
    for (std::string line; std::getline(in, line);)
        if (line.starts_with(name + " ")) return std::stod(line.substr(name.size() + 1));
    return -1;
}

/// A camera orbiting a volume at 20 degrees elevation.
inline protocol::SetCamera orbitCamera(const protocol::VolumeInfo& v, double azDeg,
                                       std::uint32_t id) {
    return client::orbitCamera(v, azDeg, 20.0, 1.0, id);
}

/// Small CPU-rendered frames: what most server tests ask for.
inline protocol::RenderOptions smallCpuFrames(std::uint16_t edge = 48) {
    protocol::RenderOptions o;
    o.width = o.height = edge;
    o.renderer = protocol::Renderer::CpuRaycaster;
    o.quality = protocol::Quality::Refined;
    o.codec = protocol::Codec::Zstd;
    return o;
}

} // namespace bc::server::test
