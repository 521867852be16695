#pragma once
// brickcastd: accepts clients on the configured address, one network thread (Asio) for all
// sessions and one render thread for all frames. stop() (or SIGTERM/SIGINT when
// handleSignals) drains: no new clients, every session gets Bye, run() returns once they are
// written or the write deadline passes. reload() (or SIGHUP) re-reads the config file and
// opens its stores on a worker thread (Catalog::prepareReload), then swaps the catalog in on
// the network thread (Catalog::apply): sessions on a volume reopened with the same shape move
// to the new store unasked (VolumeOpened, request id 0), sessions on removed volumes or ones
// reopened with another shape get UnknownVolume. A volume whose store changed on disk while
// served is out of service until a reload reopens it; its sessions get RenderFailed once.
#include "server/DaemonConfig.h"

#include <cstdint>
#include <memory>

namespace bc::server {

class FrameCluster;
class Log;

class Daemon {
  public:
    /// Opens the catalog, starts the render thread and binds the listen address. `cluster`
    /// (rank 0 under MPI, outliving the daemon): the raycasters' frames are drawn across
    /// its ranks, and reload() is refused (every rank must serve the same catalog).
    /// @throw ConfigError when the address cannot be bound (naming it) or a volume's store
    /// cannot be opened (Catalog).
    Daemon(DaemonConfig config, Log& log, bool handleSignals = false,
           FrameCluster* cluster = nullptr);
    ~Daemon();
    Daemon(const Daemon&) = delete;
    Daemon& operator=(const Daemon&) = delete;

    /// The bound port (the actual one when the config asked for port 0).
    std::uint16_t port() const;
    /// The metrics endpoint's bound port; 0 when the config has none.
    std::uint16_t metricsPort() const;
    /// The browser viewer's port (DaemonConfig::web), 0 when it is not served.
    std::uint16_t webPort() const;
    /// Serves until stop() or a signal, then drains. Call from one thread.
    void run();
    /// Starts the drain; thread-safe, returns at once.
    void stop();
    /// Starts a catalog reload from config.file (what SIGHUP does); thread-safe, returns at
    /// once, and clients keep being served while the stores are opened. A config that fails
    /// to load is logged and the catalog kept. The destructor waits up to a second for a
    /// reload in progress, then abandons it (logged): a store whose open() hangs delays
    /// neither the clients nor the exit.
    void reload();

  private:
    struct Impl;
    std::unique_ptr<Impl> mImpl;
};

} // namespace bc::server
