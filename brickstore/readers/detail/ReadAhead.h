#pragma once
// Keeps the page cache ahead of a reader that moves forward through a file (raw voxels, a
// multi-page TIFF). Ingest reads a brick row of slices, then cuts and compresses it while the
// reader waits on a full queue: without help the disk idles through the cutting and the
// workers idle through the reading. A thread of its own asks the kernel (readahead(2)) for the
// window past the reader's position, so the next row is in memory when the reader comes to
// it. The window lives in the page cache, not in the process: it is not part of an ingest's
// memory budget, and the kernel drops it under pressure (the reads then go to the disk).
#include <condition_variable>
#include <cstdint>
#include <mutex>
#include <string>
#include <thread>
#include <vector>

namespace bc::brickstore::detail {

/// Bytes kept read ahead of the reader: a brick row of 2048² u16 slices (64 + 2 of them).
constexpr std::uint64_t kReadAheadWindowBytes = 512ull << 20;

/// How far ahead of its reads a reader of a folder of one-slice files (a TIFF folder) asks the
/// kernel for its next files (willNeed).
constexpr std::uint64_t kFilesReadAheadBytes = 64ull << 20;

/// Asks the kernel to read the whole file at `path` into the page cache, without waiting (a
/// folder's next slices); a file that cannot be opened is left to the reader to report.
void willNeed(const std::string& path);

/// A folder's reader is at file `at` of `files`, each about `fileBytes` long: asks for the
/// next files within kFilesReadAheadBytes (willNeed), those past `advised` only, and moves
/// `advised` past them.
void willNeedAfter(const std::vector<std::string>& files, std::uint64_t at, std::uint64_t fileBytes,
                   std::uint64_t& advised);

class ReadAhead {
  public:
    /// Reads ahead in `fd` (borrowed: it must outlive this object) up to `fileEnd`, from
    /// `position` on.
    ReadAhead(int fd, std::uint64_t position, std::uint64_t fileEnd,
              std::uint64_t windowBytes = kReadAheadWindowBytes);
    ~ReadAhead();
    ReadAhead(const ReadAhead&) = delete;
    ReadAhead& operator=(const ReadAhead&) = delete;

    /// The reader has come to `position`: the window moves on to `position + windowBytes`.
    void reached(std::uint64_t position);

  private:
    void run();

    const int mFd;
    const std::uint64_t mEnd, mWindow;
    std::mutex mMutex;
    std::condition_variable mMoved;
    std::uint64_t mTarget = 0; ///< where the window ends now
    std::uint64_t mAsked = 0;  ///< how far the kernel has been asked to read
    bool mStopping = false;
    std::thread mThread; ///< last: it starts once the rest is built
};

} // namespace bc::brickstore::detail
