#include "server/InteractiveBudget.h"

#include "protocol/Messages.h"
#include "server/Catalog.h"

#include <algorithm>
#include <cmath>
#include <stdexcept>

namespace bc::server {

double levelBytes(const Volume& volume, std::uint32_t level) {
    const auto last = std::uint32_t(volume.store->layout().levels().size() - 1);
    return double(volume.store->storedBricks(std::min(level, last))) *
           double(volume.store->brickBytes());
}

bool levelFits(const Volume& volume, std::uint32_t level) {
    return levelBytes(volume, level) <= double(volume.cache->stats().budgetBytes);
}

LevelRange interactiveLevels(const Volume& volume, const protocol::RenderOptions& o) {
    const brickstore::StoreLayout& layout = volume.store->layout();
    const auto levels = std::uint32_t(layout.levels().size());
    if (o.level != protocol::kLevelAutomatic) {
        const std::uint32_t l = std::min<std::uint32_t>(o.level, levels - 1);
        return {l, l, {}, {}};
    }
    const double share = double(volume.cache->stats().budgetBytes);
    LevelRange range{0, levels - 1, {}, {}};
    for (std::uint32_t l = 0; l < levels; ++l) {
        range.fits.push_back(levelFits(volume, l));
        range.warm.push_back(double(volume.cache->residentBytes(l)) >=
                             LevelRange::kWarmShare * std::min(levelBytes(volume, l), share));
    }
    return range;
}

InteractiveBudget::InteractiveBudget(double targetMs) : mTargetMs(targetMs) {
    if (!(targetMs > 0)) throw std::invalid_argument("interactive frame budget: target ms <= 0");
}

double InteractiveBudget::expectedMs(const std::string& volume, const std::string& renderer,
                                     std::uint32_t level, std::uint64_t pixels) const {
    // The drawn level nearest `level` (the finer one on a tie), scaled by 2 a level.
    const auto from = mMsPerPixel.lower_bound({volume, renderer, 0});
    double rate = -1;
    std::uint32_t nearest = 0;
    for (auto it = from; it != mMsPerPixel.end(); ++it) {
        const auto& [v, r, l] = it->first;
        if (v != volume || r != renderer) break;
        const std::uint32_t distance = l > level ? l - level : level - l;
        if (rate < 0 || distance < (nearest > level ? nearest - level : level - nearest)) {
            rate = it->second;
            nearest = l;
        }
    }
    if (rate < 0) return -1;
    return rate * std::ldexp(1.0, int(nearest) - int(level)) * double(pixels);
}

InteractiveChoice InteractiveBudget::bestAt(const std::string& volume, const std::string& renderer,
                                            std::uint32_t width, std::uint32_t height,
                                            std::uint32_t level, double target) const {
    InteractiveChoice chosen{level, kFirstDivisor, -1};
    for (const std::uint32_t d : kDivisors) {
        // Past the smallest edge allowed, a larger divisor draws no smaller an image.
        if (d > 1 && std::min(drawnEdge(width, d), drawnEdge(height, d)) < kMinEdge) break;
        const std::uint64_t pixels = std::uint64_t(drawnEdge(width, d)) * drawnEdge(height, d);
        chosen = {level, d, expectedMs(volume, renderer, level, pixels)};
        if (chosen.expectedMs <= target) return chosen;
    }
    return chosen;
}

InteractiveChoice InteractiveBudget::wanted(const std::string& volume, const std::string& renderer,
                                            std::uint32_t width, std::uint32_t height,
                                            const std::vector<std::uint32_t>& tried,
                                            double target) const {
    const auto last = mLastLevel.find({volume, renderer});
    InteractiveChoice chosen{tried.front(), kFirstDivisor, -1};
    for (const std::uint32_t level : tried) {
        chosen = bestAt(volume, renderer, width, height, level, target);
        if (chosen.expectedMs <= target) return chosen;
        // The level drawn last is left for a coarser one only when its smallest image is
        // expected over kLevelStickiness x the target: the first frames of a level whose bricks
        // are not resident yet load them, which costs more than a frame a little late.
        if (last != mLastLevel.end() && level == last->second &&
            chosen.expectedMs <= kLevelStickiness * target)
            return chosen;
    }
    return chosen;
}

InteractiveChoice InteractiveBudget::choose(const std::string& volume, const std::string& renderer,
                                            std::uint32_t width, std::uint32_t height,
                                            const LevelRange& levels, std::uint32_t sharers,
                                            double targetMs) {
    // The levels tried: those whose bricks stay resident, or the coarsest when none does.
    std::vector<std::uint32_t> tried;
    for (std::uint32_t l = levels.first; l <= levels.last; ++l)
        if (levels.fitting(l)) tried.push_back(l);
    if (tried.empty()) tried.push_back(levels.last);
    const double target =
        (targetMs > 0 ? targetMs : mTargetMs) / double(std::max<std::uint32_t>(sharers, 1));
    if (expectedMs(volume, renderer, tried.front(), 1) < 0)
        return {tried.front(), kFirstDivisor, -1};
    const InteractiveChoice want = wanted(volume, renderer, width, height, tried, target);
    ColdStreak& streak = mColdStreak[{volume, renderer}];
    const auto last = mLastLevel.find({volume, renderer});
    const bool lastTried = last != mLastLevel.end() &&
                           std::find(tried.begin(), tried.end(), last->second) != tried.end();
    if (!lastTried || want.level == last->second || levels.warming(want.level)) {
        streak = {};
        return want;
    }
    // A cold level: entered once kColdEntryFrames choices in a row have wanted it.
    streak = {want.level, streak.level == want.level ? streak.count + 1 : 1};
    if (streak.count >= kColdEntryFrames) {
        streak = {};
        return want;
    }
    return bestAt(volume, renderer, width, height, last->second, target);
}

void InteractiveBudget::record(const std::string& volume, const std::string& renderer,
                               std::uint32_t level, std::uint64_t pixels, double ms,
                               double loadMs) {
    if (pixels == 0 || !(ms >= 0)) return;
    mLastLevel[{volume, renderer}] = level;
    const double rays = std::max(ms - std::clamp(loadMs, 0.0, ms), 0.0);
    const double rate = std::max(rays, 1e-3) / double(pixels);
    // What was expected of the level: its own rate, or the nearest drawn level's scaled.
    const double before = expectedMs(volume, renderer, level, 1);
    if (before <= 0) {
        mMsPerPixel[{volume, renderer, level}] = rate;
        return;
    }
    const double after = rate > before ? rate : 0.5 * (before + rate);
    mMsPerPixel[{volume, renderer, level}] = after;
    // What changed the level's speed (the machine's load, caches gone cold or warm) changes the
    // other levels' too: they move by the same factor, keeping what each costs against the
    // others. Without it, a level left after one slow frame would keep that frame's rate, and
    // the budget would never come back to it.
    const double factor = after / before;
    for (auto o = mMsPerPixel.lower_bound({volume, renderer, 0});
         o != mMsPerPixel.end() && std::get<0>(o->first) == volume &&
         std::get<1>(o->first) == renderer;
         ++o)
        if (std::get<2>(o->first) != level) o->second *= factor;
}

} // namespace bc::server
