#include "brickstore/detail/StoreFile.h"

#include "brickstore/Error.h"
#include "brickstore/detail/StoreFormat.h"

#include <cerrno>
#include <csignal>
#include <cstring>
#include <fcntl.h>
#include <filesystem>
#include <unistd.h>

namespace bc::brickstore::detail {
namespace {

std::string errnoText() {
    return std::strerror(errno);
}

/// Removes `target.partial.PID` files whose ingest process no longer exists; returns them.
std::vector<std::string> removeStalePartials(const std::filesystem::path& target) {
    std::vector<std::string> removed;
    std::error_code ec;
    auto folder = target.has_parent_path() ? target.parent_path() : std::filesystem::path(".");
    std::string prefix = target.filename().string() + ".partial.";
    for (const auto& entry : std::filesystem::directory_iterator(folder, ec)) {
        std::string name = entry.path().filename().string();
        if (name.rfind(prefix, 0) != 0) continue;
        char* end = nullptr;
        long pid = std::strtol(name.c_str() + prefix.size(), &end, 10);
        if (pid <= 0 || *end != '\0') continue;
        if (::kill(static_cast<pid_t>(pid), 0) != 0 && errno == ESRCH &&
            std::filesystem::remove(entry.path(), ec))
            removed.push_back(entry.path().string());
    }
    return removed;
}

void syncFolder(const std::filesystem::path& target) {
    auto folder = target.has_parent_path() ? target.parent_path() : std::filesystem::path(".");
    int fd = ::open(folder.c_str(), O_RDONLY | O_DIRECTORY | O_CLOEXEC);
    if (fd < 0) return;
    ::fsync(fd);
    ::close(fd);
}

} // namespace

StoreFile::StoreFile(const std::string& target) : mTarget(target), mEnd(kHeaderBytes) {
    std::filesystem::path t(target);
    std::error_code ec;
    if (std::filesystem::is_directory(t, ec))
        throw StoreIoError(target + ": is a folder; give the store's file name");
    mRemovedStale = removeStalePartials(t);
    mTemp = target + ".partial." + std::to_string(::getpid());
    mFd = ::open(mTemp.c_str(), O_RDWR | O_CREAT | O_TRUNC | O_CLOEXEC, 0644);
    if (mFd < 0)
        throw StoreIoError(target + ": cannot create its partial file " + mTemp + ": " +
                           errnoText());
    // The header stays zero until commit: an interrupted ingest leaves no magic. A constructor
    // that throws runs no destructor: a full disk here must not leave an empty partial file.
    try {
        writeAt(0, std::vector<std::byte>(kHeaderBytes));
    } catch (...) {
        discard();
        throw;
    }
}

StoreFile::~StoreFile() {
    if (!mCommitted) {
        discard();
        return;
    }
    if (mFd >= 0) ::close(mFd);
}

void StoreFile::discard() noexcept {
    if (mFd >= 0) ::close(mFd);
    mFd = -1;
    ::unlink(mTemp.c_str());
}

std::uint64_t StoreFile::append(std::span<const std::byte> bytes) {
    std::uint64_t offset = mEnd.fetch_add(bytes.size());
    writeAt(offset, bytes);
    return offset;
}

void StoreFile::writeAt(std::uint64_t offset, std::span<const std::byte> bytes) {
    std::size_t done = 0;
    while (done < bytes.size()) {
        ssize_t n = ::pwrite(mFd, bytes.data() + done, bytes.size() - done,
                             static_cast<off_t>(offset + done));
        if (n < 0 && errno == EINTR) continue;
        if (n <= 0)
            throw StoreIoError(mTarget + ": cannot write the store: " + errnoText() + " (" +
                               std::to_string(bytes.size() - done) + " bytes at offset " +
                               std::to_string(offset + done) + " of " + mTemp +
                               ", removed on failure)");
        done += static_cast<std::size_t>(n);
    }
}

void StoreFile::readAt(std::uint64_t offset, std::span<std::byte> out) const {
    std::size_t done = 0;
    while (done < out.size()) {
        ssize_t n =
            ::pread(mFd, out.data() + done, out.size() - done, static_cast<off_t>(offset + done));
        if (n < 0 && errno == EINTR) continue;
        if (n <= 0)
            throw StoreIoError(mTarget + ": cannot read back " + mTemp + ": " +
                               (n < 0 ? errnoText() : std::string("it ended early")));
        done += static_cast<std::size_t>(n);
    }
}

void StoreFile::commit() {
    if (::fsync(mFd) != 0)
        throw StoreIoError(mTarget + ": fsync of " + mTemp + " failed: " + errnoText());
    if (::rename(mTemp.c_str(), mTarget.c_str()) != 0)
        throw StoreIoError(mTarget +
                           ": cannot rename the finished store into place: " + errnoText());
    mCommitted = true;
    syncFolder(mTarget);
}

} // namespace bc::brickstore::detail
