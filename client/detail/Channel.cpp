#include "client/detail/Channel.h"

#include "client/Error.h"

#include <openssl/err.h>
#include <openssl/ssl.h>
#include <openssl/x509v3.h>

#include <arpa/inet.h>
#include <cerrno>
#include <csignal>
#include <cstring>
#include <ctime>
#include <netdb.h>
#include <netinet/in.h>
#include <netinet/tcp.h>
#include <poll.h>
#include <pthread.h>
#include <sys/socket.h>
#include <unistd.h>

namespace bc::client::detail {
namespace {

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

/// Waits until `fd` is readable; false when `timeoutMs` passed first.
bool readable(int fd, std::uint32_t timeoutMs, const std::string& where) {
    pollfd p{fd, POLLIN, 0};
    const int ready = ::poll(&p, 1, int(timeoutMs));
    if (ready < 0 && errno != EINTR) throw ClientError(where + ": poll: " + std::strerror(errno));
    return ready > 0;
}

class TcpChannel final : public Channel {
  public:
    TcpChannel(int fd, std::string where) : mFd(fd), mWhere(std::move(where)) {}
    ~TcpChannel() override { ::close(mFd); }

    void sendAll(std::span<const std::uint8_t> bytes) override {
        std::size_t sent = 0;
        while (sent < bytes.size()) {
            const ssize_t n = ::send(mFd, bytes.data() + sent, bytes.size() - sent, MSG_NOSIGNAL);
            if (n < 0 && errno == EINTR) continue;
            if (n <= 0) throw ClientError(mWhere + ": send: " + std::strerror(errno));
            sent += std::size_t(n);
        }
    }

    std::size_t receive(std::span<std::uint8_t> buffer, std::uint32_t timeoutMs) override {
        if (!readable(mFd, timeoutMs, mWhere))
            throw ClientError(mWhere + ": no reply in " + std::to_string(timeoutMs) + " ms");
        const ssize_t n = ::recv(mFd, buffer.data(), buffer.size(), 0);
        if (n == 0) throw ClientError(mWhere + ": the server closed the connection");
        if (n < 0) {
            if (errno == EINTR || errno == EAGAIN) return 0;
            throw ClientError(mWhere + ": recv: " + std::strerror(errno));
        }
        return std::size_t(n);
    }

  private:
    int mFd;
    std::string mWhere;
};

/// OpenSSL's error queue as text (and emptied).
std::string sslErrors() {
    std::string text;
    while (const unsigned long e = ERR_get_error()) {
        char buf[256];
        ERR_error_string_n(e, buf, sizeof buf);
        text += (text.empty() ? "" : "; ") + std::string(buf);
    }
    return text.empty() ? "unknown TLS error" : text;
}

/// SIGPIPE held back on this thread while it lives: OpenSSL writes with write(2), and a
/// server that has closed must be an error here, not the end of the caller's process.
class NoSigpipe {
  public:
    NoSigpipe() {
        sigset_t pipe;
        sigemptyset(&pipe);
        sigaddset(&pipe, SIGPIPE);
        sigpending(&mPendingBefore);
        pthread_sigmask(SIG_BLOCK, &pipe, &mOld);
    }
    ~NoSigpipe() {
        sigset_t pending;
        sigpending(&pending);
        if (sigismember(&pending, SIGPIPE) && !sigismember(&mPendingBefore, SIGPIPE)) {
            sigset_t pipe;
            sigemptyset(&pipe);
            sigaddset(&pipe, SIGPIPE);
            const timespec none{0, 0};
            sigtimedwait(&pipe, nullptr, &none); // the one our write raised
        }
        pthread_sigmask(SIG_SETMASK, &mOld, nullptr);
    }

  private:
    sigset_t mOld{}, mPendingBefore{};
};

class TlsChannel final : public Channel {
  public:
    TlsChannel(int fd, const ClientConfig& config, std::string where)
        : mFd(fd), mWhere(std::move(where)) {
        mContext.reset(SSL_CTX_new(TLS_client_method()));
        if (!mContext) fail("TLS");
        SSL_CTX_set_min_proto_version(mContext.get(), TLS1_2_VERSION);
        trust(config);
        mSsl.reset(SSL_new(mContext.get()));
        if (!mSsl || SSL_set_fd(mSsl.get(), mFd) != 1) fail("TLS");
        if (config.tlsVerify) checkName(config.host);
        SSL_set_tlsext_host_name(mSsl.get(), config.host.c_str());
        NoSigpipe quiet;
        if (SSL_connect(mSsl.get()) != 1) {
            const long verified = SSL_get_verify_result(mSsl.get());
            if (verified != X509_V_OK)
                fail("TLS handshake: the server's certificate: " +
                     std::string(X509_verify_cert_error_string(verified)));
            fail("TLS handshake");
        }
    }
    ~TlsChannel() override {
        mSsl.reset(); // before the socket it writes to
        ::close(mFd);
    }

    void sendAll(std::span<const std::uint8_t> bytes) override {
        NoSigpipe quiet;
        std::size_t sent = 0;
        while (sent < bytes.size()) {
            std::size_t n = 0;
            if (SSL_write_ex(mSsl.get(), bytes.data() + sent, bytes.size() - sent, &n) != 1)
                fail("send");
            sent += n;
        }
    }

    std::size_t receive(std::span<std::uint8_t> buffer, std::uint32_t timeoutMs) override {
        if (SSL_pending(mSsl.get()) == 0 && !readable(mFd, timeoutMs, mWhere))
            throw ClientError(mWhere + ": no reply in " + std::to_string(timeoutMs) + " ms");
        std::size_t n = 0;
        if (SSL_read_ex(mSsl.get(), buffer.data(), buffer.size(), &n) == 1) return n;
        const int why = SSL_get_error(mSsl.get(), 0);
        if (why == SSL_ERROR_WANT_READ || why == SSL_ERROR_WANT_WRITE) return 0;
        if (why == SSL_ERROR_ZERO_RETURN || (why == SSL_ERROR_SYSCALL && ERR_peek_error() == 0))
            throw ClientError(mWhere + ": the server closed the connection");
        fail("recv");
    }

  private:
    /// Trusts config.tlsCaFile, or the system's CAs; verifies the server unless told not to.
    void trust(const ClientConfig& config) {
        if (!config.tlsVerify) return SSL_CTX_set_verify(mContext.get(), SSL_VERIFY_NONE, nullptr);
        SSL_CTX_set_verify(mContext.get(), SSL_VERIFY_PEER, nullptr);
        const bool loaded = config.tlsCaFile.empty()
                                ? SSL_CTX_set_default_verify_paths(mContext.get()) == 1
                                : SSL_CTX_load_verify_locations(
                                      mContext.get(), config.tlsCaFile.c_str(), nullptr) == 1;
        if (!loaded) fail("TLS: cannot load the CA file '" + config.tlsCaFile + "'");
    }
    /// The certificate must name `host`: an IP address as an IP, anything else as a DNS name.
    void checkName(const std::string& host) {
        X509_VERIFY_PARAM* param = SSL_get0_param(mSsl.get());
        in6_addr any{};
        const bool ip = inet_pton(AF_INET, host.c_str(), &any) == 1 ||
                        inet_pton(AF_INET6, host.c_str(), &any) == 1;
        const int ok = ip ? X509_VERIFY_PARAM_set1_ip_asc(param, host.c_str())
                          : X509_VERIFY_PARAM_set1_host(param, host.c_str(), host.size());
        if (ok != 1) fail("TLS: cannot check the name '" + host + "'");
    }
    [[noreturn]] void fail(const std::string& what) {
        throw ClientError(mWhere + ": " + what + ": " + sslErrors());
    }

    int mFd;
    std::string mWhere;
    std::unique_ptr<SSL_CTX, void (*)(SSL_CTX*)> mContext{nullptr, SSL_CTX_free};
    std::unique_ptr<SSL, void (*)(SSL*)> mSsl{nullptr, SSL_free};
};

} // namespace

std::unique_ptr<Channel> openChannel(const ClientConfig& config, const std::string& where) {
    const int fd = connectTo(config.host, config.port, where);
    if (!config.tls) return std::make_unique<TcpChannel>(fd, where);
    try {
        return std::make_unique<TlsChannel>(fd, config, where);
    } catch (...) {
        ::close(fd);
        throw;
    }
}

} // namespace bc::client::detail
