// libFuzzer target of the DICOM series reader over GDCM (scripts/fuzz.sh dicom builds and
// runs it): our length pre-walk, our wrapper's checks of the headers GDCM parses (counts,
// lengths, geometry, consistency across slices) and of the pixel data it decodes, and the
// parser sandbox that contains GDCM's own aborts.
//
// Input: one to four files separated by "BCSPLIT!", written into a fresh folder of a private
// scratch folder. Each input is run three ways:
//  1. the length pre-walk (detail::checkDicomLengths) on each file, in process;
//  2. when GDCM would read a file (the pre-walk passes one), openDicomSeries, as ingest runs
//     it: GDCM in the sandboxed child. Its error must name a file of the folder (or the
//     folder) and stay under 1 kB;
//  3. unless GDCM aborted in the child or it ran out of a limit (the sandbox's job, not a
//     finding), the same reader in process (detail::openDicomSeriesInProcess), so that
//     libFuzzer sees the coverage of our code (a child's is lost to it) and a sanitizer
//     report in our code or GDCM's happens where libFuzzer catches it.
// A FormatError is the expected refusal; a crash, sanitizer report, other exception, a child
// that died where the in-process run did not, or a volume that validateVolumeInfo rejects is a
// finding. Slices are then read (tests/fuzz/ReaderFuzz.h).
//
// With BC_FUZZ_SEED_DIR set, the binary first writes seeds there from the real series
// (BC_SHARED_DATA_DIR/tcia_pancreas_ct_dicom, implicit VR little endian): a real file's
// header with a truncated payload, and series of 1 and 3 real headers cropped to 16x16
// pixels (Rows, Columns and the pixel data length patched) with their pixels.
#include "brickstore/Readers.h"
#include "brickstore/readers/detail/DicomLengths.h"
#include "brickstore/readers/detail/DicomSeries.h"
#include "tests/fuzz/ReaderFuzz.h"

#include <algorithm>
#include <csignal>
#include <cstdio>
#include <cstdlib>
#include <cstring>
#include <string_view>

namespace {

using namespace bc;
using fuzz::Bytes;

constexpr std::string_view kSplit = "BCSPLIT!";
constexpr std::size_t kMaxFiles = 4;

/// Offset of the value of implicit-VR element (group, element) after its tag and length;
/// 0 when absent.
std::size_t valueOffset(const Bytes& b, std::uint16_t group, std::uint16_t element) {
    const std::uint8_t tag[4] = {std::uint8_t(group), std::uint8_t(group >> 8),
                                 std::uint8_t(element), std::uint8_t(element >> 8)};
    const auto at = std::search(b.begin() + std::min<std::size_t>(132, b.size()), b.end(),
                                std::begin(tag), std::end(tag));
    return at == b.end() ? 0 : std::size_t(at - b.begin()) + 8;
}

void setU16(Bytes& b, std::size_t at, std::uint16_t v) {
    if (at + 2 <= b.size()) std::memcpy(b.data() + at, &v, 2);
}

/// A real slice cropped to 16x16 pixels; empty if its layout is not the expected one.
Bytes cropSlice(const Bytes& real) {
    const std::size_t rows = valueOffset(real, 0x0028, 0x0010),
                      columns = valueOffset(real, 0x0028, 0x0011),
                      pixels = valueOffset(real, 0x7fe0, 0x0010);
    if (!rows || !columns || !pixels || pixels > real.size()) return {};
    std::uint16_t x = 0, y = 0;
    std::memcpy(&y, real.data() + rows, 2);
    std::memcpy(&x, real.data() + columns, 2);
    const Bytes voxels = fuzz::cropVoxels(real, pixels, x, y, 2, 16, 16, 1);
    if (voxels.empty()) return {};
    Bytes out(real.begin(), real.begin() + std::ptrdiff_t(pixels));
    setU16(out, rows, 16);
    setU16(out, columns, 16);
    const std::uint32_t length = std::uint32_t(voxels.size());
    std::memcpy(out.data() + pixels - 4, &length, 4);
    out.insert(out.end(), voxels.begin(), voxels.end());
    return out;
}

void writeSeeds(const std::string& seeds) {
    const std::string data = fuzz::sharedData();
    if (data.empty()) return;
    const std::filesystem::path series = std::filesystem::path(data) / "tcia_pancreas_ct_dicom";
    std::vector<Bytes> cropped;
    for (const char* name : {"1-001.dcm", "1-002.dcm", "1-003.dcm"}) {
        const Bytes real = fuzz::readFile(series / name);
        if (real.empty()) return;
        if (cropped.empty()) {
            const std::size_t pixels = valueOffset(real, 0x7fe0, 0x0010);
            if (pixels)
                fuzz::writeSeed(
                    seeds, "truncated",
                    Bytes(real.begin(),
                          real.begin() + std::ptrdiff_t(std::min(real.size(), pixels + 2048))));
        }
        cropped.push_back(cropSlice(real));
        if (cropped.back().empty()) return;
    }
    fuzz::writeSeed(seeds, "one-slice", cropped[0]);
    Bytes three;
    for (const Bytes& slice : cropped) {
        if (!three.empty()) three.insert(three.end(), kSplit.begin(), kSplit.end());
        three.insert(three.end(), slice.begin(), slice.end());
    }
    fuzz::writeSeed(seeds, "three-slices", three);
}

/// A fresh, empty series folder for each input.
std::filesystem::path seriesFolder() {
    const std::filesystem::path dir = fuzz::scratchDir() / "series";
    std::filesystem::remove_all(dir);
    std::filesystem::create_directory(dir);
    return dir;
}

/// Step 1: the pre-walk on every file, in process. Returns whether GDCM would read any file:
/// openDicomSeries walks each file (in name order) before GDCM reads it, skips one that is not
/// DICOM and stops at one whose lengths are wrong.
bool walkLengths(const std::filesystem::path& dir) {
    std::vector<std::string> files;
    for (const auto& entry : std::filesystem::directory_iterator(dir))
        files.push_back(entry.path().string());
    std::sort(files.begin(), files.end());
    bool gdcmReads = false, stopped = false;
    for (const std::string& file : files) {
        try {
            const bool dicom = brickstore::detail::checkDicomLengths(file);
            gdcmReads = gdcmReads || (dicom && !stopped);
        } catch (const brickstore::FormatError& e) {
            fuzz::require(e.file() == file, "a length error names another file");
            stopped = true;
        }
    }
    return gdcmReads;
}

/// A child that ended in a way the sandbox exists for: GDCM's assertion (SIGABRT) or a limit.
bool containedDeath(const brickstore::detail::ParserDied& e) {
    return e.signal() == SIGABRT || e.signal() == SIGALRM || e.signal() == SIGXCPU ||
           e.signal() == SIGKILL;
}

/// Step 2: the sandboxed reader. Returns the child's death when it is not a contained one.
std::string runSandboxed(const std::filesystem::path& dir, bool& contained) {
    const std::string folder = dir.string();
    try {
        // Not exerciseVolume: it takes a FormatError while reading for a refusal, and a child
        // that dies while decoding must be seen here. The same slices as it reads, so that the
        // in-process run decodes none the child has not.
        auto source = brickstore::openDicomSeries(folder);
        const brickstore::VolumeInfo& info = source->info();
        const std::uint64_t sliceBytes = info.sliceBytes();
        if (sliceBytes > fuzz::kMaxFuzzSliceBytes) return {};
        const bool whole = sliceBytes * info.dims[2] <= fuzz::kMaxFuzzVolumeBytes;
        const std::uint64_t slices =
            whole ? info.dims[2] : std::min<std::uint64_t>(3, info.dims[2]);
        std::vector<std::byte> slice(sliceBytes);
        for (std::uint64_t z = 0; z < slices; ++z)
            source->readSlices(1, slice);
        return {};
    } catch (const brickstore::FormatError& e) {
        fuzz::require(std::strlen(e.what()) < 1024, "a sandboxed reader's error is over 1 kB");
        fuzz::require(e.file().compare(0, folder.size(), folder) == 0,
                      "a sandboxed reader's error names no file of the series");
        const auto* died = dynamic_cast<const brickstore::detail::ParserDied*>(&e);
        if (!died) return {};
        contained = containedDeath(*died);
        return contained ? std::string() : e.what();
    }
}

} // namespace

extern "C" int LLVMFuzzerTestOneInput(const std::uint8_t* data, std::size_t size) {
    const std::filesystem::path dir = seriesFolder();
    std::string_view rest(reinterpret_cast<const char*>(data), size);
    for (std::size_t i = 0; i < kMaxFiles && (i == 0 || !rest.empty()); ++i) {
        const std::size_t end = i + 1 == kMaxFiles ? rest.npos : rest.find(kSplit);
        const std::string_view file = rest.substr(0, end);
        fuzz::writeFile(dir / ("slice-" + std::to_string(i) + ".dcm"),
                        {reinterpret_cast<const std::uint8_t*>(file.data()), file.size()});
        rest = end == rest.npos ? std::string_view() : rest.substr(end + kSplit.size());
    }
    bool contained = false;
    std::string death;
    // Forking costs ~10 ms of a sanitized process: only inputs that reach GDCM go through the
    // sandbox (the others cannot abort in process).
    if (walkLengths(dir)) death = runSandboxed(dir, contained);
    if (contained) return 0;
    try {
        auto source = brickstore::detail::openDicomSeriesInProcess(dir.string());
        fuzz::exerciseVolume(*source, dir.string());
    } catch (const brickstore::FormatError&) {
    }
    // The child died of something the in-process run survived (a sanitizer report there, a
    // crash signal): not reproduced here, so report it as it is.
    if (!death.empty()) {
        std::fprintf(stderr, "sandboxed child died, in-process run did not: %s\n", death.c_str());
        std::abort();
    }
    return 0;
}

extern "C" int LLVMFuzzerInitialize(int*, char***) {
    if (const std::string seeds = fuzz::envFolder("BC_FUZZ_SEED_DIR"); !seeds.empty())
        writeSeeds(seeds);
    // The child's parse alarm fires before libFuzzer's 10 s timeout of the whole input.
    brickstore::ParserSandboxLimits limits;
    limits.parseSeconds = 4;
    limits.cpuSeconds = 8;
    brickstore::setParserSandboxLimits(limits);
    return 0;
}
