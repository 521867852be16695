#pragma once
// The volumes a daemon serves, by name (clients never send paths). Every entry is opened at
// start-up: brick stores as they are, generated entries ingested once into the store folder
// and reused after. An entry that fails to open stops the start (ConfigError naming it),
// except a store marked optional that is missing: logged and left out. A reload (SIGHUP)
// applies a new config: volumes added, removed, reopened when their store file changed, in two
// halves: the stores are opened off the network thread, then swapped in on it. A volume whose
// store changes on disk while served is taken out of service (markFailed) until a reload.
// Sessions hold a VolumeLease while they view a volume: the host budget is split among the
// volumes in proportion to their sessions, so every session gets a fair share.
#include "brickstore/BrickCache.h"
#include "brickstore/BrickStore.h"
#include "protocol/Messages.h"
#include "render/TransferFunction.h"
#include "server/DaemonConfig.h"

#include <atomic>
#include <map>
#include <memory>
#include <mutex>
#include <optional>
#include <string>
#include <vector>

namespace bc::server {

class Log;

/// An opened catalog entry. The store and cache are thread-safe; `sessions` is how many
/// sessions hold a lease on it.
struct Volume {
    std::string name;
    CatalogEntry entry; ///< as configured; a reload compares it
    std::unique_ptr<brickstore::BrickStore> store;
    std::unique_ptr<brickstore::BrickCache> cache;
    render::VolumeValueStats stats;
    protocol::VolumeInfo info;
    std::atomic<std::uint32_t> sessions{0};

    /// Why the volume is out of service (Catalog::markFailed), or nullopt while it serves.
    /// Thread-safe.
    std::optional<std::string> failure() const;

  private:
    friend class Catalog;
    mutable std::mutex mFailureMutex;
    std::optional<std::string> mFailure;
};

/// Whether a session viewing `from` can be moved to `to` without asking its client: the same
/// name, voxel type, dims and spacing, so its camera and transfer function still fit.
bool sameShape(const Volume& from, const Volume& to);

/// A reload's volumes, opened off the network thread (Catalog::prepareReload) and swapped in on
/// it (Catalog::apply).
struct CatalogUpdate {
    std::vector<std::shared_ptr<Volume>> volumes; ///< in config order
    std::vector<std::shared_ptr<Volume>> removed; ///< no longer served (or failed to reopen)
    /// Volumes reopened (entry or store file changed, or out of service): old, new.
    std::vector<std::pair<std::shared_ptr<Volume>, std::shared_ptr<Volume>>> reopened;
    std::map<std::string, std::string> presets;
    std::size_t unchanged = 0;
    /// What the reload has to say (a line per volume added, reopened, removed or left out;
    /// error: true), written to the daemon's Log by Catalog::apply: the worker that opens the
    /// stores may outlive a daemon that stopped while it waited, and with it that Log.
    std::vector<std::pair<bool, std::string>> log;
    void writeLog(Log& to) const;
};

class Catalog;
class MetricSet;

/// A session's hold on a volume; releasing it rebalances the budgets. Move-only.
class VolumeLease {
  public:
    VolumeLease() = default;
    VolumeLease(Catalog* catalog, std::shared_ptr<Volume> volume);
    VolumeLease(VolumeLease&& other) noexcept;
    VolumeLease& operator=(VolumeLease&& other) noexcept;
    ~VolumeLease();
    const std::shared_ptr<Volume>& volume() const { return mVolume; }
    explicit operator bool() const { return mVolume != nullptr; }

  private:
    void release();
    Catalog* mCatalog = nullptr;
    std::shared_ptr<Volume> mVolume;
};

class Catalog {
  public:
    /// Opens (and generates) every entry of `config`.
    /// @throw ConfigError naming the volume and its store when one cannot be opened (missing,
    /// unreadable, failing its header or index check), unless it is optional and missing.
    Catalog(const DaemonConfig& config, Log& log);

    /// The first half of a reload to `config`'s volumes and presets (other settings need a
    /// restart): opens added volumes and reopens those whose entry or store file changed or
    /// that are out of service (a new store instance); logs one line per volume added,
    /// reopened, removed or left out. A volume that fails to open is left out (logged); the others
    /// still apply. Touches nothing served: call it off the network thread (opening a store
    /// reads its index; a generated one may be ingested). One reload at a time. Static: it
    /// works on `served` (a snapshot()) alone, so a worker may go on after the catalog is gone.
    static CatalogUpdate prepareReload(std::map<std::string, std::shared_ptr<Volume>> served,
                                       const DaemonConfig& config);
    /// The volumes served now, by name.
    std::map<std::string, std::shared_ptr<Volume>> snapshot() const;
    /// The second half: serves `update`'s volumes and presets from now on; logs update.log and
    /// one line with the counts. Sessions on update.removed and on the old side
    /// of update.reopened must be told (moved or sent an Error). Network thread (the one that
    /// leases).
    void apply(const CatalogUpdate& update, Log& log);

    /// Takes `volume` out of service: its store changed on disk while served (`why` names the
    /// store and the change). OpenVolume of it is refused and ListVolumes leaves it out until
    /// a reload reopens it; logs one line. Returns true on the first call only (later calls
    /// keep the first reason). Thread-safe.
    bool markFailed(Volume& volume, const std::string& why, Log& log);

    /// The served volumes, in config order (those out of service left out).
    std::vector<protocol::VolumeInfo> list() const;
    /// A lease on `name`, or an empty lease when the catalog has no such volume (one out of
    /// service is leased: the caller checks Volume::failure()).
    VolumeLease lease(const std::string& name);
    std::size_t size() const;
    /// Sessions holding a lease, over all volumes.
    std::uint32_t sessions() const { return mSessions.load(); }
    /// A volume's fair share of `totalBytes`: in proportion to its sessions (at least one).
    std::uint64_t shareOf(const Volume& volume, std::uint64_t totalBytes) const;
    /// Presets the config added ([[preset]]): name -> JSON text, read at start-up and at each
    /// reload. Network thread only (apply() runs there too).
    const std::map<std::string, std::string>& configPresets() const { return mPresets; }
    /// Whether a client may name `name` as a preset: a built-in one or the config's.
    bool hasPreset(const std::string& name) const;
    /// Every preset a client may name, sorted.
    std::vector<std::string> presetNames() const;
    /// The disk -> host tier per volume (labelled volume="name"): hits, misses, evictions,
    /// bytes loaded and re-fetched after eviction, resident and budget bytes; sessions; and
    /// the volumes out of service.
    void collect(MetricSet& metrics) const;

  private:
    friend class VolumeLease;
    void changeSessions(Volume& volume, int delta);
    static std::shared_ptr<Volume> open(const CatalogEntry& entry, const std::string& storeDir);
    /// A volume of `entry` for a reload, or nullptr (said in update.log) when it cannot be
    /// opened.
    static std::shared_ptr<Volume> reopen(const CatalogEntry& entry, const std::string& storeDir,
                                          const std::string& verb, CatalogUpdate& update);
    void rebalance(); ///< with mMutex held

    std::uint64_t mHostBudgetBytes;
    std::vector<std::shared_ptr<Volume>> mVolumes;
    std::map<std::string, std::shared_ptr<Volume>> mByName;
    std::map<std::string, std::string> mPresets;
    std::atomic<std::uint32_t> mSessions{0};
    /// Guards mVolumes, mByName and the budgets: the render thread reads shares while a
    /// reload swaps volumes.
    mutable std::mutex mMutex;
};

} // namespace bc::server
