#pragma once
// Read side of a store file (POSIX): positional reads (pread) from a descriptor held open, and
// the identity the file had when opened. Not a memory map: a file truncated or rewritten while
// open turns into an error on the next read, never into SIGBUS. Thread-safe (pread and fstat
// are). Move-only owner of the descriptor.
#include <cstddef>
#include <cstdint>
#include <optional>
#include <span>
#include <string>

namespace bc::brickstore::detail {

/// What identifies a file's contents without reading them. The inode's change time is the one
/// time no one can set: a rewrite in place that restores the size and modification time (cp
/// -p, rsync --inplace -t) still moves it, as a chmod does.
struct FileIdentity {
    std::uint64_t device = 0, inode = 0, bytes = 0;
    std::int64_t mtimeNs = 0;
    std::int64_t ctimeNs = 0;
    bool operator==(const FileIdentity&) const = default;
};

class StoreReadFile {
  public:
    /// Refuses anything but a regular file without blocking (a FIFO is never opened).
    /// @throw StoreIoError naming the path when it cannot be opened or is not a regular file.
    explicit StoreReadFile(const std::string& path);
    ~StoreReadFile();
    StoreReadFile(const StoreReadFile&) = delete;
    StoreReadFile& operator=(const StoreReadFile&) = delete;

    /// Size when opened.
    std::uint64_t size() const { return mOpened.bytes; }
    const FileIdentity& opened() const { return mOpened; }
    /// Reads out.size() bytes at `offset`. @throw StoreIoError naming the path on a read
    /// error or a short read (the file shrank).
    void readAt(std::uint64_t offset, std::span<std::byte> out) const;
    /// Whether the open file still has the size and modification time it had when opened
    /// (one fstat; not the change time, which a chmod moves too: a rewrite that restored the
    /// modification time fails the bricks' checksums instead).
    /// @throw StoreCorrupt naming the path and what changed when not.
    void checkUnchanged() const;
    /// What changed between the opened file and whatever `path` names now ("replaced by
    /// another file", "size A -> B bytes", "modified", "rewritten in place...", "gone: ...");
    /// nullopt when nothing did. One stat. Without `changeTime` the inode's change time is not
    /// compared.
    std::optional<std::string> changeAtPath(bool changeTime = true) const;

  private:
    std::string mPath;
    int mFd = -1;
    FileIdentity mOpened;
};

} // namespace bc::brickstore::detail
