// The parser sandbox (SandboxedSource.h): a forked child that opens the volume under limits
// and streams it over a pipe, and the parent's VolumeSource that reads that stream.
#include "brickstore/readers/detail/SandboxedSource.h"

#include "brickstore/detail/RegularFile.h"
#include "brickstore/readers/detail/ReadAhead.h"

#include <algorithm>
#include <atomic>
#include <cctype>
#include <cerrno>
#include <cmath>
#include <csignal>
#include <cstring>
#include <initializer_list>
#include <new>
#include <vector>

#include <fcntl.h>
#include <sys/mman.h>
#include <sys/resource.h>
#include <sys/stat.h>
#include <sys/wait.h>
#include <unistd.h>

// Under AddressSanitizer the process has terabytes of shadow memory reserved, so an
// address-space limit would fail every allocation of the child: it is not set there.
#if defined(__SANITIZE_ADDRESS__)
#define BC_ADDRESS_SANITIZED 1
#elif defined(__has_feature)
#if __has_feature(address_sanitizer)
#define BC_ADDRESS_SANITIZED 1
#endif
#endif

namespace bc::brickstore {
namespace {

/// Messages on the pipe, child to parent: 'F' (path) before each file the parser reads, 'I'
/// info, then the voxels as 'S' slabs (u64 slices, bytes) and 'X' extents (u32 count, then
/// count times u32 file, u64 offset, u64 bytes: where the next bytes lie in directFiles), in
/// slice order; 'E' (file, field, why) ends the stream with an error. Integers in host order
/// (same machine).
constexpr char kReading = 'F', kInfo = 'I', kSlab = 'S', kExtents = 'X', kError = 'E';
/// Extents per 'X' message: what the parent holds at a time (24 bytes each).
constexpr std::uint32_t kMaxExtentsPerMessage = 1u << 16;
constexpr std::size_t kMaxErrorText = 400; ///< per string: the parent's error stays < 1 kB
constexpr std::size_t kMaxPathText = 300;
constexpr std::size_t kMaxFieldText = 100;
constexpr std::size_t kMaxDescriptionText = 4096; ///< as a store's description
constexpr std::uint64_t kSlabBytes = 64ull << 20;
constexpr int kPipeBytes = 1 << 20; ///< /proc/sys/fs/pipe-max-size's default
/// The child's stderr goes to a file of its own (a memfd) sealed at this size: its writes past
/// it fail; an error quotes at most kMaxStderrText of the end of what it wrote.
constexpr off_t kMaxStderrBytes = 1 << 20;
constexpr std::size_t kMaxStderrText = 300;

std::atomic<std::uint64_t> gAddressSpaceBytes{ParserSandboxLimits{}.addressSpaceBytes};
std::atomic<std::uint32_t> gParseSeconds{ParserSandboxLimits{}.parseSeconds};
std::atomic<std::uint32_t> gCpuSeconds{ParserSandboxLimits{}.cpuSeconds};

std::string clip(const std::string& text, std::size_t maxBytes = kMaxErrorText) {
    return text.size() <= maxBytes ? text : text.substr(0, maxBytes) + "...";
}

/// At most `maxBytes` of a C string, never reading further (what() may be gigabytes).
std::string clipC(const char* text, std::size_t maxBytes = kMaxErrorText) {
    return std::string(text, ::strnlen(text, maxBytes));
}

/// The child's side: blocking writes; a parent gone (EPIPE) ends the child.
class ChildWriter {
  public:
    explicit ChildWriter(int fd) : mFd(fd) {}
    void bytes(const void* data, std::size_t n) {
        const auto* p = static_cast<const char*>(data);
        while (n > 0) {
            const ssize_t w = ::write(mFd, p, n);
            if (w < 0 && errno == EINTR) continue;
            if (w <= 0) ::_exit(3);
            p += w;
            n -= std::size_t(w);
        }
    }
    template <class T> void value(T v) { bytes(&v, sizeof v); }
    void text(const std::string& s, std::size_t maxBytes = kMaxErrorText) {
        const std::string c = clip(s, maxBytes);
        value(std::uint32_t(c.size()));
        bytes(c.data(), c.size());
    }
    void error(const std::string& file, const std::string& field, const std::string& why) {
        value(kError);
        text(file, kMaxPathText);
        text(field, kMaxFieldText);
        text(why);
    }

  private:
    int mFd;
};

void sendInfo(ChildWriter& w, const VolumeInfo& i) {
    w.value(kInfo);
    for (int a = 0; a < 3; ++a)
        w.value(i.dims[a]);
    w.value(std::uint8_t(i.type));
    for (int a = 0; a < 3; ++a)
        w.value(i.spacingMm[a]);
    for (int a = 0; a < 3; ++a)
        w.value(i.originMm[a]);
    w.value(i.background);
    w.value(i.valueScale);
    w.value(i.valueOffset);
    w.text(i.description, kMaxDescriptionText);
}

/// The file the child's stderr goes to: a memfd of kMaxStderrBytes that cannot grow (a child
/// printing without end fills no memory; RLIMIT_FSIZE would also stop OpenVDB's temporary copy
/// of the file it reads). The child's writes move the offset it shares with this descriptor,
/// so lseek tells how much it wrote. -1 when there is none: the child shares our stderr.
int openStderrFile() {
    const int fd = ::memfd_create("bc-parser-stderr", MFD_CLOEXEC | MFD_ALLOW_SEALING);
    if (fd < 0) return -1;
    if (::ftruncate(fd, kMaxStderrBytes) == 0 &&
        ::fcntl(fd, F_ADD_SEALS, F_SEAL_GROW | F_SEAL_SHRINK | F_SEAL_SEAL) == 0)
        return fd;
    ::close(fd);
    return -1;
}

/// In the child: fd 2 becomes `stderrFd` (when there is one).
void redirectStderr(int stderrFd) {
    if (stderrFd >= 0 && ::dup2(stderrFd, STDERR_FILENO) >= 0) ::close(stderrFd);
}

void applyLimits(const ParserSandboxLimits& limits, int stderrFd) {
#ifndef BC_ADDRESS_SANITIZED
    const rlimit as{limits.addressSpaceBytes, limits.addressSpaceBytes};
    ::setrlimit(RLIMIT_AS, &as);
#endif
    const rlimit cpu{limits.cpuSeconds, limits.cpuSeconds + 1};
    ::setrlimit(RLIMIT_CPU, &cpu);
    // The child dies of the signal that ends it, whatever handlers the parent installed (a
    // fuzzer's would turn GDCM's abort into a crash report and an exit status).
    for (int sig :
         {SIGALRM, SIGXCPU, SIGPIPE, SIGABRT, SIGSEGV, SIGBUS, SIGILL, SIGFPE, SIGINT, SIGTERM})
        ::signal(sig, SIG_DFL);
    sigset_t limitSignals;
    sigemptyset(&limitSignals);
    sigaddset(&limitSignals, SIGALRM);
    sigaddset(&limitSignals, SIGXCPU);
    ::sigprocmask(SIG_UNBLOCK, &limitSignals, nullptr); // a parent's mask is inherited
    redirectStderr(stderrFd);
}

/// Byte `c` as it stands in one line of text: tab, CR and LF as \t \r \n, other bytes
/// outside printable ASCII as \xNN.
std::string escaped(char c) {
    if (c == '\n') return "\\n";
    if (c == '\r') return "\\r";
    if (c == '\t') return "\\t";
    const auto b = static_cast<unsigned char>(c);
    if (b >= 0x20 && b < 0x7f) return std::string(1, c);
    const char hex[] = "0123456789abcdef";
    return {'\\', 'x', hex[b >> 4], hex[b & 15]};
}

/// The end of what the child wrote to its stderr file, for an error: one line of at most
/// kMaxStderrText characters (bytes escaped), "..." in front when cut; empty when nothing.
std::string stderrTail(int fd) {
    const off_t written = fd < 0 ? -1 : ::lseek(fd, 0, SEEK_CUR);
    if (written <= 0) return {};
    const auto size = std::size_t(written);
    std::string raw(std::min(size, kMaxStderrText), '\0');
    const ssize_t got = ::pread(fd, raw.data(), raw.size(), off_t(size - raw.size()));
    raw.resize(got > 0 ? std::size_t(got) : 0);
    bool cut = size > raw.size();
    while (!raw.empty() && std::isspace(static_cast<unsigned char>(raw.back())))
        raw.pop_back();
    // Built from the end: the last words before a death are the ones that say why.
    std::string line;
    for (std::size_t i = raw.size(); i > 0; --i) {
        const std::string e = escaped(raw[i - 1]);
        if (line.size() + e.size() > kMaxStderrText) {
            cut = true;
            break;
        }
        line.insert(0, e);
    }
    return line.empty() ? std::string() : (cut ? "..." : "") + line;
}

/// Streams a SliceLocator's volume: runs of located slices as 'X' messages, runs of slices it
/// must decode as 'S' slabs, in slice order. Located slices go out a slab's worth at a time:
/// locating a slice reads its page header, and a multi-page TIFF's headers lie one before
/// each page, spread over the file. Sent all at the end, the parent would wait for every one
/// of those reads (on a cold page cache, a seek each: 3.7 s for 920 pages of 4.7 MB) before
/// it read a voxel; sent as they come, it reads (and reads ahead) while the child locates
/// the rest, and the headers it has read ahead are in the page cache when the child gets there.
void streamLocated(ChildWriter& w, const VolumeInfo& info, detail::SliceLocator& locator) {
    const std::uint64_t sliceBytes = info.sliceBytes();
    const std::uint64_t perSlab = std::max<std::uint64_t>(1, kSlabBytes / sliceBytes);
    std::vector<detail::FileExtent> extents;
    std::vector<std::byte> slab;
    std::uint64_t decoded = 0; // slices waiting in `slab`
    std::uint64_t located = 0; // slices whose extents wait in `extents`
    const auto sendExtents = [&] {
        for (std::size_t at = 0; at < extents.size(); at += kMaxExtentsPerMessage) {
            const std::size_t n = std::min<std::size_t>(kMaxExtentsPerMessage, extents.size() - at);
            w.value(kExtents);
            w.value(std::uint32_t(n));
            for (std::size_t i = at; i < at + n; ++i) {
                w.value(extents[i].file);
                w.value(extents[i].offset);
                w.value(extents[i].bytes);
            }
        }
        extents.clear();
        located = 0;
    };
    const auto sendSlab = [&] {
        if (decoded == 0) return;
        w.value(kSlab);
        w.value(decoded);
        w.bytes(slab.data(), decoded * sliceBytes);
        decoded = 0;
    };
    for (std::uint64_t z = 0; z < info.dims[2]; ++z) {
        if (locator.locateSlice(z, extents)) {
            ::alarm(0); // a file read armed it; waiting on the parent is not parsing
            sendSlab(); // slices decoded before this one go first (extents was empty)
            if (++located >= perSlab || extents.size() >= kMaxExtentsPerMessage) sendExtents();
            continue;
        }
        sendExtents();
        slab.resize(perSlab * sliceBytes);
        locator.decodeSlice(z, std::span(slab).subspan(decoded * sliceBytes, sliceBytes));
        ::alarm(0);
        if (++decoded == perSlab) sendSlab();
    }
    sendExtents();
    sendSlab();
}

/// Opens the volume, streams it and ends the child; returns only by throwing.
void streamVolume(ChildWriter& w, const detail::SandboxedParser& parser,
                  const ParserSandboxLimits& limits, std::string& readingFile,
                  const detail::SandboxedOpener& open) {
    const detail::ReadingFile reading = [&](const std::string& path) {
        ::alarm(limits.parseSeconds);
        readingFile = path;
        w.value(kReading);
        w.text(path, kMaxPathText);
    };
    ::alarm(limits.parseSeconds);
    auto source = open(reading);
    ::alarm(0); // parsed: from here the parent's pace sets the time, RLIMIT_CPU the bound
    const VolumeInfo& info = source->info();
    sendInfo(w, info);
    auto* locator = dynamic_cast<detail::SliceLocator*>(source.get());
    if (locator && !parser.directFiles.empty()) {
        streamLocated(w, info, *locator);
        ::_exit(0);
    }
    const std::uint64_t sliceBytes = info.sliceBytes();
    const std::uint64_t perSlab = std::max<std::uint64_t>(1, kSlabBytes / sliceBytes);
    std::vector<std::byte> slab;
    for (std::uint64_t z = 0; z < info.dims[2];) {
        const std::uint64_t n = std::min(perSlab, info.dims[2] - z);
        slab.resize(n * sliceBytes);
        source->readSlices(n, slab);
        ::alarm(0); // a file read while streaming armed it; waiting on the parent is not parsing
        w.value(kSlab);
        w.value(n);
        w.bytes(slab.data(), slab.size());
        z += n;
    }
    ::_exit(0);
}

/// Runs in the child: limits, open, stream. Never returns.
[[noreturn]] void childMain(int fd, int stderrFd, const detail::SandboxedParser& parser,
                            const ParserSandboxLimits& limits,
                            const detail::SandboxedOpener& open) {
    applyLimits(limits, stderrFd);
    ChildWriter w(fd);
    std::string readingFile; // the file the parser read last, for errors that do not say
    try {
        streamVolume(w, parser, limits, readingFile, open);
    } catch (const FormatError& e) {
        // what() is "FILE: FIELD: why"; only the why crosses, bounded (never copied whole).
        const char* what = e.what();
        const std::size_t prefix = e.file().size() + e.field().size() + 4;
        w.error(e.file(), e.field(), clipC(what + ::strnlen(what, prefix), kMaxErrorText + 1));
    } catch (const std::bad_alloc&) {
        w.error(readingFile.empty() ? parser.path : readingFile, "file",
                "out of memory under the parser's " +
                    std::to_string(limits.addressSpaceBytes >> 20) +
                    " MiB address-space limit (a damaged or hostile file?)");
    } catch (const std::exception& e) {
        w.error(readingFile.empty() ? parser.path : readingFile, "file",
                parser.parserName + " cannot read it: " + clipC(e.what()));
    }
    ::_exit(2);
}

/// The parent's side: the VolumeSource ingest reads, fed by the child.
class SandboxedSource final : public VolumeSource {
  public:
    SandboxedSource(const detail::SandboxedParser& parser, const ParserSandboxLimits& limits,
                    const detail::SandboxedOpener& open)
        : mParser(parser) {
        mLimitText = std::to_string(limits.addressSpaceBytes >> 20) + " MiB, " +
                     std::to_string(limits.parseSeconds) + " s " + parser.alarmWords;
        int fds[2];
        if (::pipe2(fds, O_CLOEXEC) != 0)
            throw FormatError(parser.path, "file",
                              std::string("cannot create a pipe: ") + std::strerror(errno));
        // The child's stderr (GDCM's assertion text) is quoted in its error instead of reaching
        // the user's terminal above it.
        mStderrFd = openStderrFile();
        mPid = ::fork();
        if (mPid < 0) {
            ::close(fds[0]);
            ::close(fds[1]);
            if (mStderrFd >= 0) ::close(mStderrFd);
            throw FormatError(parser.path, "file",
                              std::string("cannot fork the parser: ") + std::strerror(errno));
        }
        if (mPid == 0) {
            ::close(fds[0]);
            childMain(fds[1], mStderrFd, parser, limits, open);
        }
        ::close(fds[1]);
        mFd = fds[0];
        // A slab crosses in pieces of the pipe's buffer, each a switch between the child and
        // the reading thread: the default 64 KiB made those switches most of a TIFF ingest's
        // time. The largest buffer an unprivileged process may set (1 MiB unless the system
        // says otherwise) cuts them 16-fold; failing to set it only costs speed.
        ::fcntl(mFd, F_SETPIPE_SZ, kPipeBytes);
        try {
            readInfo();
        } catch (...) {
            release(); // no destructor runs after a throwing constructor
            throw;
        }
    }
    ~SandboxedSource() override { release(); }
    const VolumeInfo& info() const override { return mInfo; }

  private:
    /// The voxels are one stream of bytes, from the pipe ('S') or from the files ('X').
    void readNextSlices(std::uint64_t count, std::span<std::byte> out) override {
        const std::uint64_t sliceBytes = mInfo.sliceBytes();
        // The file each slice starts in, where it came from the files (for a NaN's error).
        std::vector<std::uint32_t> sliceFiles;
        if (mInfo.type == VoxelType::F32) sliceFiles.assign(count, UINT32_MAX);
        for (std::uint64_t done = 0; done < out.size();) {
            if (mPipeBytes == 0 && mExtentAt == mExtents.size()) nextVoxels();
            std::uint64_t n = 0;
            if (mPipeBytes > 0) {
                n = std::min(out.size() - done, mPipeBytes);
                read(out.data() + done, n);
                mPipeBytes -= n;
            } else {
                if (!sliceFiles.empty() && done % sliceBytes == 0)
                    sliceFiles[done / sliceBytes] = mExtents[mExtentAt].file;
                n = readExtent(out.data() + done, out.size() - done);
            }
            done += n;
        }
        // The child checked the floats it sent; those read from the files passed no parser.
        for (std::uint64_t k = 0; k < sliceFiles.size(); ++k)
            if (sliceFiles[k] != UINT32_MAX)
                checkFinite(out.subspan(k * sliceBytes, sliceBytes), nextSlice() + k,
                            sliceFiles[k]);
    }

    void readInfo() {
        nextTag({kInfo});
        for (int a = 0; a < 3; ++a)
            mInfo.dims[a] = value<std::uint64_t>();
        const auto type = value<std::uint8_t>();
        if (!isValidVoxelType(type)) fail("the parser sent an unknown voxel type");
        mInfo.type = VoxelType(type);
        for (int a = 0; a < 3; ++a)
            mInfo.spacingMm[a] = value<double>();
        for (int a = 0; a < 3; ++a)
            mInfo.originMm[a] = value<double>();
        mInfo.background = value<double>();
        mInfo.valueScale = value<double>();
        mInfo.valueOffset = value<double>();
        mInfo.description = text();
        validateVolumeInfo(mInfo, mParser.path);
        const bool folder = S_ISDIR(::bc::brickstore::detail::fileMode(mParser.path));
        checkInputHolds(mInfo, ::bc::brickstore::detail::fileOrFolderBytes(mParser.path),
                        folder ? "the folder's files" : "the file's bytes", mParser.path, "dims");
    }

    /// The next 'S' slab or 'X' extents; the bytes they announce may not pass the volume's.
    void nextVoxels() {
        const std::uint64_t left = mInfo.voxelCount() * voxelBytes(mInfo.type) - mAnnounced;
        if (nextTag({kSlab, kExtents}) == kSlab) {
            const auto n = value<std::uint64_t>();
            if (n == 0 || n > left / mInfo.sliceBytes())
                fail("the parser sent a slab of " + std::to_string(n) + " slices");
            mPipeBytes = n * mInfo.sliceBytes();
            mAnnounced += mPipeBytes;
            return;
        }
        const auto count = value<std::uint32_t>();
        if (count == 0 || count > kMaxExtentsPerMessage || mParser.directFiles.empty())
            fail("the parser sent " + std::to_string(count) + " extents");
        mExtents.resize(count);
        mExtentAt = mExtentDone = 0;
        std::uint64_t announced = 0;
        for (detail::FileExtent& e : mExtents) {
            e.file = value<std::uint32_t>();
            e.offset = value<std::uint64_t>();
            e.bytes = value<std::uint64_t>();
            if (e.file >= mParser.directFiles.size() || e.bytes == 0 ||
                e.bytes > left - announced || e.offset > UINT64_MAX - e.bytes)
                fail("the parser sent an extent outside the volume's files or bytes");
            announced += e.bytes;
        }
        mAnnounced += announced;
    }

    /// Reads at most `need` bytes of the current extent into `p`; returns how many.
    std::uint64_t readExtent(std::byte* p, std::uint64_t need) {
        const detail::FileExtent& e = mExtents[mExtentAt];
        const int fd = openDirect(e.file);
        const std::string& path = mParser.directFiles[e.file];
        const std::uint64_t n = std::min(need, e.bytes - mExtentDone);
        for (std::uint64_t got = 0; got < n;) {
            const std::uint64_t at = e.offset + mExtentDone + got;
            const ssize_t r =
                ::pread(fd, p + got, std::min<std::uint64_t>(n - got, 1ull << 30), off_t(at));
            if (r < 0 && errno == EINTR) continue;
            if (r < 0)
                throw FormatError(path, "path",
                                  std::string("cannot read: ") + std::strerror(errno));
            if (r == 0)
                throw FormatError(
                    path, "data",
                    "ends at byte " + std::to_string(at) + ", inside the " +
                        std::to_string(e.bytes) + " voxel bytes its header places at " +
                        std::to_string(e.offset) + "; was it truncated while it was read?");
            got += std::uint64_t(r);
        }
        mExtentDone += n;
        if (mAhead) mAhead->reached(e.offset + mExtentDone);
        if (mExtentDone == e.bytes) ++mExtentAt, mExtentDone = 0;
        return n;
    }

    /// The descriptor of directFiles[file], opened on first use (one file open at a time),
    /// with the page cache kept ahead of the reads: ReadAhead within one file, the next files
    /// of a folder asked for whole.
    int openDirect(std::uint32_t file) {
        if (file == mDirectFile) return mDirectFd;
        closeDirect();
        const std::string& path = mParser.directFiles[file];
        mDirectFd = ::open(path.c_str(), O_RDONLY | O_CLOEXEC);
        if (mDirectFd < 0)
            throw FormatError(path, "path", std::string("cannot open: ") + std::strerror(errno));
        mDirectFile = file;
        const std::vector<std::string>& files = mParser.directFiles;
        if (files.size() == 1) {
            struct stat st {};
            if (::fstat(mDirectFd, &st) == 0)
                mAhead =
                    std::make_unique<detail::ReadAhead>(mDirectFd, 0, std::uint64_t(st.st_size));
            return mDirectFd;
        }
        detail::willNeedAfter(files, file, mInfo.sliceBytes(), mAdvised);
        return mDirectFd;
    }

    void closeDirect() {
        mAhead.reset(); // its thread reads the descriptor
        if (mDirectFd >= 0) ::close(mDirectFd);
        mDirectFd = -1;
        mDirectFile = UINT32_MAX;
    }

    /// NaN or infinity would poison every min/max and average the store keeps. The error
    /// names the file slice `z` came from, and its page when that file holds every slice.
    void checkFinite(std::span<const std::byte> slice, std::uint64_t z, std::uint32_t file) const {
        for (std::size_t i = 0; i < slice.size(); i += 4) {
            float v;
            std::memcpy(&v, slice.data() + i, 4);
            if (std::isfinite(v)) continue;
            const std::uint64_t voxel = i / 4;
            const bool pages = mParser.directFiles.size() == 1;
            throw FormatError(mParser.directFiles[file], "data",
                              (pages ? "page " + std::to_string(z + 1) + ": " : std::string()) +
                                  "voxel (" + std::to_string(voxel % mInfo.dims[0]) + "," +
                                  std::to_string(voxel / mInfo.dims[0]) + ") is " +
                                  (std::isnan(v) ? "NaN" : "infinite") +
                                  "; float volumes must be finite");
        }
    }

    /// Reads the next tag, past the files the parser reports, and checks it is one of `want`;
    /// an 'E' from the child becomes its FormatError.
    char nextTag(std::initializer_list<char> want) {
        char tag = value<char>();
        for (; tag == kReading; tag = value<char>())
            mReadingFile = text();
        if (std::find(want.begin(), want.end(), tag) != want.end()) return tag;
        if (tag == kError) {
            const std::string file = text(), field = text(), why = text();
            reap(false);
            throw FormatError(file.empty() ? mParser.path : file, field.empty() ? "file" : field,
                              why + " [sandboxed parser: " + mLimitText + "]");
        }
        fail("the parser sent an unexpected message");
    }

    template <class T> T value() {
        T v{};
        read(&v, sizeof v);
        return v;
    }
    std::string text() {
        const auto n = value<std::uint32_t>();
        if (n > kMaxDescriptionText + 3) fail("the parser sent a text too long");
        std::string s(n, '\0');
        read(s.data(), n);
        return s;
    }

    void read(void* data, std::size_t n) {
        auto* p = static_cast<char*>(data);
        while (n > 0) {
            const ssize_t r = ::read(mFd, p, n);
            if (r < 0 && errno == EINTR) continue;
            if (r <= 0) childEnded();
            p += r;
            n -= std::size_t(r);
        }
    }

    /// The stream ended early: how the child ended (waited for), as a ParserDied naming the
    /// file it was reading.
    [[noreturn]] void childEnded() {
        const int status = reap(false);
        const int sig = WIFSIGNALED(status) ? WTERMSIG(status) : 0;
        const int exitStatus = WIFEXITED(status) ? WEXITSTATUS(status) : -1;
        std::string why;
        if (sig == SIGALRM)
            why = "took longer than its time limit";
        else if (sig == SIGXCPU)
            why = "used more than its CPU-time limit";
        else if (sig == SIGKILL)
            why = "was killed (SIGKILL; out of memory?)";
        else if (sig == SIGABRT)
            why = "aborted (SIGABRT: a failed assertion in the parser library?)";
        else if (sig != 0)
            why = std::string("crashed: ") + ::strsignal(sig);
        else
            why = "ended early with status " + std::to_string(exitStatus);
        const std::string where = mReadingFile.empty() ? "" : " while reading this file";
        const std::string tail = stderrTail(mStderrFd);
        const std::string printed = tail.empty() ? "" : "; its stderr ends: \"" + tail + "\"";
        throw detail::ParserDied(mReadingFile.empty() ? mParser.path : mReadingFile,
                                 "the " + mParser.parserName + " parser " + why + where + printed +
                                     " [sandboxed parser: " + mLimitText + "]",
                                 sig, exitStatus);
    }

    [[noreturn]] void fail(const std::string& why) {
        throw FormatError(mParser.path, "file",
                          "sandboxed " + mParser.parserName + " parser: " + clip(why));
    }

    /// Closes the pipe, the files and the stderr file and ends the child (killed and waited for).
    void release() {
        closeDirect();
        if (mFd >= 0) ::close(mFd);
        mFd = -1;
        reap(true);
        if (mStderrFd >= 0) ::close(mStderrFd);
        mStderrFd = -1;
    }

    /// Waits for the child (killing it first when `kill`); its wait status, once.
    int reap(bool kill) {
        if (mPid <= 0) return mStatus;
        if (kill) ::kill(mPid, SIGKILL);
        while (::waitpid(mPid, &mStatus, 0) < 0 && errno == EINTR) {
        }
        mPid = -1;
        return mStatus;
    }

    detail::SandboxedParser mParser;
    std::string mLimitText;
    std::string mReadingFile; ///< the file the child reported reading last
    VolumeInfo mInfo;
    pid_t mPid = -1;
    int mFd = -1, mStatus = 0;
    int mStderrFd = -1;           ///< the child's stderr file (memfd); -1 when it shares ours
    std::uint64_t mAnnounced = 0; ///< voxel bytes the child's 'S' and 'X' messages announced
    std::uint64_t mPipeBytes = 0; ///< of the last 'S', still in the pipe
    std::vector<detail::FileExtent> mExtents; ///< of the last 'X'
    std::size_t mExtentAt = 0;                ///< the extent read next
    std::uint64_t mExtentDone = 0;            ///< its bytes already read
    std::uint32_t mDirectFile = UINT32_MAX;   ///< the directFiles entry open in mDirectFd
    int mDirectFd = -1;
    std::uint64_t mAdvised = 0; ///< a folder's files before this one were asked for (willNeed)
    std::unique_ptr<detail::ReadAhead> mAhead; ///< over mDirectFd, for one file
};

} // namespace

namespace detail {

std::unique_ptr<VolumeSource> openSandboxed(const SandboxedParser& parser,
                                            const ParserSandboxLimits& limits,
                                            SandboxedOpener open) {
    // The child's open() of a FIFO would wait for a writer until the parse alarm.
    if (!S_ISDIR(fileMode(parser.path))) requireRegularFile(parser.path);
    return std::make_unique<SandboxedSource>(parser, limits, open);
}

} // namespace detail

void setParserSandboxLimits(const ParserSandboxLimits& limits) {
    gAddressSpaceBytes = limits.addressSpaceBytes;
    gParseSeconds = limits.parseSeconds;
    gCpuSeconds = limits.cpuSeconds;
}

ParserSandboxLimits parserSandboxLimits() {
    return {gAddressSpaceBytes.load(), gParseSeconds.load(), gCpuSeconds.load()};
}

} // namespace bc::brickstore
