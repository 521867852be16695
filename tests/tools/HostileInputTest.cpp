// Hostile inputs fail fast, in bounded memory, naming the file and the field. Each
// damaged input is made in a temp folder from a real scan and ingested by the real `brickcast`
// under a 4 GiB address-space limit; it must fail within 10 s. Also: SIGTERM during an ingest
// removes the partial store, and a stale partial file of a killed ingest is reported.
#include "tests/TestSupport.h"

#include <array>
#include <chrono>
#include <csignal>
#include <cstdint>
#include <cstring>
#include <filesystem>
#include <string>
#include <thread>
#include <vector>

#include <spawn.h>
#include <sys/wait.h>
#include <unistd.h>

extern char** environ;

namespace {

namespace fs = std::filesystem;
using Bytes = std::vector<std::uint8_t>;

constexpr const char* kPancreas = "tcia_pancreas_ct_dicom";
constexpr const char* kCthead = "stanford_cthead_256x256x113_uint16.raw";

bool contains(const std::string& text, const std::string& part) {
    return text.find(part) != std::string::npos;
}

struct TimedOutput {
    bc::test::CommandOutput out;
    double seconds = 0.0;
};

/// `brickcast ingest ARGS` under a 4 GiB address-space limit and a 20 s kill timer.
TimedOutput ingestLimited(const std::string& args) {
    const auto start = std::chrono::steady_clock::now();
    TimedOutput r;
    r.out = bc::test::runCommand("prlimit --as=4294967296 -- timeout -s KILL 20 " +
                                 std::string(BC_BRICKCAST_EXE) + " ingest " + args);
    r.seconds = std::chrono::duration<double>(std::chrono::steady_clock::now() - start).count();
    return r;
}

/// The ingest failed cleanly (exit status 1, not a crash or the kill timer) within 10 s and
/// said which file and which field; and left no store or partial file behind.
void expectFastNamedFailure(const TimedOutput& r, const std::string& file, const std::string& field,
                            const bc::test::TempDir& dir) {
    EXPECT_EQ(r.out.exitCode, 1) << r.out.text;
    EXPECT_LT(r.seconds, 10.0) << r.out.text;
    EXPECT_TRUE(contains(r.out.text, file)) << "does not name " << file << ": " << r.out.text;
    EXPECT_TRUE(contains(r.out.text, field)) << "does not name " << field << ": " << r.out.text;
    EXPECT_FALSE(contains(r.out.text, "bad_alloc")) << r.out.text;
    for (const auto& entry : fs::directory_iterator(dir.path()))
        EXPECT_FALSE(contains(entry.path().filename().string(), ".bcs")) << "left " << entry.path();
}

void put16(Bytes& b, std::size_t at, std::uint16_t v) {
    b[at] = std::uint8_t(v & 0xff);
    b[at + 1] = std::uint8_t(v >> 8);
}

void put32(Bytes& b, std::size_t at, std::uint32_t v) {
    for (int i = 0; i < 4; ++i)
        b[at + std::size_t(i)] = std::uint8_t(v >> (8 * i));
}

/// Offset of `pattern` in the first `limit` bytes of `b`, or npos.
std::size_t find(const Bytes& b, const std::vector<std::uint8_t>& pattern, std::size_t limit) {
    const std::size_t end = std::min(limit, b.size());
    for (std::size_t i = 0; i + pattern.size() <= end; ++i)
        if (std::memcmp(b.data() + i, pattern.data(), pattern.size()) == 0) return i;
    return std::string::npos;
}

// Implicit VR little endian (the series' transfer syntax): tag group, element, 4-byte length.
const std::vector<std::uint8_t> kRowsTag = {0x28, 0x00, 0x10, 0x00, 0x02, 0x00, 0x00, 0x00};
const std::vector<std::uint8_t> kColumnsTag = {0x28, 0x00, 0x11, 0x00, 0x02, 0x00, 0x00, 0x00};
const std::vector<std::uint8_t> kPixelDataTag = {0xe0, 0x7f, 0x10, 0x00, 0x00, 0x00, 0x08, 0x00};
constexpr const char* kSlice = "1-050.dcm";

/// Ingests a copy of the pancreas series in `dir`/series: links to the real files, but for
/// kSlice, written from `slice` (a damaged copy of it).
TimedOutput ingestSeriesWith(const bc::test::TempDir& dir, const Bytes& slice) {
    const fs::path folder = dir.path() / "series";
    const fs::directory_iterator series(bc::test::dataPath(kPancreas));
    bc::test::linkWithDamagedFile(folder, {fs::begin(series), fs::end(series)}, kSlice, slice);
    return ingestLimited(folder.string() + " -o " + dir.file("out.bcs"));
}

/// The cthead scan compressed with zstd into `dir`; empty when zstd failed.
std::string zstdCthead(const bc::test::TempDir& dir) {
    const std::string zst = dir.file("cthead.raw.zst");
    const auto out =
        bc::test::runCommand("zstd -q -c " + bc::test::dataPath(kCthead) + " > " + zst);
    return out.exitCode == 0 ? zst : std::string();
}

Bytes pancreasSlice() {
    return bc::test::readFile(bc::test::dataPath(kPancreas) + "/" + kSlice);
}

TEST(HostileInput, NiftiClaimingHugeDimsFailsFastNamingTheField) {
    if (!bc::test::haveData("CT_AVM.nii.gz")) return bc::test::missingData("CT_AVM.nii.gz");
    bc::test::TempDir dir;
    const std::string plain = dir.file("CT_huge.nii");
    ASSERT_EQ(
        bc::test::runCommand("gzip -dc " + bc::test::dataPath("CT_AVM.nii.gz") + " > " + plain)
            .exitCode,
        0);
    Bytes nii = bc::test::readFile(plain);
    ASSERT_GT(nii.size(), 352u);
    for (int i = 1; i <= 3; ++i)
        put16(nii, 40 + 2 * std::size_t(i), 32767); // dim[1..3]
    bc::test::writeFile(plain, nii.data(), nii.size());
    ASSERT_EQ(bc::test::runCommand("gzip -f " + plain).exitCode, 0);
    auto r = ingestLimited(plain + ".gz -o " + dir.file("out.bcs"));
    expectFastNamedFailure(r, "CT_huge.nii.gz", "dims", dir);
    EXPECT_TRUE(contains(r.out.text, "32767x32767x32767")) << r.out.text;
}

TEST(HostileInput, GzipNrrdClaimingHugeSizesFailsFast) {
    if (!bc::test::haveData(kCthead)) return bc::test::missingData(kCthead);
    bc::test::TempDir dir;
    const std::string data = dir.file("cthead.raw.gz"), nrrd = dir.file("huge.nrrd");
    ASSERT_EQ(
        bc::test::runCommand("gzip -1 -c " + bc::test::dataPath(kCthead) + " > " + data).exitCode,
        0);
    const Bytes gz = bc::test::readFile(data);
    std::string text = "NRRD0004\ntype: uint16\ndimension: 3\nsizes: 40000 40000 4\n"
                       "endian: little\nencoding: gzip\n\n";
    text.append(gz.begin(), gz.end());
    bc::test::writeFile(nrrd, text);
    auto r = ingestLimited(nrrd + " -o " + dir.file("out.bcs"));
    expectFastNamedFailure(r, "huge.nrrd", "dims", dir);
}

TEST(HostileInput, ZstdRawWithHugeDimsFailsFast) {
    if (!bc::test::haveData(kCthead)) return bc::test::missingData(kCthead);
    bc::test::TempDir dir;
    const std::string zst = zstdCthead(dir);
    ASSERT_FALSE(zst.empty()) << "zstd failed";
    auto r = ingestLimited(zst + " --dims 40000,40000,4 --type u16 -o " + dir.file("out.bcs"));
    expectFastNamedFailure(r, "cthead.raw.zst", "dims", dir);
}

// A zstd payload whose frames declare exactly dims that fit every limit but not the file's
// content: the frame sizes, not only the edge and slice limits, are checked.
TEST(HostileInput, ZstdRawWhoseFramesDeclareOtherSizeFailsBeforeReading) {
    if (!bc::test::haveData(kCthead)) return bc::test::missingData(kCthead);
    bc::test::TempDir dir;
    const std::string zst = zstdCthead(dir);
    ASSERT_FALSE(zst.empty()) << "zstd failed";
    auto r = ingestLimited(zst + " --dims 1024,1024,64 --type u16 -o " + dir.file("out.bcs"));
    expectFastNamedFailure(r, "cthead.raw.zst", "size", dir);
    EXPECT_TRUE(contains(r.out.text, "zstd frames declare 14811136")) << r.out.text;
}

/// Sets a slice's Rows and Columns to `value` in place; false when the tags are not found.
bool setRowsAndColumns(Bytes& slice, std::uint16_t value) {
    const std::size_t pixels = find(slice, kPixelDataTag, slice.size());
    const std::size_t rows = find(slice, kRowsTag, pixels),
                      columns = find(slice, kColumnsTag, pixels);
    if (pixels == std::string::npos || rows == std::string::npos || columns == std::string::npos)
        return false;
    put16(slice, rows + 8, value);
    put16(slice, columns + 8, value);
    return true;
}

// One slice claiming 65535 x 65535: refused by the slice limit, naming that file.
TEST(HostileInput, DicomSliceWithHugeRowsAndColumnsFailsFast) {
    if (!bc::test::haveData(kPancreas)) return bc::test::missingData(kPancreas);
    bc::test::TempDir dir;
    Bytes slice = pancreasSlice();
    ASSERT_TRUE(setRowsAndColumns(slice, 65535));
    auto r = ingestSeriesWith(dir, slice);
    expectFastNamedFailure(r, kSlice, "Rows/Columns", dir);
    EXPECT_TRUE(contains(r.out.text, "exceeds the limit")) << r.out.text;
}

// Every slice claiming 65535 x 65535 (a consistent series, so no mismatch to catch): the
// first slice read is refused before any buffer of that size exists.
TEST(HostileInput, DicomSeriesWithHugeRowsAndColumnsFailsFast) {
    if (!bc::test::haveData(kPancreas)) return bc::test::missingData(kPancreas);
    bc::test::TempDir dir;
    const fs::path folder = dir.path() / "series";
    fs::create_directories(folder);
    for (const auto& entry : fs::directory_iterator(bc::test::dataPath(kPancreas))) {
        Bytes bytes = bc::test::readFile(entry.path().string());
        if (entry.path().extension() == ".dcm") {
            ASSERT_TRUE(setRowsAndColumns(bytes, 65535));
        }
        bc::test::writeFile((folder / entry.path().filename()).string(), bytes.data(),
                            bytes.size());
    }
    auto r = ingestLimited(folder.string() + " -o " + dir.file("out.bcs"));
    expectFastNamedFailure(r, ".dcm", "Rows/Columns", dir);
}

TEST(HostileInput, HugeGeneratedVolumeFailsFast) {
    bc::test::TempDir dir;
    auto r = ingestLimited("synth:vessels --dims 100000,100000,100000 -o " + dir.file("out.bcs"));
    expectFastNamedFailure(r, "synth:vessels", "dims", dir);
}

// The memory budget itself: dims within every format limit whose slab buffers do not fit.
TEST(HostileInput, IngestOverTheMemoryBudgetFailsNamingTheBudget) {
    bc::test::TempDir dir;
    auto r = ingestLimited("synth:checker --dims 8192,8192,8 --memory-budget-mb 256 -o " +
                           dir.file("out.bcs"));
    expectFastNamedFailure(r, "synth:checker", "dims", dir);
    EXPECT_TRUE(contains(r.out.text, "over the ingest memory budget of 268.4 MB")) << r.out.text;
    EXPECT_TRUE(contains(r.out.text, "--memory-budget-mb")) << r.out.text;
}

// A budget set above what the process may really allocate (300 MB of address space): the
// allocation fails, and the user is told what ran out, on which input, and what to change.
TEST(HostileInput, OutOfMemoryIsExplainedWithTheInputAndStore) {
    bc::test::TempDir dir;
    const std::string store = dir.file("out.bcs");
    auto out = bc::test::runCommand(
        "prlimit --as=300000000 -- " + std::string(BC_BRICKCAST_EXE) +
        " ingest synth:phantom --dims 2048,2048,160 --memory-budget-mb 4000 --threads 1 -o " +
        store);
    EXPECT_EQ(out.exitCode, 1) << out.text;
    EXPECT_TRUE(contains(out.text, "out of memory while ingesting synth:phantom (2048x2048x160)"))
        << out.text;
    EXPECT_TRUE(contains(out.text, store)) << out.text;
    EXPECT_FALSE(fs::exists(store));
}

TEST(HostileInput, DicomSliceWithShortPixelDataFails) {
    if (!bc::test::haveData(kPancreas)) return bc::test::missingData(kPancreas);
    bc::test::TempDir dir;
    Bytes slice = pancreasSlice();
    const std::size_t pixels = find(slice, kPixelDataTag, slice.size());
    ASSERT_NE(pixels, std::string::npos);
    put32(slice, pixels + 4, 1000); // PixelData's length, and only 1000 bytes of it
    slice.resize(pixels + 8 + 1000);
    auto r = ingestSeriesWith(dir, slice);
    expectFastNamedFailure(r, kSlice, "PixelData", dir);
    EXPECT_TRUE(contains(r.out.text, "declares 1000 bytes")) << r.out.text;
}

TEST(HostileInput, DicomSliceCutShortFails) {
    if (!bc::test::haveData(kPancreas)) return bc::test::missingData(kPancreas);
    bc::test::TempDir dir;
    Bytes slice = pancreasSlice();
    slice.resize(slice.size() - 300000);
    auto r = ingestSeriesWith(dir, slice);
    expectFastNamedFailure(r, kSlice, "PixelData", dir);
    EXPECT_TRUE(contains(r.out.text, "truncated")) << r.out.text;
}

// A slice cut inside its file meta group makes Debian's GDCM assert (abort); GDCM
// runs in the sandboxed child, so ingest fails with a short error naming that file; GDCM's
// assertion text is in that error line only, not printed above it.
TEST(HostileInput, DicomSliceThatMakesGdcmAssertFailsNamingIt) {
    if (!bc::test::haveData(kPancreas)) return bc::test::missingData(kPancreas);
    bc::test::TempDir dir;
    Bytes slice = pancreasSlice();
    const std::vector<std::uint8_t> implementationClassUid = {0x02, 0x00, 0x12, 0x00, 'U', 'I'};
    const std::size_t at = find(slice, implementationClassUid, slice.size());
    ASSERT_NE(at, std::string::npos);
    slice.resize(at + 8 + (slice[at + 6] | slice[at + 7] << 8));
    auto r = ingestSeriesWith(dir, slice);
    expectFastNamedFailure(r, kSlice, "file", dir);
    EXPECT_TRUE(contains(r.out.text, "DICOM parser aborted")) << r.out.text;
    const std::size_t assertion = r.out.text.find("Should not happen");
    ASSERT_NE(assertion, std::string::npos) << r.out.text;
    EXPECT_EQ(r.out.text.find("Should not happen", assertion + 1), std::string::npos) << r.out.text;
    const std::size_t line = r.out.text.rfind('\n', assertion);
    const std::string errorLine = r.out.text.substr(line == std::string::npos ? 0 : line + 1);
    EXPECT_EQ(errorLine.rfind("brickcast: bad input: ", 0), 0u) << r.out.text;
}

/// Starts `program ARGS...` as a child; returns its pid (-1 when it cannot).
pid_t spawn(const std::string& program, const std::vector<std::string>& args) {
    std::vector<std::string> all = {program};
    all.insert(all.end(), args.begin(), args.end());
    std::vector<char*> argv;
    for (auto& a : all)
        argv.push_back(a.data());
    argv.push_back(nullptr);
    pid_t pid = -1;
    if (::posix_spawn(&pid, program.c_str(), nullptr, nullptr, argv.data(), environ) != 0)
        return -1;
    return pid;
}

pid_t spawnIngest(std::vector<std::string> args) {
    args.insert(args.begin(), "ingest");
    return spawn(BC_BRICKCAST_EXE, args);
}

bool hasPartial(const fs::path& folder) {
    for (const auto& entry : fs::directory_iterator(folder))
        if (contains(entry.path().filename().string(), ".partial.")) return true;
    return false;
}

TEST(HostileInput, SigtermDuringIngestRemovesThePartialStore) {
    bc::test::TempDir dir;
    const std::string store = dir.file("big.bcs");
    // About 1 GiB of voxels on one worker: tens of seconds, far longer than the wait below.
    const pid_t pid = spawnIngest(
        {"synth:phantom", "--dims", "1024,1024,512", "--threads", "1", "-q", "-o", store});
    ASSERT_GT(pid, 0);
    const auto deadline = std::chrono::steady_clock::now() + std::chrono::seconds(10);
    while (!hasPartial(dir.path()) && std::chrono::steady_clock::now() < deadline)
        std::this_thread::sleep_for(std::chrono::milliseconds(20));
    const bool started = hasPartial(dir.path());
    std::this_thread::sleep_for(std::chrono::milliseconds(200));
    ASSERT_EQ(::kill(pid, SIGTERM), 0);
    const auto signalled = std::chrono::steady_clock::now();
    int status = 0;
    ASSERT_EQ(::waitpid(pid, &status, 0), pid);
    const double seconds =
        std::chrono::duration<double>(std::chrono::steady_clock::now() - signalled).count();
    ASSERT_TRUE(started) << "the ingest never created its partial file";
    EXPECT_TRUE(WIFSIGNALED(status) && WTERMSIG(status) == SIGTERM)
        << "status " << status << ": the process should end by the signal it was sent";
    EXPECT_LT(seconds, 5.0);
    EXPECT_FALSE(hasPartial(dir.path())) << "a .partial. file remains after SIGTERM";
    EXPECT_FALSE(fs::exists(store));
}

TEST(HostileInput, StalePartialOfAKilledIngestIsRemovedAndReported) {
    bc::test::TempDir dir;
    const std::string store = dir.file("s.bcs");
    // The pid of a process that has exited: what a kill -9 leaves in the name.
    const pid_t gone = spawn("/bin/true", {});
    ASSERT_GT(gone, 0);
    int status = 0;
    ::waitpid(gone, &status, 0);
    const std::string stale = store + ".partial." + std::to_string(gone);
    bc::test::writeFile(stale, "half a store");
    auto r = bc::test::runCommand(std::string(BC_BRICKCAST_EXE) +
                                  " ingest synth:checker --dims 16,16,16 -q -o " + store);
    EXPECT_EQ(r.exitCode, 0) << r.text;
    EXPECT_FALSE(fs::exists(stale));
    EXPECT_TRUE(contains(r.text, "removed " + stale)) << r.text;
    EXPECT_TRUE(fs::exists(store));
}

} // namespace
