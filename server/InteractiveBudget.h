#pragma once
// Interactive frames on a time budget: while a camera moves, the daemon draws each
// frame at a pyramid level and at the requested size divided by a whole number (1, 2, 3, 4, 6,
// 8), scaled back up, choosing both so that the frame is expected to take at most its share of
// `[frames] interactive_ms`.
//
// What is given up first: image scale, then level. On the shared scans a quarter-size frame at
// level 0 is both faster and closer to the converged image than a full-size frame of level 1
// (docs/benchmarks/budgets.md): a coarser level moves the surfaces the transfer function
// picks out, a smaller image only blurs them. So the candidates are tried level by level, finest
// first, and within a level largest image first; the first expected within the target is drawn,
// except that the level drawn last is kept, at its smallest image, while that is expected within
// twice the target (a level switch loads the new level's bricks: a long frame for every session).
// A level is passed over when its bricks do not fit the volume's share of the host cache whole
// (LevelRange::fits): every frame of it then reloads bricks from the store, and loading, which
// does not shrink with the image, bounds it (the 2.36 GiB mosaic's level 0 under 1 GiB takes
// over a second a frame at any size). A level whose bricks are not resident (LevelRange::warm)
// costs a long first frame to enter (its view's bricks loaded: 1.1-1.3 s for the mosaic's level
// 1 on the dev VM), so it is entered only when kColdEntryFrames frames in a row chose it; until
// then the level drawn last is drawn, at its best image. One late frame (another session's
// load, a busy machine) then costs a few small frames, not a second-long stall of every session.
//
// The model: per (volume, renderer, level), the ms per drawn pixel of the rays alone (a frame's
// drawing time less the time it waited for bricks to load, which is transient for a level that
// fits, and the octree and cell maps built for a new transfer function). The daemon names the
// renderer with its mode where that is not composite ("cpu mip"): a mode's rays cost what
// another's do not, and a switch of mode must not inherit the other's rate. A frame that ran slower
// than predicted is believed at once; a faster one moves the rate half way, so one fast frame
// does not buy a larger image that then runs late. Whatever changes a level's rate changes the
// other levels' by the same factor (the load or the caches changed, not what a level costs
// against another), so that after a slow frame the budget comes back to the levels it left. A
// level not drawn yet is expected at the nearest drawn level's rate, halved per level coarser
// (a ray crosses half the samples) and doubled per level finer. Several sessions moving at once
// share the target: each frame gets target / sharers. Render thread only.
#include <cstdint>
#include <map>
#include <string>
#include <tuple>
#include <vector>

namespace bc::protocol {
struct RenderOptions;
}

namespace bc::server {

struct Volume;

/// The pyramid levels an interactive frame may be drawn at, finest `first` to coarsest `last`.
struct LevelRange {
    std::uint32_t first = 0, last = 0;
    /// Per level: whether its stored bricks (those of one value are never loaded) fit the
    /// volume's host cache share whole. Empty: all do.
    std::vector<bool> fits;
    /// Per level: whether enough of its bricks are resident that a frame of it draws mostly
    /// from memory (LevelRange::kWarmShare). Empty: all are.
    std::vector<bool> warm;
    bool fitting(std::uint32_t level) const { return level >= fits.size() || fits[level]; }
    bool warming(std::uint32_t level) const { return level >= warm.size() || warm[level]; }
    /// A level is warm with this share of its stored bricks' bytes resident (of the host cache
    /// share where the level is larger): a flight's view holds about half of a level's bricks.
    static constexpr double kWarmShare = 0.25;
};

/// The bytes of `level` of `volume` (the last level past it) a host cache can hold: its stored
/// bricks, decompressed, aprons included (a brick of one value is never loaded).
double levelBytes(const Volume& volume, std::uint32_t level);

/// Whether those bytes fit the volume's share of the host cache.
bool levelFits(const Volume& volume, std::uint32_t level);

/// The levels an interactive frame of `volume` asked for with `options` may be drawn at: the
/// one asked for, or under automatic level every level, each marked by whether its stored
/// bricks fit the volume's share of the host cache whole (levelBytes) and whether it is warm.
LevelRange interactiveLevels(const Volume& volume, const protocol::RenderOptions& options);

/// What an interactive frame is drawn at.
struct InteractiveChoice {
    std::uint32_t level = 0;
    std::uint32_t divisor = 2;
    double expectedMs = -1; ///< < 0: nothing known of the volume and renderer
};

class InteractiveBudget {
  public:
    /// The divisors tried, largest image first.
    static constexpr std::uint32_t kDivisors[] = {1, 2, 3, 4, 6, 8};
    /// The divisor when nothing is known yet of a volume and renderer: today's half size.
    static constexpr std::uint32_t kFirstDivisor = 2;
    /// No drawn edge is made shorter than this (unless the request's is).
    static constexpr std::uint32_t kMinEdge = 16;
    /// The level drawn last is kept while its smallest image is expected within this many
    /// times the target (choose()).
    static constexpr double kLevelStickiness = 2.0;
    /// A level not warm (LevelRange::warm) other than the level drawn last is entered when this
    /// many choices in a row wanted it (choose()).
    static constexpr std::uint32_t kColdEntryFrames = 4;

    /// `targetMs` > 0: the time an interactive frame should take, unless choose() is told
    /// another (a session's own target, SetFrameBudget).
    explicit InteractiveBudget(double targetMs);

    double targetMs() const { return mTargetMs; }

    /// The level and divisor of the next interactive frame of `volume` drawn by `renderer` at a
    /// requested `width` x `height`, while `sharers` sessions (>= 1, this one included) draw
    /// interactive frames: the first candidate (finest fitting level, then largest image)
    /// expected within targetMs / sharers, else the coarsest fitting level's smallest image.
    /// Nothing known of the volume and renderer: the finest fitting level at kFirstDivisor.
    /// A level not warm other than the level drawn last is chosen only when the last
    /// kColdEntryFrames - 1 choices wanted it too: until then the level drawn last, its first
    /// image expected within the target, else its smallest.
    /// `targetMs` > 0 replaces targetMs() for this frame.
    InteractiveChoice choose(const std::string& volume, const std::string& renderer,
                             std::uint32_t width, std::uint32_t height, const LevelRange& levels,
                             std::uint32_t sharers = 1, double targetMs = 0);

    /// An interactive frame of `volume` by `renderer` at `level`, `pixels` drawn, took `ms`, of
    /// which `loadMs` went to loading bricks and building what a new transfer function needs
    /// (octrees, cell maps): not to the rays.
    void record(const std::string& volume, const std::string& renderer, std::uint32_t level,
                std::uint64_t pixels, double ms, double loadMs = 0);

    /// The expected ms of a frame of `pixels` at `level` (negative while nothing is known of
    /// the volume and renderer at any level).
    double expectedMs(const std::string& volume, const std::string& renderer, std::uint32_t level,
                      std::uint64_t pixels) const;

    /// The drawn edge for a requested `edge` and `divisor`: ceil(edge / divisor).
    static std::uint32_t drawnEdge(std::uint32_t edge, std::uint32_t divisor) {
        return (edge + divisor - 1) / divisor;
    }

  private:
    using Key = std::tuple<std::string, std::string, std::uint32_t>;
    /// The choice without the cold-level rule: the first candidate within `target` at the
    /// fitting levels, finest first, with the last level's stickiness.
    InteractiveChoice wanted(const std::string& volume, const std::string& renderer,
                             std::uint32_t width, std::uint32_t height,
                             const std::vector<std::uint32_t>& tried, double target) const;
    /// At one level: the first image expected within `target`, else the smallest.
    InteractiveChoice bestAt(const std::string& volume, const std::string& renderer,
                             std::uint32_t width, std::uint32_t height, std::uint32_t level,
                             double target) const;
    /// Choices in a row that wanted a cold level (which one, how many).
    struct ColdStreak {
        std::uint32_t level = 0, count = 0;
    };
    double mTargetMs;
    std::map<Key, double> mMsPerPixel;
    std::map<std::pair<std::string, std::string>, std::uint32_t> mLastLevel;
    std::map<std::pair<std::string, std::string>, ColdStreak> mColdStreak;
};

} // namespace bc::server
