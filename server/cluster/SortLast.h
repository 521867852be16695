#pragma once
// Sort-last compositing over MPI ranks by direct send (render/SCALEOUT.md): rank r
// has drawn part r of a Partition over its footprint; the frame's rows are cut into one band
// per rank, each rank sends every band owner the piece of its image that falls in that band,
// each band owner lays the pieces it receives front to back, and the root gathers the bands.
// Every rank knows every footprint and the order (they follow from the view and the split,
// which every rank computes alike), so every message's size is known before it is sent:
// nothing is negotiated, and a piece no footprint covers is never sent.
#include "render/Composite.h"
#include "render/Partition.h"

#include <mpi.h>

#include <chrono>
#include <cstdint>
#include <stdexcept>
#include <string>
#include <vector>

namespace bc::server::cluster {

/// A rank did not answer in time, or MPI reported an error. what() names the ranks.
class ClusterError : public std::runtime_error {
  public:
    explicit ClusterError(const std::string& what) : std::runtime_error(what) {}
};

/// Returns when `code` is MPI_SUCCESS. @throw ClusterError "what: MPI's text for the code".
void checkMpi(int code, const std::string& what);

/// Waits for `requests` (request i is with rank `peers[i]`; `receives[i]`: it is a receive)
/// until `deadline`. @throw ClusterError "what: rank a did not answer in time" ("ranks a, b ..."),
/// naming the ranks whose requests are not complete (their receives are cancelled first), or "what:
/// MPI's text" when MPI fails.
void waitForRanks(std::vector<MPI_Request>& requests, const std::vector<int>& peers,
                  const std::vector<bool>& receives, std::chrono::steady_clock::time_point deadline,
                  const std::string& what);

/// What every rank knows about one frame: its size, each rank's footprint (footprints[r];
/// not visible: rank r sends nothing) and the ranks front to back (ranks whose part is empty
/// or out of view may be left out).
struct SortLastFrame {
    std::uint32_t width = 0, height = 0;
    std::vector<render::Footprint> footprints;
    std::vector<std::uint32_t> frontToBack;
    /// How the parts combine: over (composite, isosurface), or a projection's raw pixels,
    /// which the root then resolves (render::resolveProjections).
    render::PartsCombine combine = render::PartsCombine::Over;
};

struct CompositeStats {
    double ms = 0.0;                 ///< from the call to the frame at the root
    std::uint64_t bytesSent = 0;     ///< this rank's, pieces and band
    std::uint64_t bytesReceived = 0; ///< this rank's
};

/// Rows [first, end) of the frame's band `band` of `bands` (as even as rows allow).
std::array<std::uint32_t, 2> bandRows(std::uint32_t height, std::uint32_t band,
                                      std::uint32_t bands);

/// Collective over `comm` (every rank calls it with the same frame, root and tag). `mine`: this
/// rank's partial image over frame.footprints[rank].rect (ignored when that is not visible).
/// Returns the composited frame, clamped to [0, 1] (raw for a projection), at `root`, an empty
/// image elsewhere.
/// Messages carry `tag` (distinct per frame in flight). @throw ClusterError when a message
/// has not arrived within `timeout` (naming the ranks it waits for) or MPI fails; the
/// communicator is not usable for further frames after that. std::invalid_argument when the
/// frame does not match the communicator or `mine` its footprint.
render::Image compositeDirectSend(MPI_Comm comm, int root, const SortLastFrame& frame,
                                  const render::PartialImage& mine, int tag,
                                  std::chrono::milliseconds timeout, CompositeStats& stats);

} // namespace bc::server::cluster
