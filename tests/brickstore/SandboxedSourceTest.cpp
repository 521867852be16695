// The parser sandbox (brickstore/readers/detail/SandboxedSource.h) with openers written here:
// a volume crosses the pipe byte for byte, in every voxel type; and each way a child can end
// early (an exception, an abort while opening or while streaming, the alarm, the address-space
// limit) is one FormatError under 1 kB naming the file the parser was reading, and quoting the
// end of what the child printed to its stderr instead of letting it reach ours. A SliceLocator's
// slices (located in files the parent reads itself, or decoded through the pipe) arrive in
// order, and extents that lie (outside the files, past the volume or a file's end) and NaN in a
// located float slice are errors naming the file.
#include "brickstore/readers/detail/SandboxedSource.h"
#include "brickstore/Error.h"
#include "brickstore/Readers.h"
#include "tests/TestSupport.h"
#include "tests/brickstore/VolumeTestSupport.h"

#include <gtest/gtest.h>

#include <chrono>
#include <csignal>
#include <cstdio>
#include <cstdlib>
#include <cstring>
#include <filesystem>
#include <functional>
#include <limits>
#include <thread>
#include <vector>

namespace bc::brickstore {
namespace {

using detail::ParserDied;
using detail::ReadingFile;

const detail::SandboxedParser kParser{"/data/series", "test", "per file", {}};

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

/// A volume whose slices lie in files the test wrote: `locate` says where (or refuses, and the
/// slice is then sent through the pipe from `voxels`).
class LocatedVolume final : public VolumeSource, public detail::SliceLocator {
  public:
    using Locate = std::function<bool(std::uint64_t z, std::vector<detail::FileExtent>&)>;
    LocatedVolume(const VolumeInfo& info, std::vector<std::byte> voxels, Locate locate)
        : mInfo(info), mVoxels(std::move(voxels)), mLocate(std::move(locate)) {}
    const VolumeInfo& info() const override { return mInfo; }
    bool locateSlice(std::uint64_t z, std::vector<detail::FileExtent>& out) override {
        return mLocate(z, out);
    }
    void decodeSlice(std::uint64_t z, std::span<std::byte> out) override {
        std::memcpy(out.data(), mVoxels.data() + z * mInfo.sliceBytes(), out.size());
    }

  private:
    void readNextSlices(std::uint64_t, std::span<std::byte>) override {
        std::abort(); // the sandbox must use locateSlice and decodeSlice
    }
    VolumeInfo mInfo;
    std::vector<std::byte> mVoxels;
    Locate mLocate;
};

/// A u16 volume of 33x17x12 and two files holding its slices out of order: slice z at
/// kGap + z * (slice + kGap) of a.bin, except that slice 5's first 100 bytes are in b.bin.
struct LocatedFiles {
    static constexpr std::uint64_t kGap = 7;
    test::TempDir dir;
    VolumeInfo info;
    std::vector<std::byte> voxels;
    detail::SandboxedParser parser{
        dir.file("a.bin"), "test", "per file", {dir.file("a.bin"), dir.file("b.bin")}};

    LocatedFiles() {
        auto synthetic = makeSynthetic(SynthKind::Phantom, {33, 17, 12}, 3);
        info = synthetic->info();
        voxels = test::readAllSlices(*synthetic, 12);
        const std::uint64_t slice = info.sliceBytes();
        std::vector<std::byte> a(kGap + 12 * (slice + kGap), std::byte{0xee});
        for (std::uint64_t z = 0; z < 12; ++z)
            std::memcpy(a.data() + kGap + z * (slice + kGap), voxels.data() + z * slice, slice);
        test::writeFile(dir.file("a.bin"), a.data(), a.size());
        test::writeFile(dir.file("b.bin"), voxels.data() + 5 * slice, 100);
    }
    /// Where slice z lies: the truthful map.
    void locate(std::uint64_t z, std::vector<detail::FileExtent>& out) const {
        const std::uint64_t slice = info.sliceBytes(), at = kGap + z * (slice + kGap);
        if (z == 5) {
            out.push_back({1, 0, 100});
            out.push_back({0, at + 100, slice - 100});
        } else {
            out.push_back({0, at, slice});
        }
    }
};

TEST(SandboxedSource, LocatedAndDecodedSlicesArriveInOrder) {
    LocatedFiles files;
    for (const std::uint64_t decodedEvery : {1, 3, 1000}) {
        auto source = detail::openSandboxed(files.parser, limits(), [&](const ReadingFile&) {
            return std::make_unique<LocatedVolume>(
                files.info, files.voxels,
                [&files, decodedEvery](std::uint64_t z, std::vector<detail::FileExtent>& out) {
                    if (decodedEvery != 1000 && z % decodedEvery == 1) return false;
                    files.locate(z, out);
                    return true;
                });
        });
        EXPECT_EQ(test::readAllSlices(*source, {1, 5, 2}), files.voxels)
            << "every " << decodedEvery << " slices decoded";
    }
}

/// The error a located volume whose map `lie` rewrites ends with.
std::string lyingLocatorError(LocatedFiles& files,
                              std::function<void(std::uint64_t, detail::FileExtent&)> lie) {
    try {
        auto source = detail::openSandboxed(files.parser, limits(), [&](const ReadingFile&) {
            return std::make_unique<LocatedVolume>(
                files.info, files.voxels,
                [&files, lie](std::uint64_t z, std::vector<detail::FileExtent>& out) {
                    files.locate(z, out);
                    lie(z, out.back());
                    return true;
                });
        });
        test::readAllSlices(*source, 4);
    } catch (const FormatError& e) {
        EXPECT_LT(std::strlen(e.what()), 1024u) << e.what();
        return e.what();
    }
    ADD_FAILURE() << "the lying locator's volume read without an error";
    return {};
}

TEST(SandboxedSource, ExtentsOutsideTheFilesOrTheVolumeAreRefused) {
    LocatedFiles files;
    const std::string notAFile = lyingLocatorError(files, [](std::uint64_t z, auto& e) {
        if (z == 6) e.file = 2; // only a.bin and b.bin are listed
    });
    EXPECT_TRUE(contains(notAFile, "an extent outside the volume's files or bytes")) << notAFile;
    const std::string tooMany = lyingLocatorError(files, [](std::uint64_t z, auto& e) {
        if (z == 11) e.bytes += 2; // more bytes than the volume holds
    });
    EXPECT_TRUE(contains(tooMany, "an extent outside the volume's files or bytes")) << tooMany;
    const std::string wraps = lyingLocatorError(files, [](std::uint64_t z, auto& e) {
        if (z == 3) e.offset = UINT64_MAX - 10;
    });
    EXPECT_TRUE(contains(wraps, "an extent outside the volume's files or bytes")) << wraps;
}

TEST(SandboxedSource, AnExtentPastItsFilesEndNamesTheFile) {
    LocatedFiles files;
    const std::string what = lyingLocatorError(files, [&files](std::uint64_t z, auto& e) {
        if (z == 2) e.offset = 1ull << 40;
    });
    EXPECT_EQ(what.rfind(files.dir.file("a.bin") + ": data: ends at byte 1099511627776", 0), 0u)
        << what;
}

TEST(SandboxedSource, NaNInALocatedFloatSliceNamesItsFileAndVoxel) {
    test::TempDir dir;
    VolumeInfo info;
    info.dims = {4, 3, 2};
    info.type = VoxelType::F32;
    std::vector<float> values(24, 1.5f);
    values[12 + 2 * 4 + 1] = std::numeric_limits<float>::quiet_NaN(); // slice 1, voxel (1,2)
    test::writeFile(dir.file("s0.raw"), values.data(), 48);
    test::writeFile(dir.file("s1.raw"), values.data() + 12, 48);
    const detail::SandboxedParser parser{
        dir.path().string(), "test", "per file", {dir.file("s0.raw"), dir.file("s1.raw")}};
    std::vector<std::byte> none(96);
    try {
        auto source = detail::openSandboxed(parser, limits(), [&](const ReadingFile&) {
            return std::make_unique<LocatedVolume>(
                info, none, [](std::uint64_t z, std::vector<detail::FileExtent>& out) {
                    out.push_back({std::uint32_t(z), 0, 48});
                    return true;
                });
        });
        test::readAllSlices(*source, 2);
        FAIL() << "a NaN voxel was read";
    } catch (const FormatError& e) {
        EXPECT_EQ(e.file(), dir.file("s1.raw")) << e.what();
        EXPECT_EQ(e.field(), "data") << e.what();
        EXPECT_TRUE(contains(e.what(), "voxel (1,2) is NaN")) << e.what();
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
