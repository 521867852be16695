// A FIFO (or any file that is not a regular one) named as a store or as an ingest input is
// refused at once with an error naming it: open() of a FIFO waits for a writer, so a daemon
// given one as a store never finished starting, and an ingest given one never began.
#include "brickstore/BrickStore.h"
#include "brickstore/Error.h"
#include "brickstore/Readers.h"
#include "tests/TestSupport.h"
#include "tests/brickstore/RawTestSupport.h"

#include <chrono>
#include <filesystem>
#include <functional>
#include <future>
#include <string>
#include <vector>

#include <fcntl.h>
#include <sys/stat.h>
#include <unistd.h>

namespace bc::brickstore {
namespace {

namespace fs = std::filesystem;
using Clock = std::chrono::steady_clock;

/// How a call that had to refuse a FIFO ended.
struct Outcome {
    std::string error;     ///< what() of what it threw; empty when it returned
    std::string errorType; ///< "FormatError", "StoreIoError", "other"
    double seconds = 0;
    bool released = false; ///< it blocked until the test opened the FIFO for writing
};

/// Runs `call` on a thread of its own. One still running after `limitS` seconds is blocked on
/// the FIFO: opening and closing `fifo` for writing releases it (its open returns, its reads
/// see the end), so that the test fails instead of hanging.
Outcome runReleasing(const std::function<void()>& call, const std::string& fifo, double limitS) {
    const auto start = Clock::now();
    auto done = std::async(std::launch::async, [&call]() -> std::pair<std::string, std::string> {
        try {
            call();
        } catch (const FormatError& e) {
            return {e.what(), "FormatError"};
        } catch (const StoreIoError& e) {
            return {e.what(), "StoreIoError"};
        } catch (const std::exception& e) {
            return {e.what(), "other"};
        }
        return {};
    });
    Outcome out;
    const auto limit = std::chrono::duration<double>(limitS * test::timeScale());
    if (done.wait_for(limit) == std::future_status::timeout) {
        out.released = true;
        while (done.wait_for(std::chrono::milliseconds(50)) == std::future_status::timeout) {
            const int fd = ::open(fifo.c_str(), O_WRONLY | O_NONBLOCK | O_CLOEXEC);
            if (fd >= 0) ::close(fd);
        }
    }
    std::tie(out.error, out.errorType) = done.get();
    out.seconds = std::chrono::duration<double>(Clock::now() - start).count();
    return out;
}

std::string makeFifo(const test::TempDir& dir, const std::string& name) {
    const std::string path = dir.file(name);
    EXPECT_EQ(::mkfifo(path.c_str(), 0600), 0) << path;
    return path;
}

void expectRefusedAtOnce(const Outcome& o, const std::string& path, const std::string& type) {
    EXPECT_FALSE(o.released) << path << ": blocked until a writer came (" << o.seconds
                             << " s), then: " << o.error;
    EXPECT_LT(o.seconds, 1.0 * test::timeScale()) << path;
    EXPECT_EQ(o.errorType, type) << o.error;
    EXPECT_NE(o.error.find(path), std::string::npos) << o.error;
    EXPECT_NE(o.error.find("not a regular file (a FIFO)"), std::string::npos) << o.error;
}

TEST(FifoTest, StoreThatIsAFifoIsRefusedAtOnce) {
    test::TempDir dir;
    const std::string path = makeFifo(dir, "s.bcs");
    const Outcome o = runReleasing([&] { BrickStore::open(path); }, path, 2.0);
    expectRefusedAtOnce(o, path, "StoreIoError");
}

TEST(FifoTest, IngestInputThatIsAFifoIsRefusedAtOnce) {
    // Every reader of a file: raw (plain and zstd), NRRD, NIfTI, MetaImage, VTI, TIFF, HDF5,
    // OpenVDB. A pipe never was a raw input: its size is checked against the dims first.
    for (const std::string name : {"v_8x8x8_uint8.raw", "v_8x8x8_uint8.raw.zst", "v.nrrd", "v.nii",
                                   "v.nii.gz", "v.mha", "v.vti", "v.tif", "v.h5", "v.vdb"}) {
        test::TempDir dir;
        SourceSpec spec;
        spec.input = makeFifo(dir, name);
        spec.dataset = "/v";
        const Outcome o = runReleasing([&] { openSource(spec); }, spec.input, 2.0);
        expectRefusedAtOnce(o, spec.input, "FormatError");
    }
}

TEST(FifoTest, DetachedNrrdDataThatIsAFifoIsRefusedAtOnce) {
    test::TempDir dir;
    test::writeFile(dir.file("v.nhdr"), "NRRD0004\ntype: uint8\ndimension: 3\nsizes: 8 8 8\n"
                                        "encoding: raw\ndata file: v.raw\n");
    const std::string data = makeFifo(dir, "v.raw");
    const Outcome o = runReleasing([&] { openNrrd(dir.file("v.nhdr")); }, data, 2.0);
    expectRefusedAtOnce(o, data, "FormatError");
}

TEST(FifoTest, ZarrChunkThatIsAFifoIsRefusedAtOnce) {
    test::TempDir dir;
    fs::create_directories(dir.path() / "vol");
    test::writeFile(dir.file("vol/.zarray"),
                    R"({"zarr_format": 2, "shape": [4, 4, 4], "chunks": [4, 4, 4], )"
                    R"("dtype": "|u1", "order": "C", "fill_value": 0, "filters": null, )"
                    R"("compressor": null})");
    const std::string chunk = makeFifo(dir, "vol/0.0.0");
    const Outcome o = runReleasing(
        [&] {
            auto source = openZarr(dir.file("vol"), 0);
            std::vector<std::byte> slices(4 * 4 * 4);
            source->readSlices(4, slices);
        },
        chunk, 2.0);
    EXPECT_FALSE(o.released) << "blocked until a writer came: " << o.error;
    EXPECT_LT(o.seconds, 1.0 * test::timeScale());
    EXPECT_EQ(o.errorType, "FormatError") << o.error;
    EXPECT_NE(o.error.find(chunk + ": chunk: "), std::string::npos) << o.error;
}

} // namespace
} // namespace bc::brickstore
