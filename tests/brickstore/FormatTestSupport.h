#pragma once
// Shared helpers of the readers' round trips: each shared scan, read by the readers
// already trusted, dumped as raw voxels; an independent writer (a Debian Python module, run
// by /usr/bin/python3) writes them in the format under test; the new reader must then ingest
// and extract to exactly the source voxels.
#include "brickstore/BrickStore.h"
#include "brickstore/Ingest.h"
#include "brickstore/Readers.h"
#include "brickstore/StoreVolume.h"
#include "tests/TestSupport.h"

#include <algorithm>
#include <cstring>
#include <fstream>
#include <ostream>
#include <string>
#include <vector>

namespace bc::test {

/// A shared scan of ../shared/data as its own reader sees it.
struct SharedScan {
    std::string name;     ///< a test-name-safe label: "cthead"
    std::string file;     ///< in ../shared/data
    std::string dataType; ///< the NumPy dtype name of its voxels: "uint16"
};

/// Every shared scan: u8, u16, i16 (pancreas, from DICOM) and f32 (hydrogen, gaffer smoke).
inline std::vector<SharedScan> sharedScans() {
    return {
        {"cthead", "stanford_cthead_256x256x113_uint16.raw", "uint16"},
        {"headsq", "vtk_headsq_quarter_64x64x93_uint16.raw", "uint16"},
        {"frog", "frog_500x470x136_uint8.raw", "uint8"},
        {"ct_avm", "CT_AVM_256x242x154_uint8.raw", "uint8"},
        {"iguana", "Iguana.nii.gz", "uint8"},
        {"pancreas", "tcia_pancreas_ct_dicom", "int16"},
        {"hydrogen", "hydrogen_64x64x64_float32.raw", "float32"},
        {"gaffer", "gaffer_smoke.vdb", "float32"},
    };
}

/// How GoogleTest prints a scan (test lists, failures): by its name, not its bytes.
inline void PrintTo(const SharedScan& scan, std::ostream* os) {
    *os << scan.name;
}

inline brickstore::SourceSpec sharedSpec(const SharedScan& scan) {
    brickstore::SourceSpec spec;
    spec.input = dataPath(scan.file);
    return spec;
}

/// The NumPy dtype name of a voxel type.
inline const char* dtypeName(brickstore::VoxelType type) {
    switch (type) {
    case brickstore::VoxelType::U8:
        return "uint8";
    case brickstore::VoxelType::U16:
        return "uint16";
    case brickstore::VoxelType::I16:
        return "int16";
    case brickstore::VoxelType::F32:
        return "float32";
    }
    return "?";
}

/// Writes the voxels of `spec` to `path` as raw (x fastest, host = little endian), a slab at a
/// time, and returns what the reader said of them.
inline brickstore::VolumeInfo dumpRaw(const brickstore::SourceSpec& spec, const std::string& path) {
    auto source = brickstore::openSource(spec);
    const brickstore::VolumeInfo info = source->info();
    std::ofstream out(path, std::ios::binary);
    const std::uint64_t slab = 16, sb = info.sliceBytes();
    std::vector<std::byte> buf(slab * sb);
    for (std::uint64_t z = 0; z < info.dims[2]; z += slab) {
        const std::uint64_t n = std::min(slab, info.dims[2] - z);
        source->readSlices(n, std::span(buf).first(n * sb));
        out.write(reinterpret_cast<const char*>(buf.data()), std::streamsize(n * sb));
    }
    return info;
}

/// Whether /usr/bin/python3 imports every module of `modules` (a comma-separated list, as
/// `import` takes it). When not, the test is skipped saying which, or fails under CI=true:
/// CI installs them (scripts/setup.sh), so a missing one there is a broken set-up.
/// Use: `if (!test::pythonHas("tifffile, numpy")) return;`
inline bool pythonHas(const std::string& modules) {
    const CommandOutput r = runCommand("/usr/bin/python3 -c 'import " + modules + "'");
    if (r.exitCode == 0) return true;
    if (dataRequired())
        ADD_FAILURE() << "/usr/bin/python3 cannot import " << modules
                      << " (CI=true: scripts/setup.sh installs them): " << r.text;
    else // GTEST_SKIP returns from the function it is in: a lambda here, not this bool one
        [&] { GTEST_SKIP() << "/usr/bin/python3 cannot import " << modules << ": " << r.text; }();
    return false;
}

/// Path of a file of tests/ (a writer script).
inline std::string testsPath(const std::string& name) {
    return (std::filesystem::path(BC_TESTS_DIR) / name).string();
}

/// The command line of a writer script that takes RAW DTYPE X Y Z SX SY SZ FOLDER VARIANT...:
/// the raw dump of a scan, what the reader said of it, where to write and what.
inline std::vector<std::string> writerArgs(const std::string& raw,
                                           const brickstore::VolumeInfo& info,
                                           const std::string& folder,
                                           const std::vector<std::string>& variants) {
    std::vector<std::string> args = {raw, dtypeName(info.type)};
    for (std::uint64_t d : info.dims)
        args.push_back(std::to_string(d));
    for (double s : info.spacingMm)
        args.push_back(std::to_string(s));
    args.push_back(folder);
    args.insert(args.end(), variants.begin(), variants.end());
    return args;
}

/// Runs /usr/bin/python3 SCRIPT ARGS...; fails the test (and returns false) when it fails.
inline bool runPython(const std::string& script, const std::vector<std::string>& args) {
    std::string line = "/usr/bin/python3 '" + testsPath(script) + "'";
    for (const std::string& a : args)
        line += " '" + a + "'";
    const CommandOutput r = runCommand(line);
    EXPECT_EQ(r.exitCode, 0) << line << "\n" << r.text;
    return r.exitCode == 0;
}

/// Ingests `written` into a store (two brick sizes' worth of geometry is the round trip's job;
/// one here), extracts level 0 and compares it, slab by slab, with a fresh read of `original`:
/// same dims, same type, the same voxels bit for bit.
inline void expectIngestsToSameVoxels(const brickstore::SourceSpec& original,
                                      const brickstore::SourceSpec& written,
                                      const std::string& label) {
    TempDir dir;
    const std::string path = dir.file("rt.bcs");
    {
        auto src = brickstore::openSource(written);
        brickstore::IngestConfig config;
        config.geometry = brickstore::BrickGeometry{32, 2, 8};
        brickstore::ingest(*src, path, config);
    }
    auto store = brickstore::BrickStore::open(path);
    auto source = brickstore::openSource(original);
    auto extracted = brickstore::openStoreLevel(*store, 0);
    ASSERT_EQ(source->info().dims, extracted->info().dims) << label;
    ASSERT_EQ(source->info().type, extracted->info().type) << label;
    const std::uint64_t sb = source->info().sliceBytes(), slab = 7;
    std::vector<std::byte> a(slab * sb), b(slab * sb);
    for (std::uint64_t z = 0; z < source->info().dims[2]; z += slab) {
        const std::uint64_t n = std::min(slab, source->info().dims[2] - z);
        source->readSlices(n, std::span(a).first(n * sb));
        extracted->readSlices(n, std::span(b).first(n * sb));
        ASSERT_EQ(std::memcmp(a.data(), b.data(), n * sb), 0)
            << label << ": slices " << z << ".." << z + n - 1;
    }
}

/// The round trip of a format VTK writes (MetaImage, .vti): `scan` dumped to raw and written
/// by writers/write_vtk_formats.py in each of `variants`; each written file (`fileOf(variant)`
/// in the scan's folder) opened with `open` must show the scan's dims and spacing and a
/// description naming `format`, then ingest to exactly the scan's voxels.
template <typename FileOf, typename Open>
void expectVtkWrittenScanRoundTrips(const SharedScan& scan,
                                    const std::vector<std::string>& variants, FileOf fileOf,
                                    Open open, const std::string& format) {
    if (!pythonHas("numpy, vtkmodules.vtkIOImage, vtkmodules.vtkIOXML")) return;
    if (!haveData(scan.file)) return missingData(scan.file);
    TempDir dir;
    const brickstore::SourceSpec original = sharedSpec(scan);
    const brickstore::VolumeInfo info = dumpRaw(original, dir.file("src.raw"));
    if (!runPython("brickstore/writers/write_vtk_formats.py",
                   writerArgs(dir.file("src.raw"), info, dir.path().string(), variants)))
        return;
    for (const std::string& v : variants) {
        brickstore::SourceSpec written;
        written.input = dir.file(fileOf(v));
        {
            auto source = open(written.input);
            EXPECT_EQ(source->info().dims, info.dims) << v;
            for (int a = 0; a < 3; ++a)
                EXPECT_NEAR(source->info().spacingMm[a], info.spacingMm[a], 1e-5) << v;
            EXPECT_NE(source->info().description.find(format), std::string::npos)
                << v << ": " << source->info().description;
        }
        expectIngestsToSameVoxels(original, written, scan.name + " " + v);
    }
}

} // namespace bc::test
