#include "brickstore/detail/StoreReadFile.h"

#include "brickstore/Error.h"
#include "brickstore/detail/RegularFile.h"

#include <cerrno>
#include <cstring>
#include <fcntl.h>
#include <sys/stat.h>
#include <unistd.h>

namespace bc::brickstore::detail {
namespace {

std::int64_t nanoseconds(const timespec& t) {
    return std::int64_t(t.tv_sec) * 1000000000 + t.tv_nsec;
}

FileIdentity identityOf(const struct stat& st) {
    return {std::uint64_t(st.st_dev), std::uint64_t(st.st_ino), std::uint64_t(st.st_size),
            nanoseconds(st.st_mtim), nanoseconds(st.st_ctim)};
}

/// "size 1000 -> 400 bytes", "modified", or "" when `now` is `was`.
std::string contentChange(const FileIdentity& was, const FileIdentity& now) {
    if (now.bytes != was.bytes)
        return "size " + std::to_string(was.bytes) + " -> " + std::to_string(now.bytes) + " bytes";
    if (now.mtimeNs != was.mtimeNs) return "modified (same size, new modification time)";
    return {};
}

} // namespace

StoreReadFile::StoreReadFile(const std::string& path) : mPath(path) {
    std::string why;
    mFd = openRegularFile(path, why);
    if (mFd < 0) throw StoreIoError(path + ": cannot open: " + why);
    struct stat st {};
    if (::fstat(mFd, &st) != 0) {
        const std::string error = std::strerror(errno);
        ::close(mFd);
        throw StoreIoError(path + ": fstat failed: " + error);
    }
    mOpened = identityOf(st);
}

StoreReadFile::~StoreReadFile() {
    if (mFd >= 0) ::close(mFd);
}

void StoreReadFile::readAt(std::uint64_t offset, std::span<std::byte> out) const {
    std::size_t done = 0;
    while (done < out.size()) {
        const ssize_t n =
            ::pread(mFd, out.data() + done, out.size() - done, static_cast<off_t>(offset + done));
        if (n < 0 && errno == EINTR) continue;
        if (n < 0)
            throw StoreIoError(mPath + ": read of " + std::to_string(out.size()) +
                               " bytes at offset " + std::to_string(offset) +
                               " failed: " + std::strerror(errno));
        if (n == 0) {
            struct stat st {};
            const std::string now = ::fstat(mFd, &st) == 0
                                        ? std::to_string(std::uint64_t(st.st_size)) + " bytes"
                                        : "of unknown size";
            throw StoreIoError(mPath + ": short read: " + std::to_string(done) + " of " +
                               std::to_string(out.size()) + " bytes at offset " +
                               std::to_string(offset) + " (the file was " +
                               std::to_string(mOpened.bytes) + " bytes when opened, is " + now +
                               " now: truncated while served?)");
        }
        done += static_cast<std::size_t>(n);
    }
}

void StoreReadFile::checkUnchanged() const {
    struct stat st {};
    if (::fstat(mFd, &st) != 0)
        throw StoreIoError(mPath + ": fstat failed: " + std::strerror(errno));
    const std::string change = contentChange(mOpened, identityOf(st));
    if (!change.empty())
        throw StoreCorrupt(mPath + ": changed on disk since it was opened: " + change +
                           "; reload the daemon (SIGHUP) to serve the new store");
}

std::optional<std::string> StoreReadFile::changeAtPath(bool changeTime) const {
    struct stat st {};
    if (::stat(mPath.c_str(), &st) != 0) return std::string("gone: ") + std::strerror(errno);
    const FileIdentity now = identityOf(st);
    if (now.device != mOpened.device || now.inode != mOpened.inode)
        return std::string("replaced by another file");
    std::string change = contentChange(mOpened, now);
    if (!change.empty()) return change;
    if (changeTime && now.ctimeNs != mOpened.ctimeNs)
        return std::string("rewritten in place with its size and modification time kept, or "
                           "its owner or permissions changed (new inode change time)");
    return std::nullopt;
}

} // namespace bc::brickstore::detail
