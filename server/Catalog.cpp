#include "server/Catalog.h"

#include "server/Metrics.h"

#include "brickstore/Ingest.h"
#include "brickstore/Readers.h"
#include "server/Error.h"
#include "server/Log.h"

#include <algorithm>
#include <filesystem>

namespace bc::server {

namespace {

protocol::VoxelType wireType(brickstore::VoxelType t) {
    switch (t) {
    case brickstore::VoxelType::U8:
        return protocol::VoxelType::U8;
    case brickstore::VoxelType::U16:
        return protocol::VoxelType::U16;
    case brickstore::VoxelType::I16:
        return protocol::VoxelType::I16;
    case brickstore::VoxelType::F32:
        return protocol::VoxelType::F32;
    }
    return protocol::VoxelType::U8;
}

protocol::VolumeInfo infoOf(const std::string& name, const brickstore::BrickStore& store) {
    const auto& i = store.info();
    protocol::VolumeInfo v;
    v.name = name;
    for (int a = 0; a < 3; ++a) {
        v.dims[a] = std::uint32_t(i.volume.dims[a]);
        v.spacingMm[a] = i.volume.spacingMm[a];
    }
    v.voxelType = wireType(i.volume.type);
    v.levels = std::uint8_t(store.layout().levels().size());
    v.valueMin = i.valueMin;
    v.valueMax = i.valueMax;
    v.storedBytes = i.storedBytes;
    return v;
}

/// The store of a generated entry, ingested on first use (ingest renames a complete store
/// into place, so a half-written one is never picked up).
std::string generatedStore(const CatalogEntry& e, const std::string& storeDir) {
    const auto kind = brickstore::parseSynthKind(e.generate);
    if (!kind) throw std::invalid_argument("unknown generator '" + e.generate + "'");
    std::filesystem::create_directories(storeDir);
    const std::string path =
        (std::filesystem::path(storeDir) /
         (e.generate + "_" + std::to_string(e.dims[0]) + "x" + std::to_string(e.dims[1]) + "x" +
          std::to_string(e.dims[2]) + ".bcs"))
            .string();
    if (std::filesystem::exists(path)) return path;
    auto source = brickstore::makeSynthetic(*kind, e.dims, 1);
    brickstore::ingest(*source, path, {});
    return path;
}

} // namespace

VolumeLease::VolumeLease(Catalog* catalog, std::shared_ptr<Volume> volume)
    : mCatalog(catalog), mVolume(std::move(volume)) {
    if (mVolume) mCatalog->changeSessions(*mVolume, +1);
}

VolumeLease::VolumeLease(VolumeLease&& other) noexcept
    : mCatalog(other.mCatalog), mVolume(std::move(other.mVolume)) {
    other.mVolume.reset();
}

VolumeLease& VolumeLease::operator=(VolumeLease&& other) noexcept {
    if (this != &other) {
        release();
        mCatalog = other.mCatalog;
        mVolume = std::move(other.mVolume);
        other.mVolume.reset();
    }
    return *this;
}

VolumeLease::~VolumeLease() {
    release();
}

void VolumeLease::release() {
    if (mVolume) mCatalog->changeSessions(*mVolume, -1);
    mVolume.reset();
}

Catalog::Catalog(const DaemonConfig& config, Log& log) : mHostBudgetBytes(config.hostBudgetBytes) {
    for (const auto& preset : config.presets)
        mPresets.emplace(preset.name, preset.json);
    for (const auto& entry : config.volumes) {
        if (entry.optional && !entry.store.empty() && !std::filesystem::exists(entry.store)) {
            log.error("catalog: " + entry.name + " left out: optional store " + entry.store +
                      " is missing");
            continue;
        }
        try {
            auto volume = open(entry, config.storeDir);
            mByName[entry.name] = volume;
            mVolumes.push_back(std::move(volume));
            log.info("catalog: " + entry.name + " <- " + mVolumes.back()->store->path());
        } catch (const std::exception& e) {
            throw ConfigError(config.source + ": volume '" + entry.name + "': " + e.what() +
                              (entry.store.empty() || entry.optional
                                   ? ""
                                   : " (optional = true lets the daemon start without a "
                                     "missing store)"));
        }
    }
}

std::shared_ptr<Volume> Catalog::reopen(const CatalogEntry& entry, const std::string& storeDir,
                                        const std::string& verb, CatalogUpdate& update) {
    if (entry.optional && !entry.store.empty() && !std::filesystem::exists(entry.store)) {
        update.log.emplace_back(true, "catalog reload: " + entry.name +
                                          " left out: optional store " + entry.store +
                                          " is missing");
        return nullptr;
    }
    try {
        auto volume = open(entry, storeDir);
        update.log.emplace_back(false, "catalog reload: " + entry.name + " " + verb + " <- " +
                                           volume->store->path());
        return volume;
    } catch (const std::exception& e) {
        update.log.emplace_back(true, "catalog reload: " + entry.name + " left out: " + e.what());
        return nullptr;
    }
}

void CatalogUpdate::writeLog(Log& to) const {
    for (const auto& [error, line] : log)
        error ? to.error(line) : to.info(line);
}

std::map<std::string, std::shared_ptr<Volume>> Catalog::snapshot() const {
    std::lock_guard lock(mMutex);
    return mByName;
}

CatalogUpdate Catalog::prepareReload(std::map<std::string, std::shared_ptr<Volume>> old,
                                     const DaemonConfig& config) {
    CatalogUpdate update;
    for (const auto& entry : config.volumes) {
        const auto it = old.find(entry.name);
        std::shared_ptr<Volume> volume;
        if (it == old.end()) {
            volume = reopen(entry, config.storeDir, "added", update);
        } else {
            const auto failure = it->second->failure();
            const auto change = failure ? std::nullopt : it->second->store->fileChange();
            if (it->second->entry == entry && !change && !failure) {
                volume = it->second;
                ++update.unchanged;
            } else {
                const std::string why = failure  ? "it was out of service"
                                        : change ? "store " + *change
                                                 : "entry changed";
                volume = reopen(entry, config.storeDir, "reopened (" + why + ")", update);
                if (volume)
                    update.reopened.emplace_back(it->second, volume);
                else
                    update.removed.push_back(it->second);
            }
            old.erase(it);
        }
        if (volume) update.volumes.push_back(std::move(volume));
    }
    for (auto& [name, volume] : old) {
        update.log.emplace_back(false, "catalog reload: " + name + " removed");
        update.removed.push_back(std::move(volume));
    }
    for (const auto& preset : config.presets)
        update.presets.emplace(preset.name, preset.json);
    return update;
}

void Catalog::apply(const CatalogUpdate& update, Log& log) {
    update.writeLog(log);
    log.info("catalog reload: " + std::to_string(update.unchanged) + " volume(s) unchanged, " +
             std::to_string(update.volumes.size()) + " served");
    std::lock_guard lock(mMutex);
    mVolumes = update.volumes;
    mByName.clear();
    for (const auto& v : mVolumes)
        mByName[v->name] = v;
    mPresets = update.presets;
    rebalance();
}

bool Catalog::markFailed(Volume& volume, const std::string& why, Log& log) {
    {
        std::lock_guard lock(volume.mFailureMutex);
        if (volume.mFailure) return false;
        volume.mFailure = why;
    }
    log.error("catalog: volume '" + volume.name + "' is out of service: " + why +
              " (its sessions are told; OpenVolume of it is refused until a reload (SIGHUP) "
              "reopens it)");
    return true;
}

std::optional<std::string> Volume::failure() const {
    std::lock_guard lock(mFailureMutex);
    return mFailure;
}

bool sameShape(const Volume& from, const Volume& to) {
    const auto &a = from.info, &b = to.info;
    return a.name == b.name && a.voxelType == b.voxelType && a.dims == b.dims &&
           a.spacingMm == b.spacingMm;
}

std::shared_ptr<Volume> Catalog::open(const CatalogEntry& entry, const std::string& storeDir) {
    const std::string path = entry.store.empty() ? generatedStore(entry, storeDir) : entry.store;
    auto v = std::make_shared<Volume>();
    v->name = entry.name;
    v->entry = entry;
    v->store = brickstore::BrickStore::open(path);
    // No session yet: the cache keeps nothing until a lease gives it a share.
    v->cache = std::make_unique<brickstore::BrickCache>(*v->store, brickstore::BrickCacheConfig{0});
    v->stats = render::VolumeValueStats::fromStore(v->store->info());
    v->info = infoOf(entry.name, *v->store);
    return v;
}

std::size_t Catalog::size() const {
    std::lock_guard lock(mMutex);
    return mVolumes.size();
}

std::vector<protocol::VolumeInfo> Catalog::list() const {
    std::lock_guard lock(mMutex);
    std::vector<protocol::VolumeInfo> out;
    for (const auto& v : mVolumes)
        if (!v->failure()) out.push_back(v->info);
    return out;
}

VolumeLease Catalog::lease(const std::string& name) {
    std::shared_ptr<Volume> volume;
    {
        std::lock_guard lock(mMutex);
        const auto it = mByName.find(name);
        if (it == mByName.end()) return {};
        volume = it->second;
    }
    return VolumeLease(this, std::move(volume));
}

std::uint64_t Catalog::shareOf(const Volume& volume, std::uint64_t totalBytes) const {
    const std::uint32_t all = std::max<std::uint32_t>(mSessions.load(), 1);
    const std::uint32_t mine = std::max<std::uint32_t>(volume.sessions.load(), 1);
    const std::uint64_t m = std::min(mine, all); // floor(total * m / all), without overflow
    return totalBytes / all * m + totalBytes % all * m / all;
}

void Catalog::changeSessions(Volume& volume, int delta) {
    std::lock_guard lock(mMutex);
    volume.sessions += std::uint32_t(delta);
    mSessions += std::uint32_t(delta);
    rebalance();
}

void Catalog::rebalance() {
    for (const auto& v : mVolumes)
        v->cache->setBudgetBytes(v->sessions.load() ? shareOf(*v, mHostBudgetBytes) : 0);
}

bool Catalog::hasPreset(const std::string& name) const {
    return mPresets.count(name) != 0 || render::TransferFunction::isPreset(name);
}

std::vector<std::string> Catalog::presetNames() const {
    std::vector<std::string> names = render::TransferFunction::presetNames();
    for (const auto& [name, json] : mPresets)
        names.push_back(name);
    std::sort(names.begin(), names.end());
    return names;
}

void Catalog::collect(MetricSet& m) const {
    std::lock_guard lock(mMutex);
    m.gauge("volumes_failed",
            "Volumes out of service: their store changed on disk while served (a reload "
            "reopens them)",
            double(std::count_if(mVolumes.begin(), mVolumes.end(),
                                 [](const auto& v) { return v->failure().has_value(); })));
    for (const auto& v : mVolumes) {
        const auto c = v->cache->stats();
        const std::vector<std::pair<std::string, std::string>> l{{"volume", v->name}};
        m.counter("host_cache_hits_total", "Brick requests served from the host cache",
                  double(c.hits), l);
        m.counter("host_cache_misses_total", "Brick requests read from disk and decompressed",
                  double(c.misses), l);
        m.counter("host_cache_evictions_total", "Bricks evicted from the host cache (LRU)",
                  double(c.evictions), l);
        m.counter("host_cache_bytes_loaded_total", "Decompressed bytes read from disk",
                  double(c.bytesLoaded), l);
        m.counter("host_cache_refetches_total",
                  "Misses of bricks the host cache held before and evicted", double(c.refetches),
                  l);
        m.counter("host_cache_bytes_refetched_total",
                  "Bytes read again from disk after their eviction", double(c.bytesRefetched), l);
        m.gauge("host_cache_resident_bytes", "Decompressed bytes resident in the host cache",
                double(c.residentBytes), l);
        m.gauge("host_cache_budget_bytes", "The volume's share of the host budget",
                double(c.budgetBytes), l);
        m.gauge("volume_sessions", "Sessions viewing the volume", double(v->sessions.load()), l);
    }
}

} // namespace bc::server
