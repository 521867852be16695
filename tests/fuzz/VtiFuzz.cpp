// libFuzzer target of the VTK XML image data reader (scripts/fuzz.sh vti builds and runs it).
//
// Input: the bytes of a .vti file, written to a private scratch folder and opened with openVti,
// as ingest would: expat parses the markup, then the array streams raw or base64, whole or in
// vtkZLibDataCompressor blocks. A FormatError is the expected refusal; a crash, sanitizer
// report, other exception or a volume that validateVolumeInfo rejects is a finding. Slices are
// then read (tests/fuzz/ReaderFuzz.h).
//
// With BC_FUZZ_SEED_DIR set, the binary first writes seeds there: .vti files of a small made-up
// volume (big-endian) and of the real scans (BC_SHARED_DATA_DIR) cropped to 32x32x4 voxels, in
// every layout the reader takes (appended raw, appended base64, inline base64; plain and zlib
// blocks; UInt32 and UInt64 headers), and truncated copies.
#include "brickstore/Readers.h"
#include "tests/fuzz/ReaderFuzz.h"

namespace {

using namespace bc;
using fuzz::Bytes;

void append(Bytes& to, const Bytes& more) {
    to.insert(to.end(), more.begin(), more.end());
}

/// `v` as a binary header number of `bytes` bytes.
void appendNumber(Bytes& to, std::uint64_t v, unsigned bytes, bool big) {
    for (unsigned i = 0; i < bytes; ++i)
        to.push_back(std::uint8_t(v >> (8 * (big ? bytes - 1 - i : i))));
}

Bytes base64(const Bytes& data) {
    static const char* kAlphabet =
        "ABCDEFGHIJKLMNOPQRSTUVWXYZabcdefghijklmnopqrstuvwxyz0123456789+/";
    Bytes out;
    for (std::size_t i = 0; i < data.size(); i += 3) {
        const std::size_t n = std::min<std::size_t>(3, data.size() - i);
        std::uint32_t bits = std::uint32_t(data[i]) << 16;
        if (n > 1) bits |= std::uint32_t(data[i + 1]) << 8;
        if (n > 2) bits |= data[i + 2];
        for (std::size_t c = 0; c < 4; ++c)
            out.push_back(c <= n ? std::uint8_t(kAlphabet[(bits >> (18 - 6 * c)) & 63]) : '=');
    }
    return out;
}

/// vtkZLibDataCompressor's layout: the header [number of blocks, block size, last block's size
/// (0: full), compressed size of each block] in the header type, and the blocks, each one zlib
/// stream. In base64 the two are separate texts, the header's padded, as VTK writes them.
std::pair<Bytes, Bytes> zlibBlocks(const Bytes& raw, std::size_t blockBytes, unsigned headerBytes,
                                   bool big) {
    const std::size_t count = (raw.size() + blockBytes - 1) / blockBytes;
    Bytes header, blocks;
    appendNumber(header, count, headerBytes, big);
    appendNumber(header, blockBytes, headerBytes, big);
    appendNumber(header, raw.size() % blockBytes, headerBytes, big);
    for (std::size_t i = 0; i < count; ++i) {
        const std::size_t n = std::min(blockBytes, raw.size() - i * blockBytes);
        uLongf size = compressBound(uLong(n));
        Bytes out(size);
        fuzz::require(compress2(out.data(), &size, raw.data() + i * blockBytes, uLong(n), 6) ==
                          Z_OK,
                      "compress2");
        out.resize(size);
        appendNumber(header, size, headerBytes, big);
        append(blocks, out);
    }
    return {header, blocks};
}

enum class Layout { AppendedRaw, AppendedBase64, Inline };

/// A .vti of `voxels` (x fastest, `dims` voxels, VTK type name `type`) stored as `layout`.
Bytes vti(const Bytes& voxels, const char* type, const unsigned (&dims)[3], const char* spacing,
          Layout layout, bool zlib, unsigned headerBytes, bool big) {
    Bytes data, text; // binary bytes, and their base64 text
    if (zlib) {
        auto [header, blocks] = zlibBlocks(voxels, 5000, headerBytes, big);
        text = base64(header);
        append(text, base64(blocks));
        data = header;
        append(data, blocks);
    } else {
        appendNumber(data, voxels.size(), headerBytes, big);
        append(data, voxels);
        text = base64(data);
    }
    const std::string extent = "0 " + std::to_string(dims[0] - 1) + " 0 " +
                               std::to_string(dims[1] - 1) + " 2 " + std::to_string(dims[2] + 1);
    std::string xml =
        std::string("<?xml version=\"1.0\"?>\n<VTKFile type=\"ImageData\" version=\"1.0\" ") +
        "byte_order=\"" + (big ? "BigEndian" : "LittleEndian") + "\" header_type=\"UInt" +
        (headerBytes == 8 ? "64" : "32") + "\"" +
        (zlib ? " compressor=\"vtkZLibDataCompressor\"" : "") + ">\n  <ImageData WholeExtent=\"" +
        extent + "\" Origin=\"0 -1.5 4\" Spacing=\"" + spacing +
        "\" Direction=\"1 0 0 0 1 0 0 0 1\">\n    <Piece Extent=\"" + extent +
        "\">\n      <PointData Scalars=\"v\">\n        <DataArray type=\"" + type +
        "\" Name=\"v\" NumberOfComponents=\"1\" format=\"" +
        (layout == Layout::Inline ? "binary" : "appended\" offset=\"0") + "\"";
    Bytes out;
    if (layout == Layout::Inline) {
        out = fuzz::textBytes(xml + ">\n          ");
        append(out, text);
        append(out, fuzz::textBytes("\n        </DataArray>\n      </PointData>\n      <CellData>"
                                    "\n      </CellData>\n    </Piece>\n  </ImageData>\n"
                                    "</VTKFile>\n"));
        return out;
    }
    out = fuzz::textBytes(xml + "/>\n      </PointData>\n      <CellData>\n      </CellData>\n" +
                          "    </Piece>\n  </ImageData>\n  <AppendedData encoding=\"" +
                          (layout == Layout::AppendedRaw ? "raw" : "base64") + "\">\n   _");
    append(out, layout == Layout::AppendedRaw ? data : text);
    append(out, fuzz::textBytes("\n  </AppendedData>\n</VTKFile>\n"));
    return out;
}

/// Every layout of one volume, each whole and truncated (cut inside the data, or for inline
/// data inside the text, so the XML is broken too).
void writeLayouts(const std::string& seeds, const std::string& name, const Bytes& voxels,
                  const char* type, const unsigned (&dims)[3], const char* spacing, bool big) {
    int n = 0;
    for (Layout layout : {Layout::AppendedRaw, Layout::AppendedBase64, Layout::Inline})
        for (bool zlib : {false, true})
            for (unsigned headerBytes : {4u, 8u}) {
                Bytes bytes = vti(voxels, type, dims, spacing, layout, zlib, headerBytes, big);
                fuzz::writeSeed(seeds, name + "-" + std::to_string(n++), bytes);
                bytes.resize(bytes.size() * 2 / 3);
                fuzz::writeSeed(seeds, name + "-" + std::to_string(n++), bytes);
            }
}

void writeScanSeeds(const std::string& seeds, const std::string& data) {
    const fuzz::SeedScan scans[] = {
        {"vtk_headsq_quarter_64x64x93_uint16.raw", "UInt16", 64, 64, 2, "3.2 3.2 1.5"},
        {"hydrogen_64x64x64_float32.raw", "Float32", 64, 64, 4, "1 1 1"},
        {"CT_AVM_256x242x154_uint8.raw", "UInt8", 256, 242, 1, "0.72 0.721 1"},
    };
    int n = 0;
    for (const fuzz::SeedScan& s : scans) {
        const unsigned dims[3] = {fuzz::kSeedEdge, fuzz::kSeedEdge, 4};
        const Bytes voxels = fuzz::scanCorner(data, s, dims[2]);
        if (!voxels.empty())
            writeLayouts(seeds, "scan" + std::to_string(n++), voxels, s.type, dims, s.spacing,
                         false);
    }
}

void writeSeeds(const std::string& seeds) {
    // 12x10x6 u8 in big-endian files: the header numbers' other byte order, and a last zlib
    // block that is partial (720 bytes in one block of 5000).
    const unsigned dims[3] = {12, 10, 6};
    Bytes voxels(12 * 10 * 6);
    for (std::size_t i = 0; i < voxels.size(); ++i)
        voxels[i] = std::uint8_t((i * 37) ^ (i >> 4));
    writeLayouts(seeds, "small", voxels, "UInt8", dims, "0.5 0.5 2", true);
    if (const std::string data = fuzz::sharedData(); !data.empty()) writeScanSeeds(seeds, data);
}

const std::string& inputPath() {
    static const std::string path = (fuzz::scratchDir() / "volume.vti").string();
    return path;
}

} // namespace

extern "C" int LLVMFuzzerTestOneInput(const std::uint8_t* data, std::size_t size) {
    return fuzz::fuzzReader(data, size, inputPath(), brickstore::openVti);
}

extern "C" int LLVMFuzzerInitialize(int*, char***) {
    if (const std::string seeds = fuzz::envFolder("BC_FUZZ_SEED_DIR"); !seeds.empty())
        writeSeeds(seeds);
    return 0;
}
