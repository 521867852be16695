#pragma once
// The volumes a daemon serves, by name (clients never send paths). Every entry is opened at
// start-up: brick stores as they are, generated entries ingested once into the store folder
// and reused after. An entry that fails to open stops the start (ConfigError naming it),
// except a store marked optional that is missing: logged and left out. reload() (SIGHUP)
// applies a new config: volumes added, removed, reopened when their store file changed.
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

    /// Applies `config`'s volumes and presets (other settings need a restart): opens added
    /// volumes and reopens those whose entry or store file changed (a new store instance);
    /// logs one line per volume added, removed, reopened or left out, and one with the count
    /// unchanged. A volume that fails to open is left out (logged); the others still apply.
    /// Returns the volumes that are no longer served as they were (removed or reopened):
    /// sessions on them must be told. Network thread (the one that leases).
    std::vector<std::shared_ptr<Volume>> reload(const DaemonConfig& config, Log& log);

    /// The served volumes, in config order.
    std::vector<protocol::VolumeInfo> list() const;
    /// A lease on `name`, or an empty lease when the catalog has no such volume.
    VolumeLease lease(const std::string& name);
    std::size_t size() const;
    /// Sessions holding a lease, over all volumes.
    std::uint32_t sessions() const { return mSessions.load(); }
    /// A volume's fair share of `totalBytes`: in proportion to its sessions (at least one).
    std::uint64_t shareOf(const Volume& volume, std::uint64_t totalBytes) const;
    /// Presets the config added ([[preset]]): name -> JSON text, read at start-up and at each
    /// reload. Network thread only (reload() runs there too).
    const std::map<std::string, std::string>& configPresets() const { return mPresets; }
    /// Whether a client may name `name` as a preset: a built-in one or the config's.
    bool hasPreset(const std::string& name) const;
    /// Every preset a client may name, sorted.
    std::vector<std::string> presetNames() const;
    /// The disk -> host tier per volume (labelled volume="name"): hits, misses, evictions,
    /// bytes loaded and re-fetched after eviction, resident and budget bytes; sessions.
    void collect(MetricSet& metrics) const;

  private:
    friend class VolumeLease;
    void changeSessions(Volume& volume, int delta);
    std::shared_ptr<Volume> open(const CatalogEntry& entry, const std::string& storeDir);
    /// A volume of `entry` for a reload, or nullptr (logged) when it cannot be opened.
    std::shared_ptr<Volume> reopen(const CatalogEntry& entry, const std::string& storeDir,
                                   const std::string& verb, Log& log);
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
