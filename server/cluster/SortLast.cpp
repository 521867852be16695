#include "server/cluster/SortLast.h"

#include <algorithm>
#include <cstring>
#include <optional>
#include <set>
#include <thread>

namespace bc::server::cluster {

namespace {

using render::Image;
using render::PartialImage;
using render::PixelRect;

PixelRect bandRect(const SortLastFrame& f, std::uint32_t band, std::uint32_t bands) {
    const auto rows = bandRows(f.height, band, bands);
    return {0, rows[0], f.width, rows[1] - rows[0]};
}

/// The piece of rank `r`'s footprint in band `band`, if any.
std::optional<PixelRect> pieceOf(const SortLastFrame& f, std::uint32_t r, std::uint32_t band,
                                 std::uint32_t bands) {
    const render::Footprint& fp = f.footprints[r];
    if (!fp.visible) return std::nullopt;
    const PixelRect b = bandRect(f, band, bands);
    if (b.height == 0) return std::nullopt;
    return render::overlap(fp.rect, b);
}

/// The rect of `image` (lying at `at`) copied out as a tight image.
Image cut(const Image& image, const PixelRect& at, const PixelRect& rect) {
    Image out(rect.width, rect.height);
    for (std::uint32_t y = 0; y < rect.height; ++y)
        std::memcpy(out.pixel(0, y),
                    image.rgba.data() +
                        ((std::size_t(rect.y - at.y + y) * at.width) + (rect.x - at.x)) * 4,
                    std::size_t(rect.width) * 4 * sizeof(float));
    return out;
}

/// The bounding rect of two rects (either may be absent).
std::optional<PixelRect> unite(const std::optional<PixelRect>& a, const PixelRect& b) {
    if (!a) return b;
    const std::uint32_t x0 = std::min(a->x, b.x), y0 = std::min(a->y, b.y);
    const std::uint32_t x1 = std::max(a->x + a->width, b.x + b.width);
    const std::uint32_t y1 = std::max(a->y + a->height, b.y + b.height);
    return PixelRect{x0, y0, x1 - x0, y1 - y0};
}

void check(int code, const char* what) {
    if (code != MPI_SUCCESS) checkMpi(code, std::string("sort-last compositing: ") + what);
}

int countOf(const PixelRect& r) {
    const std::uint64_t floats = r.pixels() * 4;
    if (floats > std::uint64_t(std::numeric_limits<int>::max()))
        throw std::invalid_argument("sort-last compositing: a piece of " +
                                    std::to_string(r.pixels()) + " pixels is too large");
    return int(floats);
}

} // namespace

std::array<std::uint32_t, 2> bandRows(std::uint32_t height, std::uint32_t band,
                                      std::uint32_t bands) {
    const auto at = [&](std::uint32_t b) {
        return std::uint32_t(std::uint64_t(height) * b / bands);
    };
    return {at(band), at(band + 1)};
}

void checkMpi(int code, const std::string& what) {
    if (code == MPI_SUCCESS) return;
    char text[MPI_MAX_ERROR_STRING];
    int length = 0;
    MPI_Error_string(code, text, &length);
    throw ClusterError(what + ": " + std::string(text, std::size_t(length)));
}

void waitForRanks(std::vector<MPI_Request>& requests, const std::vector<int>& peers,
                  const std::vector<bool>& receives, std::chrono::steady_clock::time_point deadline,
                  const std::string& what) {
    for (;;) {
        int done = 0;
        checkMpi(MPI_Testall(int(requests.size()), requests.data(), &done, MPI_STATUSES_IGNORE),
                 what);
        if (done) return;
        if (std::chrono::steady_clock::now() >= deadline) break;
        std::this_thread::yield();
    }
    std::set<int> silent; // a rank may owe several of the requests: named once
    for (std::size_t i = 0; i < requests.size(); ++i) {
        if (requests[i] == MPI_REQUEST_NULL) continue;
        int flag = 0;
        MPI_Test(&requests[i], &flag, MPI_STATUS_IGNORE);
        if (flag) continue;
        silent.insert(peers[i]);
        if (receives[i]) {
            MPI_Cancel(&requests[i]);
            MPI_Request_free(&requests[i]);
        }
    }
    std::string ranks;
    for (int r : silent)
        ranks += (ranks.empty() ? "" : ", ") + std::to_string(r);
    throw ClusterError(what + (silent.size() == 1 ? ": rank " : ": ranks ") + ranks +
                       " did not answer in time");
}

Image compositeDirectSend(MPI_Comm comm, int root, const SortLastFrame& frame,
                          const PartialImage& mine, int tag, std::chrono::milliseconds timeout,
                          CompositeStats& stats) {
    const auto start = std::chrono::steady_clock::now();
    const auto deadline = start + timeout;
    stats = {};
    int rank = 0, size = 0;
    check(MPI_Comm_rank(comm, &rank), "MPI_Comm_rank");
    check(MPI_Comm_size(comm, &size), "MPI_Comm_size");
    const auto n = std::uint32_t(size), me = std::uint32_t(rank);
    if (frame.footprints.size() != n)
        throw std::invalid_argument(
            "sort-last compositing: " + std::to_string(frame.footprints.size()) +
            " footprints for " + std::to_string(n) + " ranks");
    if (root < 0 || root >= size)
        throw std::invalid_argument("sort-last compositing: root " + std::to_string(root));
    for (std::uint32_t r : frame.frontToBack)
        if (r >= n)
            throw std::invalid_argument("sort-last compositing: rank " + std::to_string(r) +
                                        " in the order of " + std::to_string(n));
    const render::Footprint& own = frame.footprints[me];
    if (own.visible && (mine.rect != own.rect || mine.image.width != own.rect.width ||
                        mine.image.height != own.rect.height))
        throw std::invalid_argument("sort-last compositing: rank " + std::to_string(me) +
                                    "'s image is not its footprint");

    // 1. Receives of the pieces of my band, in the order they composite.
    std::vector<PartialImage> pieces;
    std::vector<MPI_Request> requests;
    std::vector<int> peers;
    std::vector<bool> receives;
    std::optional<PixelRect> covered; // the part of my band any piece covers
    pieces.reserve(frame.frontToBack.size());
    for (std::uint32_t r : frame.frontToBack) {
        const auto piece = pieceOf(frame, r, me, n);
        if (!piece) continue;
        covered = unite(covered, *piece);
        if (r == me) {
            pieces.push_back({*piece, cut(mine.image, mine.rect, *piece)});
            continue;
        }
        pieces.push_back({*piece, Image(piece->width, piece->height)});
        requests.emplace_back();
        check(MPI_Irecv(pieces.back().image.rgba.data(), countOf(*piece), MPI_FLOAT, int(r), tag,
                        comm, &requests.back()),
              "MPI_Irecv");
        peers.push_back(int(r));
        receives.push_back(true);
        stats.bytesReceived += piece->pixels() * 16;
    }
    // 2. My pieces of the other bands.
    std::vector<Image> outgoing;
    outgoing.reserve(n);
    for (std::uint32_t band = 0; band < n && own.visible; ++band) {
        if (band == me) continue;
        const auto piece = pieceOf(frame, me, band, n);
        if (!piece) continue;
        outgoing.push_back(cut(mine.image, mine.rect, *piece));
        requests.emplace_back();
        check(MPI_Isend(outgoing.back().rgba.data(), countOf(*piece), MPI_FLOAT, int(band), tag,
                        comm, &requests.back()),
              "MPI_Isend");
        peers.push_back(int(band));
        receives.push_back(false);
        stats.bytesSent += piece->pixels() * 16;
    }
    waitForRanks(requests, peers, receives, deadline, "sort-last compositing: exchanging pieces");
    requests.clear();
    peers.clear();
    receives.clear();

    // 3. My band, front to back (only where a piece lies), to the root.
    Image band;
    if (covered) {
        band = Image(covered->width, covered->height);
        for (const PartialImage& p : pieces)
            render::combineUnder(band, *covered, p, frame.combine);
    }
    if (me != std::uint32_t(root)) {
        if (covered) {
            requests.emplace_back();
            check(MPI_Isend(band.rgba.data(), countOf(*covered), MPI_FLOAT, root, tag, comm,
                            &requests.back()),
                  "MPI_Isend");
            peers.push_back(root);
            receives.push_back(false);
            stats.bytesSent += covered->pixels() * 16;
            waitForRanks(requests, peers, receives, deadline,
                         "sort-last compositing: sending the band to the root");
        }
        stats.ms =
            std::chrono::duration<double, std::milli>(std::chrono::steady_clock::now() - start)
                .count();
        return {};
    }
    // 4. The root gathers every band where a piece lies (the rest stays transparent).
    std::vector<PartialImage> bands(n);
    for (std::uint32_t b = 0; b < n; ++b) {
        std::optional<PixelRect> c;
        for (std::uint32_t r : frame.frontToBack)
            if (const auto piece = pieceOf(frame, r, b, n)) c = unite(c, *piece);
        if (!c) continue;
        if (b == me) {
            bands[b] = {*c, std::move(band)};
            continue;
        }
        bands[b] = {*c, Image(c->width, c->height)};
        requests.emplace_back();
        check(MPI_Irecv(bands[b].image.rgba.data(), countOf(*c), MPI_FLOAT, int(b), tag, comm,
                        &requests.back()),
              "MPI_Irecv");
        peers.push_back(int(b));
        receives.push_back(true);
        stats.bytesReceived += c->pixels() * 16;
    }
    waitForRanks(requests, peers, receives, deadline, "sort-last compositing: gathering the bands");
    Image out(frame.width, frame.height);
    for (const PartialImage& b : bands) {
        if (b.image.width == 0) continue;
        for (std::uint32_t y = 0; y < b.rect.height; ++y)
            std::memcpy(out.pixel(b.rect.x, b.rect.y + y), b.image.pixel(0, y),
                        std::size_t(b.rect.width) * 4 * sizeof(float));
    }
    if (frame.combine == render::PartsCombine::Over) render::clampToUnit(out);
    stats.ms =
        std::chrono::duration<double, std::milli>(std::chrono::steady_clock::now() - start).count();
    return out;
}

} // namespace bc::server::cluster
