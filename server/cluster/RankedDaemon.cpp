#include "server/cluster/RankedDaemon.h"

#include "render/BrickPool.h"
#include "render/Classification.h"
#include "render/EglContext.h"
#include "render/Partition.h"
#include "render/RendererRegistry.h"
#include "render/View.h"
#include "server/Catalog.h"
#include "server/Log.h"
#include "server/RendererCache.h"
#include "server/ViewRequest.h"

#include <algorithm>
#include <array>
#include <cstring>
#include <exception>
#include <map>
#include <memory>
#include <thread>

namespace bc::server::cluster {

namespace {

using Clock = std::chrono::steady_clock;

// An order goes as a fixed header, then its payload (both broadcast from rank 0).
constexpr std::uint32_t kOrderMagic = 0x524f4342; // "BCOR"
enum OrderKind : std::uint32_t { kFrame = 1, kHeartbeatOrder = 2, kStop = 3 };
constexpr std::uint32_t kMaxOrderBytes = 1u << 20;
struct OrderHeader {
    std::uint32_t magic = kOrderMagic, kind = 0, seq = 0, payloadBytes = 0;
};

// What each rank reports to rank 0 after a slice.
constexpr std::size_t kReportErrorBytes = 232;
struct Report {
    double renderMs = 0, samples = 0, bytesSent = 0;
    char error[kReportErrorBytes] = {}; ///< NUL-terminated; empty: drawn
};
static_assert(sizeof(Report) == 256);
// Point-to-point tags: above the compositing's (1 to 30000), below the least MPI_TAG_UB (32767).
constexpr int kReportTag = 32000; ///< a worker's report to rank 0
constexpr int kQuitTag = 32001;   ///< rank 0 to a worker: the cluster failed, end

enum class Wait { Done, TimedOut, Quit };

/// waitUntil for a worker's next order, which also ends when rank 0's quit (`quit`, a posted
/// receive) arrives.
Wait waitForOrder(MPI_Request& request, MPI_Request& quit, Clock::time_point deadline) {
    auto nap = std::chrono::microseconds(50);
    for (;;) {
        int done = 0;
        checkMpi(MPI_Test(&request, &done, MPI_STATUS_IGNORE), "waiting for an order");
        if (done) return Wait::Done;
        checkMpi(MPI_Test(&quit, &done, MPI_STATUS_IGNORE), "waiting for an order");
        if (done) return Wait::Quit;
        if (Clock::now() >= deadline) return Wait::TimedOut;
        std::this_thread::sleep_for(nap);
        nap = std::min(nap * 2, std::chrono::microseconds(2000));
    }
}

/// Waits for `request` (a frame in flight: the thread only yields) until `deadline`: false
/// when it is not complete by then.
bool waitUntil(MPI_Request& request, Clock::time_point deadline, const std::string& what) {
    for (;;) {
        int done = 0;
        checkMpi(MPI_Test(&request, &done, MPI_STATUS_IGNORE), what);
        if (done) return true;
        if (Clock::now() >= deadline) return false;
        std::this_thread::yield();
    }
}

// ---- a slice on one rank ----------------------------------------------------------------------

/// The slice's sort-last frame (footprints clipped to the slice, in its coordinates) and this
/// rank's region of the whole frame, if its part shows in the slice.
struct SliceLayout {
    SortLastFrame frame;
    std::optional<render::PixelRect> mine; ///< in the whole frame's pixels
};

SliceLayout layoutOf(render::PartitionCache& partitions, const brickstore::BrickStore& store,
                     const render::View& view, const render::RenderOptions& options,
                     const render::PixelRect& slice, std::uint32_t ranks, std::uint32_t me) {
    const auto levels = std::uint32_t(store.layout().levels().size());
    const std::uint32_t level = std::min<std::uint32_t>(std::uint32_t(options.level), levels - 1);
    const render::LevelGeometry g = render::LevelGeometry::of(store, level);
    const render::Partition& partition = partitions.get(store, level, ranks);
    SliceLayout s;
    s.frame.width = slice.width;
    s.frame.height = slice.height;
    s.frame.frontToBack = partition.frontToBack(g, view.basis);
    s.frame.combine = render::combineFor(options.mode);
    for (std::uint32_t r = 0; r < ranks; ++r) {
        const render::Footprint whole = render::footprint(g, partition.region(r), view);
        render::Footprint local;
        if (whole.visible)
            if (const auto in = render::overlap(whole.rect, slice)) {
                local.visible = true;
                local.rect = {in->x - slice.x, in->y - slice.y, in->width, in->height};
                if (r == me) s.mine = *in;
            }
        s.frame.footprints.push_back(local);
    }
    return s;
}

/// This rank's part of the slice: drawn by `draw`, or transparent when `draw` throws (the
/// other ranks still composite it; the error is returned).
render::PartialImage drawPart(const SliceLayout& s, std::uint32_t me,
                              const std::function<render::Image(const render::PixelRect&)>& draw,
                              std::exception_ptr& error) {
    render::PartialImage part{s.frame.footprints[me].rect, {}};
    if (!s.mine) return part;
    try {
        part.image = draw(*s.mine);
    } catch (...) {
        error = std::current_exception();
        part.image = render::Image(part.rect.width, part.rect.height);
    }
    return part;
}

std::string messageOf(const std::exception_ptr& error) {
    try {
        std::rethrow_exception(error);
    } catch (const std::exception& e) {
        return e.what();
    } catch (...) {
        return "unknown error";
    }
}

} // namespace

std::uint64_t fingerprint(const std::string& text) {
    std::uint64_t h = 1469598103934665603ull;
    for (unsigned char c : text) {
        h ^= c;
        h *= 1099511628211ull;
    }
    return h;
}

std::optional<std::string> compareStarts(MPI_Comm comm, const RankStart& mine) {
    int ranks = 1;
    MPI_Comm_size(comm, &ranks);
    struct Start {
        std::uint64_t fingerprint;
        char error[248];
    };
    Start me{mine.configFingerprint, {}};
    std::strncpy(me.error, mine.error.c_str(), sizeof me.error - 1);
    std::vector<Start> all(std::size_t(ranks), Start{});
    checkMpi(MPI_Allgather(&me, sizeof(Start), MPI_BYTE, all.data(), sizeof(Start), MPI_BYTE, comm),
             "comparing the ranks' configs");
    std::string why;
    for (int r = 0; r < ranks; ++r) {
        const Start& s = all[std::size_t(r)];
        std::string line;
        if (s.error[0] != '\0')
            line = std::string(s.error, strnlen(s.error, sizeof s.error));
        else if (s.fingerprint != all[0].fingerprint)
            line = "its config differs from rank 0's (every rank must read the same config "
                   "file)";
        if (line.empty()) continue;
        why += (why.empty() ? "" : "; ") + ("rank " + std::to_string(r) + ": " + line);
    }
    if (why.empty()) return std::nullopt;
    return why;
}

// ---- rank 0 -----------------------------------------------------------------------------------

MpiFrameCluster::MpiFrameCluster(MPI_Comm comm, std::chrono::milliseconds timeout, Log& log)
    : mComm(comm), mTimeout(timeout), mLog(log), mLastOrder(Clock::now()) {
    MPI_Comm_size(comm, &mRanks);
}

void MpiFrameCluster::send(std::uint32_t kind, const std::vector<std::uint8_t>& payload) {
    OrderHeader header{kOrderMagic, kind, ++mSeq, std::uint32_t(payload.size())};
    const auto deadline = Clock::now() + mTimeout;
    MPI_Request request = MPI_REQUEST_NULL;
    checkMpi(MPI_Ibcast(&header, sizeof header, MPI_BYTE, 0, mComm, &request),
             "broadcasting an order");
    if (!waitUntil(request, deadline, "broadcasting an order"))
        throw ClusterError("an order's broadcast did not complete within " +
                           std::to_string(mTimeout.count()) + " ms");
    if (!payload.empty()) {
        checkMpi(MPI_Ibcast(const_cast<std::uint8_t*>(payload.data()), int(payload.size()),
                            MPI_BYTE, 0, mComm, &request),
                 "broadcasting an order");
        if (!waitUntil(request, deadline, "broadcasting an order"))
            throw ClusterError("an order's broadcast did not complete within " +
                               std::to_string(mTimeout.count()) + " ms");
    }
    mLastOrder = Clock::now();
}

render::Image MpiFrameCluster::draw(const ClusterOrder& order, const brickstore::BrickStore& store,
                                    const render::View& view, const render::RenderOptions& options,
                                    const DrawPart& drawMine, render::FrameStats& mine,
                                    ClusterFrameStats& cluster) {
    if (mFailure) throw ClusterFailed("the cluster is out of service: " + *mFailure);
    if (!mArmed) throw ClusterFailed("the cluster has not started");
    try {
        send(kFrame, encodeOrder(order));
        const SliceLayout s =
            layoutOf(mPartitions, store, view, options, options.region, ranks(), 0);
        std::exception_ptr error;
        const render::PartialImage part = drawPart(
            s, 0,
            [&](const render::PixelRect& region) {
                render::RenderOptions o = options;
                o.parts = ranks();
                o.part = 0;
                o.region = region;
                return drawMine(o, mine);
            },
            error);
        CompositeStats composite;
        render::Image image = compositeDirectSend(mComm, 0, s.frame, part, int(mSeq % 30000) + 1,
                                                  mTimeout, composite);
        Report report{mine.totalMs, double(mine.samples), double(composite.bytesSent), {}};
        // Each rank's report by a receive of its own (not a gather): a rank that does not
        // answer is named.
        std::vector<Report> reports(std::size_t(mRanks), Report{});
        reports[0] = report;
        std::vector<MPI_Request> requests;
        std::vector<int> peers;
        for (int r = 1; r < mRanks; ++r) {
            requests.push_back(MPI_REQUEST_NULL);
            peers.push_back(r);
            checkMpi(MPI_Irecv(&reports[std::size_t(r)], sizeof(Report), MPI_BYTE, r, kReportTag,
                               mComm, &requests.back()),
                     "gathering the ranks' stats");
        }
        waitForRanks(requests, peers, std::vector<bool>(requests.size(), true),
                     Clock::now() + mTimeout, "gathering the ranks' stats");
        cluster.compositeMs = composite.ms;
        cluster.ranks.clear();
        std::string failed;
        for (int r = 0; r < mRanks; ++r) {
            const Report& p = reports[std::size_t(r)];
            cluster.ranks.push_back(
                {p.renderMs, std::uint64_t(p.samples), std::uint64_t(p.bytesSent)});
            if (r != 0 && p.error[0] != '\0')
                failed += (failed.empty() ? "" : "; ") +
                          ("rank " + std::to_string(r) + ": " +
                           std::string(p.error, strnlen(p.error, kReportErrorBytes)));
        }
        if (error) std::rethrow_exception(error);
        if (!failed.empty()) throw std::runtime_error(failed);
        return image;
    } catch (const ClusterError& e) {
        mFailure = e.what();
        mLog.error("cluster: " + *mFailure + "; frames fail from now on, restart the job");
        throw ClusterFailed(e.what());
    }
}

void MpiFrameCluster::idle() {
    if (!mArmed || mFailure || Clock::now() - mLastOrder < kHeartbeat) return;
    try {
        send(kHeartbeatOrder, {});
    } catch (const ClusterError& e) {
        mFailure = e.what();
        mLog.error("cluster: " + *mFailure + "; frames fail from now on, restart the job");
    }
}

bool MpiFrameCluster::stop() {
    if (mFailure) return false;
    if (!mArmed) return true; // the workers never started serving
    try {
        send(kStop, {});
        return true;
    } catch (const ClusterError& e) {
        mFailure = e.what();
        mLog.error("cluster: stopping the ranks: " + *mFailure);
        return false;
    }
}

void MpiFrameCluster::quitWorkers() {
    std::vector<int> codes(std::size_t(mRanks), 3);
    std::vector<MPI_Request> requests;
    std::vector<int> peers;
    for (int r = 1; r < mRanks; ++r) {
        requests.push_back(MPI_REQUEST_NULL);
        peers.push_back(r);
        MPI_Isend(&codes[std::size_t(r)], 1, MPI_INT, r, kQuitTag, mComm, &requests.back());
    }
    try {
        waitForRanks(requests, peers, std::vector<bool>(requests.size(), false),
                     Clock::now() + mTimeout, "telling the ranks to quit");
    } catch (const ClusterError& e) {
        mLog.error(std::string("cluster: ") + e.what());
    }
}

// ---- the other ranks --------------------------------------------------------------------------

int serveOrders(MPI_Comm comm, Catalog& catalog, const DaemonConfig& config, Log& log) {
    const auto timeout = std::chrono::milliseconds(config.clusterTimeoutMs);
    int me = 0, ranks = 1;
    MPI_Comm_rank(comm, &me);
    MPI_Comm_size(comm, &ranks);
    const std::string who = "rank " + std::to_string(me);
    const auto silence = 2 * timeout + std::chrono::minutes(1);
    // The raycasters that draw parts, made at their first order (the GPU one with the GL
    // context, which a rank that draws on the CPU never makes), and per volume its GPU pool
    // (the rank's GPU budget split among the volumes drawn).
    std::map<std::string, std::unique_ptr<render::Renderer>, std::less<>> renderers;
    std::unique_ptr<render::EglContext> context;
    std::map<const Volume*, std::pair<std::shared_ptr<render::BrickPool>, std::uint64_t>> pools;
    render::ClassificationCache classifications;
    render::PartitionCache partitions;
    std::map<std::string, VolumeLease> leases; // held while the job runs: budgets by use
    // The last transfer function placed, by volume and message (orders repeat it per slice).
    const Volume* tfVolume = nullptr;
    protocol::SetTransferFunction tfMessage;
    std::shared_ptr<const render::TransferFunction> tf;
    std::vector<std::uint8_t> payload;
    // Rank 0's quit after a failure, listened for while waiting for orders; cancelled when
    // this rank stops otherwise (MPI_Finalize wants no receive pending).
    int quitCode = 0;
    MPI_Request quit = MPI_REQUEST_NULL;
    checkMpi(MPI_Irecv(&quitCode, 1, MPI_INT, 0, kQuitTag, comm, &quit), "listening for a quit");
    struct CancelQuit {
        MPI_Request& quit;
        ~CancelQuit() {
            if (quit == MPI_REQUEST_NULL) return;
            MPI_Cancel(&quit);
            MPI_Request_free(&quit);
        }
    } cancelQuit{quit};
    for (;;) {
        OrderHeader header;
        MPI_Request request = MPI_REQUEST_NULL;
        checkMpi(MPI_Ibcast(&header, sizeof header, MPI_BYTE, 0, comm, &request),
                 "waiting for an order");
        const Wait wait = waitForOrder(request, quit, Clock::now() + silence);
        if (wait == Wait::Quit) {
            log.error(who + ": rank 0 ends the job (the cluster failed)");
            return 3;
        }
        if (wait == Wait::TimedOut) {
            log.error(
                who + ": rank 0 has been silent for " +
                std::to_string(std::chrono::duration_cast<std::chrono::seconds>(silence).count()) +
                " s: ending the job");
            return 3;
        }
        if (header.magic != kOrderMagic || header.payloadBytes > kMaxOrderBytes ||
            header.kind < kFrame || header.kind > kStop) {
            log.error(who + ": a malformed order header (magic, kind or size): ending the job");
            return 3;
        }
        if (header.kind == kStop) return 0;
        if (header.kind == kHeartbeatOrder) continue;
        payload.resize(header.payloadBytes);
        checkMpi(MPI_Ibcast(payload.data(), int(payload.size()), MPI_BYTE, 0, comm, &request),
                 "receiving an order");
        if (!waitUntil(request, Clock::now() + timeout, "receiving an order")) {
            log.error(who + ": an order's payload did not arrive: ending the job");
            return 3;
        }
        std::exception_ptr error;
        render::FrameStats stats;
        SliceLayout s;
        render::PartialImage part;
        try {
            const ClusterOrder order = decodeOrder(payload);
            const render::RendererKind* kind =
                render::RendererRegistry::builtin().find(order.renderer);
            if (!kind || !kind->parts)
                throw std::runtime_error("no renderer '" + order.renderer + "' that draws parts");
            auto it = leases.find(order.volume);
            if (it == leases.end()) {
                VolumeLease lease = catalog.lease(order.volume);
                if (!lease) throw std::runtime_error("no volume '" + order.volume + "'");
                it = leases.emplace(order.volume, std::move(lease)).first;
            }
            const Volume& volume = *it->second.volume();
            if (tfVolume != &volume || !(tfMessage == order.tf) || !tf) {
                tf = toTransferFunction(order.tf, volume.stats, catalog.configPresets());
                tfVolume = &volume;
                tfMessage = order.tf;
            }
            render::RenderOptions options = order.options;
            const render::View view =
                render::View::ofDecoded(order.camera, options.width, options.height);
            s = layoutOf(partitions, *volume.store, view, options, options.region,
                         std::uint32_t(ranks), std::uint32_t(me));
            const render::Scene scene{*volume.store, *volume.cache, *tf, classifications};
            auto drawer = renderers.find(order.renderer);
            if (drawer == renderers.end()) {
                if (kind->needsGl && !context) context = std::make_unique<render::EglContext>();
                drawer = renderers.emplace(order.renderer, kind->create()).first;
            }
            render::Renderer& raycaster = *drawer->second;
            if (render::GpuResidency* gpu = raycaster.gpuResidency()) {
                // The volume's share of the rank's GPU budget (by the volumes drawn here, as
                // rank 0 shares by sessions); a new pool only when the share moved by more
                // than an eighth (fitPool, as rank 0's).
                auto& [pool, budget] = pools[&volume];
                const std::uint64_t share = catalog.shareOf(volume, config.gpuBudgetBytes);
                gpu->setSharedPool(fitPool(pool, budget, volume, share));
            }
            options.parts = std::uint32_t(ranks);
            options.part = std::uint32_t(me);
            // A part that fails is composited transparent (the others wait for its pixels).
            part = drawPart(
                s, std::uint32_t(me),
                [&](const render::PixelRect& region) {
                    options.region = region;
                    return raycaster.render(scene, view, options, stats);
                },
                error);
        } catch (...) {
            error = std::current_exception();
        }
        if (s.frame.footprints.empty()) {
            // Not even laid out (an order this rank cannot read): it takes part with nothing;
            // rank 0 times out on the pixels the others expect of it, and the cluster goes
            // out of service (ranks of one config never get here).
            s.frame.width = 1;
            s.frame.height = 1;
            s.frame.footprints.assign(std::size_t(ranks), render::Footprint{});
            s.frame.frontToBack.clear();
        }
        CompositeStats composite;
        compositeDirectSend(comm, 0, s.frame, part, int(header.seq % 30000) + 1, timeout,
                            composite);
        Report report{stats.totalMs, double(stats.samples), double(composite.bytesSent), {}};
        if (error) {
            const std::string why = messageOf(error);
            log.error(who + ": " + why);
            std::strncpy(report.error, why.c_str(), kReportErrorBytes - 1);
        }
        checkMpi(MPI_Isend(&report, sizeof report, MPI_BYTE, 0, kReportTag, comm, &request),
                 "reporting stats");
        if (!waitUntil(request, Clock::now() + timeout, "reporting stats")) {
            log.error(who + ": rank 0 did not take this rank's stats: ending the job");
            return 3;
        }
    }
}

} // namespace bc::server::cluster
