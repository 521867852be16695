// libFuzzer target of the MetaImage reader (scripts/fuzz.sh metaimage builds and runs it).
//
// Input: the bytes of a .mha file, written to a private scratch folder and opened with
// openMetaImage, as ingest would; the folder also holds data.raw and data.zlib (16x16x8 u8, the
// latter one zlib stream as MetaIO's compress2 writes it) so that headers naming a data file, as
// an .mhd does, reach that path too. A FormatError is the expected refusal; a crash, sanitizer
// report, other exception or a volume that validateVolumeInfo rejects is a finding. Slices are
// then read (tests/fuzz/ReaderFuzz.h).
//
// With BC_FUZZ_SEED_DIR set, the binary first writes seeds there: .mha files of the real scans
// (BC_SHARED_DATA_DIR) cropped to 32x32x4 voxels with their data raw and zlib-compressed (with
// CompressedDataSize), truncated copies, and headers naming data.raw and data.zlib.
#include "brickstore/Readers.h"
#include "tests/fuzz/ReaderFuzz.h"

namespace {

using namespace bc;
using fuzz::Bytes;

/// `raw` as one zlib stream (compress2, as MetaIO writes CompressedData).
Bytes zlibBytes(const Bytes& raw) {
    uLongf size = compressBound(uLong(raw.size()));
    Bytes out(size);
    fuzz::require(compress2(out.data(), &size, raw.data(), uLong(raw.size()), 6) == Z_OK,
                  "compress2");
    out.resize(size);
    return out;
}

const std::filesystem::path& folder() {
    static const std::filesystem::path dir = [] {
        const auto& d = fuzz::scratchDir();
        const Bytes voxels = fuzz::detachedVoxels();
        fuzz::writeFile(d / "data.raw", voxels);
        fuzz::writeFile(d / "data.zlib", zlibBytes(voxels));
        return d;
    }();
    return dir;
}

void writeScanSeeds(const std::string& seeds, const std::string& data) {
    const fuzz::SeedScan scans[] = {
        {"vtk_headsq_quarter_64x64x93_uint16.raw", "MET_USHORT", 64, 64, 2, "3.2 3.2 1.5"},
        {"hydrogen_64x64x64_float32.raw", "MET_FLOAT", 64, 64, 4, "1 1 1"},
        {"CT_AVM_256x242x154_uint8.raw", "MET_UCHAR", 256, 242, 1, "0.72 0.721 1"},
    };
    int n = 0;
    for (const fuzz::SeedScan& s : scans) {
        const unsigned slices = 4, edge = fuzz::kSeedEdge;
        const Bytes voxels = fuzz::scanCorner(data, s, slices);
        if (voxels.empty()) continue;
        for (bool zlib : {false, true}) {
            const Bytes payload = zlib ? zlibBytes(voxels) : voxels;
            // The fields and order vtkMetaImageWriter writes; CompressedDataSize is optional,
            // and a header without it lets a truncated zlib payload reach the inflater.
            const auto text = [&](bool sized) {
                return std::string("ObjectType = Image\nNDims = 3\nBinaryData = True\n") +
                       "BinaryDataByteOrderMSB = False\nCompressedData = " +
                       (zlib ? "True" : "False") + "\n" +
                       (sized ? "CompressedDataSize = " + std::to_string(payload.size()) + "\n"
                              : "") +
                       "TransformMatrix = 1 0 0 0 1 0 0 0 1\n" +
                       (n % 2 ? "Offset = 0 0 0\n" : "Origin = -10.5 3 0.25\n") +
                       "CenterOfRotation = 0 0 0\nAnatomicalOrientation = RAI\nElementSpacing = " +
                       s.spacing + "\nDimSize = " + std::to_string(edge) + " " +
                       std::to_string(edge) + " " + std::to_string(slices) +
                       "\nElementType = " + s.type + "\nElementDataFile = LOCAL\n";
            };
            Bytes bytes = fuzz::textBytes(text(zlib));
            bytes.insert(bytes.end(), payload.begin(), payload.end());
            fuzz::writeSeed(seeds, "scan-" + std::to_string(n++), bytes);
            // The header (without CompressedDataSize) with a truncated payload.
            bytes = fuzz::textBytes(text(false));
            bytes.insert(bytes.end(), payload.begin(), payload.begin() + payload.size() / 3);
            fuzz::writeSeed(seeds, "scan-" + std::to_string(n++), bytes);
        }
    }
}

void writeSeeds(const std::string& seeds) {
    const std::string head = "ObjectType = Image\nNDims = 3\nBinaryData = True\n";
    const std::string detached[] = {
        head + "DimSize = 16 16 8\nElementType = MET_UCHAR\nElementSpacing = 1 1 2\n"
               "ElementDataFile = data.raw\n",
        head + "CompressedData = True\nCompressedDataSize = " +
            std::to_string(zlibBytes(fuzz::detachedVoxels()).size()) +
            "\nDimSize = 16 16 8\nElementType = MET_UCHAR\nElementDataFile = data.zlib\n",
        // HeaderSize skips the first half of data.raw; -1 takes its last 1 KiB.
        head + "DimSize = 16 16 4\nElementType = MET_UCHAR\nHeaderSize = 1024\n"
               "ElementDataFile = ./data.raw\n",
        head + "DimSize = 16 16 2\nElementType = MET_USHORT\nHeaderSize = -1\n"
               "ElementByteOrderMSB = True\nElementDataFile = data.raw\n",
        head + "DimSize = 16 8 8\nElementType = MET_SHORT\nBinaryDataByteOrderMSB = True\n"
               "ElementSize = 0.5 0.5 1\nPosition = 1 2 3\nElementDataFile = data.raw\n",
    };
    int n = 0;
    for (const std::string& text : detached)
        fuzz::writeSeed(seeds, "detached-" + std::to_string(n++), fuzz::textBytes(text));
    if (const std::string data = fuzz::sharedData(); !data.empty()) writeScanSeeds(seeds, data);
}

} // namespace

extern "C" int LLVMFuzzerTestOneInput(const std::uint8_t* data, std::size_t size) {
    return fuzz::fuzzReader(data, size, (folder() / "volume.mha").string(),
                            brickstore::openMetaImage);
}

extern "C" int LLVMFuzzerInitialize(int*, char***) {
    if (const std::string seeds = fuzz::envFolder("BC_FUZZ_SEED_DIR"); !seeds.empty())
        writeSeeds(seeds);
    return 0;
}
