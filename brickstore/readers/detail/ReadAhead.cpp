#include "brickstore/readers/detail/ReadAhead.h"

#include <algorithm>

#include <fcntl.h>
#include <unistd.h>

namespace bc::brickstore::detail {

namespace {

/// Bytes asked of the kernel at a time: small enough that the reader's next move is seen
/// soon, large enough that the asking costs nothing.
constexpr std::uint64_t kStepBytes = 8ull << 20;

} // namespace

void willNeed(const std::string& path) {
    const int fd = ::open(path.c_str(), O_RDONLY | O_CLOEXEC);
    if (fd < 0) return;
    ::posix_fadvise(fd, 0, 0, POSIX_FADV_WILLNEED);
    ::close(fd);
}

void willNeedAfter(const std::vector<std::string>& files, std::uint64_t at, std::uint64_t fileBytes,
                   std::uint64_t& advised) {
    const std::uint64_t window =
        std::max<std::uint64_t>(1, kFilesReadAheadBytes / std::max<std::uint64_t>(fileBytes, 1));
    for (advised = std::max(advised, at + 1);
         advised < std::min<std::uint64_t>(files.size(), at + 1 + window); ++advised)
        willNeed(files[advised]);
}

ReadAhead::ReadAhead(int fd, std::uint64_t position, std::uint64_t fileEnd,
                     std::uint64_t windowBytes)
    : mFd(fd), mEnd(fileEnd), mWindow(windowBytes),
      mTarget(std::min(fileEnd, position + windowBytes)), mAsked(std::min(position, fileEnd)) {
    mThread = std::thread([this] { run(); });
}

ReadAhead::~ReadAhead() {
    {
        std::lock_guard lock(mMutex);
        mStopping = true;
    }
    mMoved.notify_all();
    mThread.join();
}

void ReadAhead::reached(std::uint64_t position) {
    const std::uint64_t target = std::min(mEnd, position + mWindow);
    {
        std::lock_guard lock(mMutex);
        // Asked in half-window steps: one wake-up per half window read, not per read.
        if (target < mTarget + mWindow / 2 && target != mEnd) return;
        if (target <= mTarget) return;
        mTarget = target;
        mAsked = std::max(mAsked, std::min(position, mEnd)); // never behind the reader
    }
    mMoved.notify_one();
}

void ReadAhead::run() {
    std::unique_lock lock(mMutex);
    for (;;) {
        mMoved.wait(lock, [&] { return mStopping || mAsked < mTarget; });
        if (mStopping) return;
        const std::uint64_t from = mAsked, bytes = std::min(kStepBytes, mTarget - mAsked);
        mAsked += bytes;
        lock.unlock();
        // Blocks while the device's queue is full: here, not in the reader. An error (a pipe,
        // a file system without readahead) only means no help: the reads still read.
        ::readahead(mFd, off_t(from), std::size_t(bytes));
        lock.lock();
    }
}

} // namespace bc::brickstore::detail
