// libFuzzer target of the NRRD reader (scripts/fuzz.sh nrrd_header builds and runs it).
//
// Input: the bytes of a .nrrd/.nhdr file, written to a private scratch folder and opened with
// openNrrd, as ingest would; the folder also holds data.raw and data.raw.gz (16x16x8 u8) for
// detached headers. A FormatError is the expected refusal; a crash, sanitizer report, other
// exception or a volume that validateVolumeInfo rejects is a finding. Slices are then read
// (tests/fuzz/ReaderFuzz.h).
//
// With BC_FUZZ_SEED_DIR set, the binary first writes seeds there: NRRD headers of the real
// scans (BC_SHARED_DATA_DIR) cropped to 32x32x4 voxels with their data attached raw and gzip,
// truncated copies, and detached headers naming data.raw and data.raw.gz.
#include "brickstore/Readers.h"
#include "tests/fuzz/ReaderFuzz.h"

namespace {

using namespace bc;
using fuzz::Bytes;
using fuzz::gzipBytes;

const std::filesystem::path& folder() {
    static const std::filesystem::path dir = [] {
        const auto& d = fuzz::scratchDir();
        const Bytes voxels = fuzz::detachedVoxels();
        fuzz::writeFile(d / "data.raw", voxels);
        fuzz::writeFile(d / "data.raw.gz", gzipBytes(voxels));
        return d;
    }();
    return dir;
}

void writeScanSeeds(const std::string& seeds, const std::string& data) {
    const fuzz::SeedScan scans[] = {
        {"vtk_headsq_quarter_64x64x93_uint16.raw", "ushort", 64, 64, 2, "3.2 3.2 1.5"},
        {"hydrogen_64x64x64_float32.raw", "float", 64, 64, 4, "1 1 1"},
        {"CT_AVM_256x242x154_uint8.raw", "uchar", 256, 242, 1, "0.72 0.721 1"},
    };
    int n = 0;
    for (const fuzz::SeedScan& s : scans) {
        const unsigned slices = 4, edge = fuzz::kSeedEdge;
        const Bytes voxels = fuzz::scanCorner(data, s, slices);
        if (voxels.empty()) continue;
        for (bool gzip : {false, true}) {
            const std::string header =
                std::string("NRRD0004\n# cropped from ") + s.file + "\ntype: " + s.type +
                "\ndimension: 3\nsizes: " + std::to_string(edge) + " " + std::to_string(edge) +
                " " + std::to_string(slices) + "\nspace: left-posterior-superior\n" +
                "space directions: (" +
                (n % 2 ? "3.2,0,0) (0,3.2,0) (0,0,1.5)" : "1,0,0) (0,1,0) (0,0,1)") +
                "\nspacings: " + s.spacing +
                "\nspace origin: (0,0,0)\nendian: little\nencoding: " + (gzip ? "gzip" : "raw") +
                "\n\n";
            Bytes bytes = fuzz::textBytes(header);
            const Bytes payload = gzip ? gzipBytes(voxels) : voxels;
            bytes.insert(bytes.end(), payload.begin(), payload.end());
            fuzz::writeSeed(seeds, "scan-" + std::to_string(n++), bytes);
            // The real header with a truncated payload.
            bytes.resize(header.size() + payload.size() / 3);
            fuzz::writeSeed(seeds, "scan-" + std::to_string(n++), bytes);
        }
    }
}

void writeSeeds(const std::string& seeds) {
    const char* detached[] = {
        "NRRD0005\ntype: uint8\ndimension: 3\nsizes: 16 16 8\nencoding: raw\ndata file: data.raw\n",
        "NRRD0004\ntype: uchar\ndimension: 3\nsizes: 16 16 8\nspacings: 1 1 2\nencoding: gzip\n"
        "datafile: data.raw.gz\nline skip: 0\nbyte skip: 0\n\n",
        "NRRD0001\ntype: uchar\ndimension: 3\nsizes: 16 16 4\nencoding: raw\nline skip: 1\n"
        "data file: ./data.raw\nkey:=value\n",
    };
    int n = 0;
    for (const char* text : detached)
        fuzz::writeSeed(seeds, "detached-" + std::to_string(n++), fuzz::textBytes(text));
    if (const std::string data = fuzz::sharedData(); !data.empty()) writeScanSeeds(seeds, data);
}

} // namespace

extern "C" int LLVMFuzzerTestOneInput(const std::uint8_t* data, std::size_t size) {
    return fuzz::fuzzReader(data, size, (folder() / "volume.nrrd").string(), brickstore::openNrrd);
}

extern "C" int LLVMFuzzerInitialize(int*, char***) {
    if (const std::string seeds = fuzz::envFolder("BC_FUZZ_SEED_DIR"); !seeds.empty())
        writeSeeds(seeds);
    return 0;
}
