#pragma once
// brickcastd over MPI ranks (render/SCALEOUT.md "The daemon over ranks"). Rank 0 runs the
// daemon (sessions, protocol, viewer, encoding) and hands each frame of the CPU or GPU
// raycaster, slice by slice, to an MpiFrameCluster: it broadcasts an order (ClusterOrder.h: the
// camera and options as rank 0 resolved them, the slice, the transfer function), every rank draws
// its part of the volume, and the parts are composited by direct send (SortLast.h). Ranks other
// than 0 run serveOrders(): no sockets, a catalog of their own from the same config, one render
// loop.
//
// Liveness: rank 0 sends a heartbeat order at least every kHeartbeat while idle; a worker that
// hears nothing from rank 0 for its silence limit ends. Rank 0 waits for every message of a
// frame at most the timeout: a rank that died or stopped answering fails that frame
// (RenderFailed to its client, naming the rank) and every cluster frame after it at once; the
// front end goes on serving, and the job ends (MPI_Abort) when rank 0 is stopped. Under OpenMPI,
// `mpirun --enable-recovery` keeps rank 0 alive when another rank dies; without it mpirun ends
// every rank.
#include "server/FrameCluster.h"
#include "server/cluster/SortLast.h"

#include <mpi.h>

#include <atomic>
#include <chrono>
#include <cstdint>
#include <optional>
#include <string>

namespace bc::server {
class Catalog;
struct DaemonConfig;
class Log;
} // namespace bc::server

namespace bc::server::cluster {

/// How often an idle rank 0 tells the workers it lives.
inline constexpr auto kHeartbeat = std::chrono::seconds(1);

/// What a rank knows of the job at start-up: a fingerprint of its config and whether it
/// could open its catalog.
struct RankStart {
    std::uint64_t configFingerprint = 0;
    std::string error; ///< empty: the catalog opened
};

/// Collective over `comm`: every rank's start compared. Returns nullopt when every rank has
/// the same config fingerprint and opened its catalog; else, at every rank, the error naming
/// each rank at fault ("rank 2: config differs from rank 0's", "rank 1: <its error>").
/// @throw ClusterError when MPI fails.
std::optional<std::string> compareStarts(MPI_Comm comm, const RankStart& mine);

/// A fingerprint of the config text every rank must share (FNV-1a of the bytes).
std::uint64_t fingerprint(const std::string& text);

/// Rank 0's FrameCluster.
class MpiFrameCluster : public FrameCluster {
  public:
    MpiFrameCluster(MPI_Comm comm, std::chrono::milliseconds timeout, Log& log);
    std::uint32_t ranks() const override { return std::uint32_t(mRanks); }
    render::Image draw(const ClusterOrder& order, const brickstore::BrickStore& store,
                       const render::View& view, const render::RenderOptions& options,
                       const DrawPart& drawMine, render::FrameStats& mine,
                       ClusterFrameStats& cluster) override;
    void idle() override;
    /// From now on idle() sends heartbeats: call once every rank has started (after
    /// compareStarts), so that no order crosses the start-up's collectives.
    void arm() { mArmed = true; }
    /// Tells every worker to stop (after the render thread has ended). False when the
    /// cluster had failed (nothing is sent: the caller ends the job with MPI_Abort).
    bool stop();
    /// After a failure: tells each worker still listening to end (a message of its own, not
    /// an order: the broadcast tree may pass through the rank at fault), waiting at most the
    /// cluster timeout for the sends. Call before MPI_Abort, which under `mpirun
    /// --enable-recovery` ends only the caller and would leave the others serving nothing.
    void quitWorkers();
    /// Why the cluster is out of service, if it is.
    const std::optional<std::string>& failure() const { return mFailure; }

  private:
    void send(std::uint32_t kind, const std::vector<std::uint8_t>& payload);

    MPI_Comm mComm;
    int mRanks = 1;
    std::chrono::milliseconds mTimeout;
    Log& mLog;
    std::uint32_t mSeq = 0;
    std::chrono::steady_clock::time_point mLastOrder;
    std::optional<std::string> mFailure;
    std::atomic<bool> mArmed{false};
    render::PartitionCache mPartitions;
};

/// A worker rank's life: draws its part of every order from `catalog`'s volumes until rank 0
/// says stop (returns 0), tells it to quit after a failure (MpiFrameCluster::quitWorkers;
/// returns 3, logged) or is silent for twice `config`'s cluster timeout plus a minute
/// (returns 3, logged). The CPU and GPU raycasters draw parts; the GPU one on a GL context
/// made at the first GPU order, with the rank's GPU budget.
/// An order it cannot draw (an unknown volume, a store error) is composited as an empty part
/// and its error goes back to rank 0 with its stats. @throw ClusterError when MPI fails or a
/// message of a frame does not arrive in time: the caller ends this rank without MPI_Finalize
/// (which would wait for the rank that failed) and without MPI_Abort (which would end rank 0,
/// which goes on answering its clients).
int serveOrders(MPI_Comm comm, Catalog& catalog, const DaemonConfig& config, Log& log);

} // namespace bc::server::cluster
