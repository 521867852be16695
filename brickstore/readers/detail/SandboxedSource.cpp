// The parser sandbox (SandboxedSource.h): a forked child that opens the volume under limits
// and streams it over a pipe, and the parent's VolumeSource that reads that stream.
#include "brickstore/readers/detail/SandboxedSource.h"

#include <algorithm>
#include <atomic>
#include <cctype>
#include <cerrno>
#include <csignal>
#include <cstring>
#include <new>
#include <vector>

#include <fcntl.h>
#include <sys/mman.h>
#include <sys/resource.h>
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
/// info, then 'S' slab (u64 slices, bytes) ...; 'E' (file, field, why) ends the stream with an
/// error. Integers in host order (same machine).
constexpr char kReading = 'F', kInfo = 'I', kSlab = 'S', kError = 'E';
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

/// Opens the volume, streams it and ends the child; returns only by throwing.
void streamVolume(ChildWriter& w, const ParserSandboxLimits& limits, std::string& readingFile,
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
        streamVolume(w, limits, readingFile, open);
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
    void readNextSlices(std::uint64_t count, std::span<std::byte> out) override {
        const std::uint64_t sliceBytes = mInfo.sliceBytes();
        std::uint64_t done = 0;
        while (done < count) {
            if (mPendingSlices == 0) nextSlab();
            const std::uint64_t n = std::min(count - done, mPendingSlices);
            read(out.data() + done * sliceBytes, n * sliceBytes);
            mPendingSlices -= n;
            done += n;
        }
    }

    void readInfo() {
        expectTag(kInfo);
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
    }

    void nextSlab() {
        expectTag(kSlab);
        const auto n = value<std::uint64_t>();
        if (n == 0 || n > mInfo.dims[2] - nextSlice())
            fail("the parser sent a slab of " + std::to_string(n) + " slices");
        mPendingSlices = n;
    }

    /// Reads the next tag, past the files the parser reports; an 'E' from the child becomes
    /// its FormatError.
    void expectTag(char want) {
        char tag = value<char>();
        for (; tag == kReading; tag = value<char>())
            mReadingFile = text();
        if (tag == want) return;
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

    /// Closes the pipe and the stderr file and ends the child (killed and waited for).
    void release() {
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
    int mStderrFd = -1; ///< the child's stderr file (memfd); -1 when it shares ours
    std::uint64_t mPendingSlices = 0;
};

} // namespace

namespace detail {

std::unique_ptr<VolumeSource> openSandboxed(const SandboxedParser& parser,
                                            const ParserSandboxLimits& limits,
                                            SandboxedOpener open) {
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
