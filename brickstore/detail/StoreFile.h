#pragma once
// The write side of a store file: a temporary file beside the target, written with pwrite
// from many threads, made durable and renamed into place only when complete.
#include <atomic>
#include <cstdint>
#include <span>
#include <string>
#include <vector>

namespace bc::brickstore::detail {

class StoreFile {
  public:
    /// Creates `target.partial.PID` (after removing stale partials of dead ingests).
    /// @throw StoreIoError naming the target, having removed the partial file it created.
    explicit StoreFile(const std::string& target);
    /// Unlinks the temporary file unless commit() succeeded.
    ~StoreFile();
    StoreFile(const StoreFile&) = delete;
    StoreFile& operator=(const StoreFile&) = delete;

    /// Appends `bytes` at a freshly reserved offset; thread-safe. Returns the offset.
    /// @throw StoreIoError naming the target (a full disk, a file-size limit).
    std::uint64_t append(std::span<const std::byte> bytes);
    /// Writes at a fixed offset (header, index).
    void writeAt(std::uint64_t offset, std::span<const std::byte> bytes);
    /// Reads back bytes written earlier.
    void readAt(std::uint64_t offset, std::span<std::byte> out) const;
    std::uint64_t end() const { return mEnd.load(); }
    /// fsync, rename over the target, fsync the folder.
    void commit();
    const std::string& tempPath() const { return mTemp; }
    /// The stale partial files (of ingests that no longer run) the constructor removed.
    const std::vector<std::string>& removedStalePartials() const { return mRemovedStale; }

  private:
    /// Closes and unlinks the temporary file.
    void discard() noexcept;

    std::string mTarget;
    std::string mTemp;
    int mFd = -1;
    std::atomic<std::uint64_t> mEnd;
    bool mCommitted = false;
    std::vector<std::string> mRemovedStale;
};

} // namespace bc::brickstore::detail
