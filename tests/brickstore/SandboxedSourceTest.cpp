// The parser sandbox (brickstore/readers/detail/SandboxedSource.h) with openers written here:
// a volume crosses the pipe byte for byte, in every voxel type; and each way a child can end
// early (an exception, an abort while opening or while streaming, the alarm, the address-space
// limit) is one FormatError under 1 kB naming the file the parser was reading, and quoting the
// end of what the child printed to its stderr instead of letting it reach ours.
#include "brickstore/readers/detail/SandboxedSource.h"
#include "brickstore/Error.h"
#include "brickstore/Readers.h"
#include "tests/brickstore/VolumeTestSupport.h"

#include <gtest/gtest.h>

#include <chrono>
#include <csignal>
#include <cstdio>
#include <cstdlib>
#include <cstring>
#include <filesystem>
#include <thread>
#include <vector>

namespace bc::brickstore {
namespace {

using detail::ParserDied;
using detail::ReadingFile;

const detail::SandboxedParser kParser{"/data/series", "test", "per file"};

ParserSandboxLimits limits(std::uint32_t parseSeconds = 10) {
    ParserSandboxLimits l;
    l.parseSeconds = parseSeconds;
    return l;
}

/// Runs `open` in the sandbox and reads the whole volume; returns the error it ends with.
template <class Open> std::string sandboxError(Open open, std::uint32_t parseSeconds = 10) {
    try {
        auto source = detail::openSandboxed(kParser, limits(parseSeconds), open);
        test::readAllSlices(*source, 1);
    } catch (const FormatError& e) {
        EXPECT_LT(std::strlen(e.what()), 1024u) << e.what();
        return e.what();
    }
    ADD_FAILURE() << "the sandboxed reader did not fail";
    return {};
}

bool contains(const std::string& text, const std::string& part) {
    return text.find(part) != std::string::npos;
}

/// A slice stream that reports a file per slice and aborts (as a failed assertion does)
/// before slice `abortAt`.
class AbortingVolume final : public VolumeSource {
  public:
    AbortingVolume(const ReadingFile& reading, std::uint64_t abortAt)
        : mReading(reading), mAbortAt(abortAt) {
        mInfo.dims = {8, 8, 16};
        mInfo.type = VoxelType::U16;
    }
    const VolumeInfo& info() const override { return mInfo; }

  private:
    void readNextSlices(std::uint64_t count, std::span<std::byte> out) override {
        for (std::uint64_t z = nextSlice(); z < nextSlice() + count; ++z) {
            mReading("/data/series/slice-" + std::to_string(z) + ".dcm");
            if (z == mAbortAt) std::abort();
        }
        std::memset(out.data(), 0, out.size());
    }

    ReadingFile mReading;
    std::uint64_t mAbortAt;
    VolumeInfo mInfo;
};

TEST(SandboxedSource, VolumesCrossThePipeByteForByteInEveryType) {
    const std::array<std::uint64_t, 3> dims{33, 17, 40};
    for (SynthKind kind : {SynthKind::Phantom, SynthKind::Vessels}) {
        auto direct = makeSynthetic(kind, dims, 7);
        auto sandboxed = detail::openSandboxed(
            kParser, limits(), [&](const ReadingFile&) { return makeSynthetic(kind, dims, 7); });
        EXPECT_EQ(sandboxed->info().dims, direct->info().dims);
        EXPECT_EQ(sandboxed->info().type, direct->info().type);
        EXPECT_EQ(sandboxed->info().description, direct->info().description);
        EXPECT_EQ(test::readAllSlices(*sandboxed, {1, 5, 40}), test::readAllSlices(*direct, 40));
    }
}

TEST(SandboxedSource, AChildsFormatErrorKeepsItsFileAndField) {
    const std::string what = sandboxError([](const ReadingFile&) -> std::unique_ptr<VolumeSource> {
        throw FormatError("/data/series/a.dcm", "Rows", "is 0");
    });
    EXPECT_EQ(what.rfind("/data/series/a.dcm: Rows: is 0 [sandboxed parser: 2048 MiB, 10 s per "
                         "file]",
                         0),
              0u)
        << what;
}

TEST(SandboxedSource, AHugeExceptionMessageIsCutShort) {
    const std::string what = sandboxError([](const ReadingFile&) -> std::unique_ptr<VolumeSource> {
        throw std::runtime_error(std::string(10 << 20, ' '));
    });
    EXPECT_TRUE(contains(what, "/data/series: file: test cannot read it")) << what;
}

TEST(SandboxedSource, AnAbortWhileOpeningNamesTheFileBeingRead) {
    try {
        detail::openSandboxed(kParser, limits(), [](const ReadingFile& reading) {
            reading("/data/series/1-001.dcm");
            reading("/data/series/1-002.dcm");
            std::abort();
            return std::unique_ptr<VolumeSource>();
        });
        FAIL() << "no error";
    } catch (const ParserDied& e) {
        EXPECT_EQ(e.file(), "/data/series/1-002.dcm") << e.what();
        EXPECT_EQ(e.field(), "file") << e.what();
        EXPECT_EQ(e.signal(), SIGABRT) << e.what();
        EXPECT_TRUE(contains(e.what(), "aborted")) << e.what();
        EXPECT_TRUE(contains(e.what(), "while reading this file")) << e.what();
    }
}

TEST(SandboxedSource, AnAbortWhileStreamingNamesTheSliceFile) {
    const std::string what = sandboxError(
        [](const ReadingFile& reading) { return std::make_unique<AbortingVolume>(reading, 11); });
    EXPECT_EQ(what.rfind("/data/series/slice-11.dcm: file: the test parser aborted", 0), 0u)
        << what;
}

// As GDCM's failed assertion: the text printed before the abort ends the error, escaped into one
// line and cut to its last 300 characters, and is not printed on the process's stderr.
TEST(SandboxedSource, WhatAnAbortingChildPrintsEndsItsErrorAndNotOurStderr) {
    testing::internal::CaptureStderr();
    const std::string what =
        sandboxError([](const ReadingFile& reading) -> std::unique_ptr<VolumeSource> {
            reading("/data/series/1-007.dcm");
            std::fprintf(stderr, "%s\n", std::string(5000, '.').c_str());
            std::fprintf(stderr, "gdcmX.cxx:375: Read: Assertion `0 && \"Should not happen\"' "
                                 "failed.\n\t\x01\n");
            std::abort();
            return nullptr;
        });
    const std::string printed = testing::internal::GetCapturedStderr();
    EXPECT_EQ(what.rfind("/data/series/1-007.dcm: file: the test parser aborted", 0), 0u) << what;
    EXPECT_TRUE(contains(what, "its stderr ends: \"...")) << what;
    EXPECT_TRUE(contains(what, "Assertion `0 && \"Should not happen\"' failed.\\n\\t\\x01\" ["))
        << what;
    EXPECT_FALSE(contains(what, std::string(300, '.'))) << what;
    EXPECT_EQ(what.find('\n'), std::string::npos) << what;
    EXPECT_FALSE(contains(printed, "Should not happen")) << printed;
}

// The child's stderr file stops at 1 MiB: a child printing 4 MiB goes on (its writes past it
// fail) and dies of its own abort, quoted from what was kept.
TEST(SandboxedSource, AChildPrintingWithoutEndIsBoundedAndGoesOn) {
    const std::string what = sandboxError([](const ReadingFile&) -> std::unique_ptr<VolumeSource> {
        const std::string line = std::string(1023, '.') + "\n";
        for (int i = 0; i < 4096; ++i)
            std::fputs(line.c_str(), stderr);
        std::abort();
    });
    EXPECT_TRUE(contains(what, "the test parser aborted")) << what;
    EXPECT_TRUE(contains(what, "its stderr ends: \"...")) << what;
}

std::size_t openDescriptors() {
    const std::filesystem::directory_iterator fds("/proc/self/fd");
    return std::size_t(std::distance(begin(fds), end(fds)));
}

// An open that fails (no destructor runs after a throwing constructor) closes the pipe and
// the stderr file of its child.
TEST(SandboxedSource, AFailedOpenLeavesNoDescriptorOpen) {
    const std::size_t before = openDescriptors();
    for (int i = 0; i < 3; ++i) {
        sandboxError([](const ReadingFile&) -> std::unique_ptr<VolumeSource> { std::abort(); });
        sandboxError([](const ReadingFile&) -> std::unique_ptr<VolumeSource> {
            throw FormatError("/data/series/a.dcm", "Rows", "is 0");
        });
    }
    EXPECT_EQ(openDescriptors(), before);
}

TEST(SandboxedSource, TheAlarmEndsAParseThatTakesTooLong) {
    const auto start = std::chrono::steady_clock::now();
    const std::string what = sandboxError(
        [](const ReadingFile&) -> std::unique_ptr<VolumeSource> {
            std::this_thread::sleep_for(std::chrono::seconds(30));
            return nullptr;
        },
        1);
    EXPECT_LT(std::chrono::steady_clock::now() - start, std::chrono::seconds(10));
    EXPECT_TRUE(contains(what, "took longer than its time limit")) << what;
    EXPECT_TRUE(contains(what, "1 s per file")) << what;
}

TEST(SandboxedSource, TheAlarmIsPerFileRead) {
    // Four files of 0.6 s each under a 1 s limit: 2.4 s in all, no file over its second.
    auto source = detail::openSandboxed(kParser, limits(1), [](const ReadingFile& reading) {
        for (int i = 0; i < 4; ++i) {
            reading("/data/series/" + std::to_string(i));
            std::this_thread::sleep_for(std::chrono::milliseconds(600));
        }
        return makeSynthetic(SynthKind::Checker, {8, 8, 8}, 1);
    });
    EXPECT_EQ(source->info().dims[2], 8u);
}

#if !defined(__SANITIZE_ADDRESS__)
TEST(SandboxedSource, TheAddressSpaceLimitBoundsTheChild) {
    ParserSandboxLimits small = limits();
    small.addressSpaceBytes = 1ull << 30;
    try {
        detail::openSandboxed(kParser, small, [](const ReadingFile&) {
            std::vector<char> big(4ull << 30, 1); // 4 GiB: over the limit
            return makeSynthetic(SynthKind::Checker, {8, 8, std::uint64_t(big[7])}, 1);
        });
        FAIL() << "a 4 GiB allocation passed a 1 GiB limit";
    } catch (const FormatError& e) {
        EXPECT_TRUE(contains(e.what(), "out of memory under the parser's 1024 MiB")) << e.what();
    }
}
#endif

} // namespace
} // namespace bc::brickstore
