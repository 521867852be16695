#include "server/Daemon.h"

#include "server/Catalog.h"
#include "server/ConfigChanges.h"
#include "server/Log.h"
#include "server/Metrics.h"
#include "server/RenderService.h"
#include "server/detail/Acceptor.h"
#include "server/detail/Asio.h"
#include "server/detail/MetricsEndpoint.h"
#include "server/detail/Session.h"
#include "server/detail/Tls.h"
#include "server/detail/WebListener.h"

#include <algorithm>
#include <chrono>
#include <condition_variable>
#include <csignal>
#include <functional>
#include <malloc.h>
#include <map>
#include <memory>
#include <mutex>
#include <thread>
#include <utility>

namespace bc::server {

struct Daemon::Impl {
    Impl(DaemonConfig c, Log& l, bool handleSignals, FrameCluster* cluster)
        : config(std::move(c)), log(l), catalog(config, log), clustered(cluster != nullptr),
          render(RenderServiceConfig{.gpuBudgetBytes = config.gpuBudgetBytes,
                                     .restMs = config.restMs,
                                     .prefetch = config.prefetch,
                                     .classificationBudgetBytes = config.hostBudgetBytes / 8,
                                     .maxFrameSamples = config.maxFrameSamples,
                                     .maxUnslicedSamples = config.maxUnslicedSamples,
                                     .sliceMs = config.sliceMs,
                                     .interactiveMs = config.interactiveMs,
                                     .frameCacheBytes = config.frameCacheBytes,
                                     .cluster = cluster},
                 catalog, log,
                 [this](std::shared_ptr<Volume> v) {
                     asio::post(io, [this, v = std::move(v)] { volumeFailed(v); });
                 }),
          acceptor(io), signals(io), drainTimer(io),
          storeWatch(io), context{config, catalog, render, log,     capabilities(),
                                  {},     {},      0,      nullptr, {}} {
        context.onClosed = [this](std::uint64_t id) { onClosed(id); };
        context.onReady = [this](std::uint64_t) { return authenticated() < config.maxClients; };
        context.authThrottle = &authThrottle;
        context.collect = [this](MetricSet& m) { collect(m); };
        tls = detail::makeTlsContext(config);
        bind();
        if (const auto where = config.webListen()) {
            web = std::make_unique<detail::WebListener>(
                io, where->first, where->second, config, log,
                [this](std::unique_ptr<detail::Transport> t) { startSession(std::move(t)); }, tls);
            log.info("viewer: " + web->url());
        }
        if (!config.metricsHost.empty())
            metrics = std::make_unique<detail::MetricsEndpoint>(
                io, config.metricsHost, config.metricsPort, log,
                [this] {
                    MetricSet m;
                    collect(m);
                    return m.prometheusText();
                },
                config.source);
        if (handleSignals) {
            signals.add(SIGTERM);
            signals.add(SIGINT);
            signals.add(SIGHUP);
            waitForSignal();
        }
    }

    /// SIGHUP reloads the catalog and waits again; SIGTERM and SIGINT drain.
    void waitForSignal() {
        signals.async_wait([this](const IoError& ec, int signal) {
            if (ec) return;
            if (signal == SIGHUP) {
                log.info("signal " + std::to_string(signal) + " (SIGHUP): reloading the catalog");
                reload();
                return waitForSignal();
            }
            log.info("signal " + std::to_string(signal) + ": draining");
            drain();
        });
    }

    ~Impl() {
        if (!reloader.joinable()) return;
        // A reload may wait in a store's open() for as long as its file system likes (a FIFO,
        // a hung network mount): stopping waits a moment, then leaves it behind. The worker
        // holds only what is its own (the channel, a snapshot of the volumes), so it may end
        // after the daemon; its result is dropped.
        std::unique_lock lock(reloadChannel->mutex);
        if (reloadChannel->finished.wait_for(lock, kReloadWaitAtStop,
                                             [&] { return reloadChannel->done; })) {
            lock.unlock();
            reloader.join();
            return;
        }
        reloadChannel->deliver = nullptr;
        lock.unlock();
        log.error("stopping while a catalog reload still waits to open a store: the reload is "
                  "abandoned");
        reloader.detach();
    }

    /// What the reload worker hands the network thread.
    struct PreparedReload {
        DaemonConfig config;
        CatalogUpdate update;
        std::string error; ///< the config failed to load: nothing changes
    };

    /// How a reload's worker reaches the daemon: `deliver` posts its result to the network
    /// thread until the daemon, stopping, clears it.
    struct ReloadChannel {
        std::mutex mutex;
        std::condition_variable finished;
        bool done = false;
        std::function<void(std::shared_ptr<PreparedReload>)> deliver;
    };
    static constexpr auto kReloadWaitAtStop = std::chrono::seconds(1);

    /// Starts a reload: the config file is re-read and its stores opened on a worker thread,
    /// so a slow store stalls no client; the result is applied here (applyReload). A reload
    /// asked for while one runs follows it. Network thread.
    void reload() {
        if (draining) return;
        if (clustered) {
            log.error("reload: refused under MPI (every rank must serve the same catalog); "
                      "restart the job to change it");
            ++reloadsFailed;
            return;
        }
        if (config.file.empty()) {
            log.error("reload: no config file to re-read (serving " + config.source +
                      "); catalog unchanged");
            ++reloadsFailed;
            return;
        }
        if (reloading) {
            reloadAgain = true;
            return;
        }
        reloading = true;
        if (reloader.joinable()) reloader.join(); // it has posted its result: done
        reloadChannel = std::make_shared<ReloadChannel>();
        reloadChannel->deliver = [this](std::shared_ptr<PreparedReload> result) {
            asio::post(io, [this, result] { applyReload(*result); });
        };
        reloader = std::thread(
            [channel = reloadChannel, file = config.file, served = catalog.snapshot()]() mutable {
                auto result = std::make_shared<PreparedReload>();
                try {
                    result->config = DaemonConfig::load(file);
                    result->update = Catalog::prepareReload(std::move(served), result->config);
                } catch (const std::exception& e) {
                    result->error = e.what();
                }
                std::lock_guard lock(channel->mutex);
                channel->done = true;
                if (channel->deliver) channel->deliver(std::move(result));
                channel->finished.notify_all();
            });
    }

    /// Swaps a prepared reload in and tells the sessions (moved or sent an Error). A config
    /// that failed to load is logged and the catalog kept. Network thread.
    void applyReload(const PreparedReload& r) {
        reloading = false;
        if (!r.error.empty()) {
            log.error("reload: " + r.error + "; the old catalog is kept");
            ++reloadsFailed;
        } else if (!draining) {
            ++reloadsApplied;
            if (const auto kept = settingsAReloadKeeps(config, r.config); !kept.empty()) {
                std::string keys;
                for (const auto& k : kept)
                    keys += (keys.empty() ? "" : ", ") + k;
                log.error("reload: " + keys + " changed in " + config.file +
                          ": not applied (a reload changes [[volume]] and [[preset]] only); "
                          "restart the daemon to apply");
            }
            catalog.apply(r.update, log);
            for (auto& [id, s] : std::map(sessions))
                s->followReload(r.update);
        }
        if (std::exchange(reloadAgain, false)) reload();
    }

    /// Each served store is checked for a change on disk (one stat) every kStoreWatchPeriod:
    /// a store rewritten while every brick a view needs is cached would otherwise serve the
    /// old bricks until a load from disk or a reload noticed. A changed one is out of service
    /// (its sessions are told) until a reload reopens it.
    void watchStores() {
        for (const auto& [name, volume] : catalog.snapshot()) {
            if (volume->failure() || !volume->store) continue;
            // Not the change time: a chmod of a served store must not take it out of service
            // (a rewrite that kept the modification time fails the bricks' checksums).
            if (const auto change = volume->store->fileChange(false))
                if (catalog.markFailed(*volume,
                                       volume->store->path() +
                                           ": changed on disk since it was opened: " + *change,
                                       log))
                    volumeFailed(volume);
        }
        storeWatch.expires_after(kStoreWatchPeriod);
        storeWatch.async_wait([this](const IoError& ec) {
            if (!ec && !draining) watchStores();
        });
    }
    static constexpr auto kStoreWatchPeriod = std::chrono::seconds(1);

    /// A volume was taken out of service: its sessions are told. Network thread.
    void volumeFailed(const std::shared_ptr<Volume>& volume) {
        for (auto& [id, s] : std::map(sessions))
            s->volumeFailed(volume);
    }

    /// What every Hello announces; the GPU bit is added per Hello (Session::onHello) while
    /// nothing is known against the GPU renderers.
    std::uint32_t capabilities() const {
        std::uint32_t caps = protocol::kCapCpuRenderer | protocol::kCapContinuous |
                             protocol::kCapFrameBudget | protocol::kCapModesAndClips |
                             protocol::kCapCapping;
        if (!config.token.empty()) caps |= protocol::kCapAuthRequired;
        return caps;
    }

    void bind() {
        detail::listenOn(acceptor, config.listenHost, config.listenPort,
                         config.source + ": listen");
        log.info("listening on " + config.listenHost + ":" + std::to_string(port()) + " (" +
                 std::to_string(catalog.size()) + " volumes, " +
                 (config.token.empty() ? "no token" : "token required") +
                 (tls ? ", TLS: " + config.tlsCert : std::string()) + ")");
        log.info("host brick budget: " + describeHostBudget(config));
    }

    std::uint16_t port() const { return acceptor.local_endpoint().port(); }

    /// Everything the server counts; on the network thread (sessions live there).
    void collect(MetricSet& m) {
        render.collect(m);
        catalog.collect(m);
        if (web) web->collect(m);
        m.gauge("sessions", "Client sessions open", double(sessions.size()));
        std::size_t queued = 0, deepest = 0;
        std::uint64_t bytes = 0, largest = 0;
        for (const auto& [id, s] : sessions) {
            queued += s->queued();
            deepest = std::max(deepest, s->queued());
            bytes += s->queuedBytes();
            largest = std::max(largest, s->queuedBytes());
        }
        m.gauge("write_queue_messages", "Messages waiting in the sessions' write queues",
                double(queued));
        m.gauge("write_queue_messages_max", "The longest session write queue", double(deepest));
        m.gauge("write_queue_bytes", "Bytes waiting in the sessions' write queues", double(bytes));
        m.gauge("write_queue_bytes_max", "The largest session write queue, in bytes",
                double(largest));
        m.counter("connections_accepted_total", "Client connections accepted", double(accepted));
        m.counter("connections_refused_total", "Client connections refused (Busy)",
                  double(refused));
        m.gauge("sessions_unauthenticated", "Connections that have not completed their handshake",
                double(sessions.size() - authenticated()));
        m.counter("connections_unauthenticated_cut_total",
                  "Connections cut before their handshake to make room for a newer one",
                  double(unauthenticatedCut));
        m.counter("auth_failures_total", "Wrong tokens", double(authThrottle.failures()));
        m.counter("catalog_reloads_total", "Catalog reloads applied (SIGHUP)",
                  double(reloadsApplied));
        m.counter("catalog_reload_failures_total",
                  "Catalog reloads that kept the old catalog (the config did not load, or a "
                  "reload is refused: under MPI, or with no config file)",
                  double(reloadsFailed));
        m.counter("auth_delayed_total",
                  "Auths checked late because their address sent wrong tokens before",
                  double(authThrottle.delayed()));
        m.counter("protocol_errors_total", "Error messages sent to clients",
                  double(context.errorsSent));
    }

    void accept() {
        acceptor.async_accept([this](const IoError& ec, asio::ip::tcp::socket socket) {
            if (ec) {
                if (ec != asio::error::operation_aborted) log.error("accept: " + ec.message());
                if (!draining && acceptor.is_open()) accept();
                return;
            }
            IoError ignored;
            socket.set_option(asio::ip::tcp::no_delay(true), ignored);
            if (tls)
                startTls(std::move(socket));
            else
                startSession(detail::makeTcpTransport(std::move(socket)));
            accept();
        });
    }

    /// A TLS handshake, then a session. Handshakes under way have the cap of connections in
    /// their handshake (max_unauthenticated) of their own: one more is closed at once.
    void startTls(asio::ip::tcp::socket socket) {
        if (tlsHandshakes >= config.maxUnauthenticated) {
            ++refused;
            IoError ignored;
            return socket.close(ignored);
        }
        ++tlsHandshakes;
        detail::acceptTls(std::move(socket), tls, config.handshakeTimeoutMs, log,
                          [this](std::unique_ptr<detail::Transport> t) {
                              --tlsHandshakes;
                              if (t) startSession(std::move(t));
                          });
    }

    /// A connection over either transport: a session, or Busy when max_clients sessions have
    /// completed their handshake. Connections still in their handshake have a cap of their
    /// own (max_unauthenticated): the oldest is cut for a newer one, so connections that
    /// never authenticate can neither take an authenticated client's place nor keep one out.
    void startSession(std::unique_ptr<detail::Transport> transport) {
        if (draining) return transport->close();
        auto session = std::make_shared<detail::Session>(std::move(transport), context, ++nextId);
        if (authenticated() >= config.maxClients) {
            ++refused;
            return session->refuseBusy();
        }
        if (sessions.size() - authenticated() >= config.maxUnauthenticated)
            cutOldestUnauthenticated();
        ++accepted;
        sessions[session->id()] = session;
        session->start();
    }

    std::size_t authenticated() const {
        return std::size_t(std::count_if(sessions.begin(), sessions.end(),
                                         [](const auto& s) { return s.second->authenticated(); }));
    }

    void cutOldestUnauthenticated() {
        for (auto& [id, s] : sessions) // by id: the oldest first
            if (!s->authenticated()) {
                ++unauthenticatedCut;
                auto keep = s; // close() erases it from sessions
                return keep->cut("handshake not completed before " +
                                 std::to_string(config.maxUnauthenticated) +
                                 " newer connections came (max_unauthenticated)");
            }
    }

    void onClosed(std::uint64_t id) {
        sessions.erase(id);
        // What a session that backed up its replies held goes back to the system, not only
        // to the allocator's free lists.
        ::malloc_trim(0);
        if (draining && sessions.empty()) io.stop();
    }

    void drain() {
        if (draining) return;
        draining = true;
        IoError ignored;
        acceptor.close(ignored);
        if (web) web->stop();
        signals.cancel(ignored);
        storeWatch.cancel();
        if (metrics) metrics->stop();
        if (sessions.empty()) return io.stop();
        for (auto& [id, s] : std::map(sessions))
            s->shutdown();
        // Sessions close once their Bye is written; a stuck one is cut at the write deadline.
        drainTimer.expires_after(std::chrono::milliseconds(config.writeTimeoutMs + 500));
        drainTimer.async_wait([this](const IoError& ec) {
            if (!ec) io.stop();
        });
    }

    DaemonConfig config;
    Log& log;
    Catalog catalog;
    bool clustered; ///< rank 0 of an MPI job
    // Before the render service: its thread posts finished frames here, so it must be joined
    // (destroyed) while the io_context still exists.
    asio::io_context io;
    RenderService render;
    asio::ip::tcp::acceptor acceptor;
    asio::signal_set signals;
    asio::steady_timer drainTimer;
    asio::steady_timer storeWatch;           ///< watchStores()
    detail::AuthThrottle authThrottle;       ///< wrong tokens, per address, for every session
    std::shared_ptr<detail::TlsContext> tls; ///< the config's certificate; null: no TLS
    std::uint32_t tlsHandshakes = 0;         ///< under way on the protocol's address
    detail::SessionContext context;
    std::map<std::uint64_t, std::shared_ptr<detail::Session>> sessions;
    std::unique_ptr<detail::MetricsEndpoint> metrics;
    std::unique_ptr<detail::WebListener> web; ///< the browser viewer's address, when served
    std::uint64_t nextId = 0, accepted = 0, refused = 0, unauthenticatedCut = 0;
    /// Reloads applied, and those that kept the old catalog.
    std::uint64_t reloadsApplied = 0, reloadsFailed = 0;
    bool draining = false, reloading = false, reloadAgain = false;
    std::thread reloader; ///< the last reload's worker (opens stores off this thread)
    std::shared_ptr<ReloadChannel> reloadChannel; ///< the last reload's
};

Daemon::Daemon(DaemonConfig config, Log& log, bool handleSignals, FrameCluster* cluster)
    : mImpl(std::make_unique<Impl>(std::move(config), log, handleSignals, cluster)) {}

Daemon::~Daemon() = default;

std::uint16_t Daemon::port() const {
    return mImpl->port();
}

std::uint16_t Daemon::webPort() const {
    return mImpl->web ? mImpl->web->port() : 0;
}

std::uint16_t Daemon::metricsPort() const {
    return mImpl->metrics ? mImpl->metrics->port() : 0;
}

void Daemon::run() {
    mImpl->accept();
    mImpl->watchStores();
    if (mImpl->metrics) mImpl->metrics->start();
    if (mImpl->web) mImpl->web->start();
    mImpl->io.run();
    mImpl->sessions.clear();
    mImpl->log.info("stopped");
}

void Daemon::reload() {
    asio::post(mImpl->io, [impl = mImpl.get()] { impl->reload(); });
}

void Daemon::stop() {
    asio::post(mImpl->io, [impl = mImpl.get()] { impl->drain(); });
}

} // namespace bc::server
