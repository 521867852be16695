// brickcast ingest INPUT -o STORE [...]: any reader or generator into a brick store.
#include "brickstore/Error.h"
#include "brickstore/Ingest.h"
#include "brickstore/Readers.h"
#include "tools/Parse.h"
#include "tools/brickcast/Commands.h"
#include "tools/brickcast/Progress.h"

#include <CLI/CLI.hpp>
#include <atomic>
#include <csignal>
#include <cstdio>
#include <fstream>
#include <memory>
#include <new>
#include <nlohmann/json.hpp>
#include <stdexcept>

namespace bc::cli {
namespace {

struct IngestOptions {
    std::string input, output, dims, type, spacing, endian = "little", grid, mosaic, dataset;
    std::string statsPath;
    std::uint32_t level = 0;
    std::uint64_t seed = 1;
    std::uint32_t brick = 64, apron = 2, leaf = 8;
    unsigned threads = 0;
    int zstdLevel = 3;
    std::uint64_t memoryBudgetMb = 0;
    std::uint64_t parserMemoryMb = brickstore::ParserSandboxLimits{}.addressSpaceBytes >> 20;
    std::uint32_t parserTimeS = brickstore::ParserSandboxLimits{}.parseSeconds;
    std::uint64_t maxVolumeGb = brickstore::InputLimits{}.maxVolumeBytes >> 30;
    std::uint64_t maxExpansion = brickstore::InputLimits{}.maxExpansion;
    std::uint64_t maxChunks = brickstore::InputLimits{}.maxChunks;
    bool quiet = false;
};

// SIGINT/SIGTERM during an ingest: the handler only sets these; the ingest loop polls the
// flag, stops, removes its partial file, and runIngest then dies of the same signal. Before
// the ingest has a partial file (opening the input, a long DICOM header scan) there is
// nothing to remove: the process dies at once.
std::atomic<bool> gCancel{false};
std::atomic<bool> gIngesting{false};
volatile std::sig_atomic_t gSignal = 0;
static_assert(std::atomic<bool>::is_always_lock_free);

extern "C" void onTerminate(int signal) {
    gSignal = signal;
    gCancel.store(true);
    if (!gIngesting.load()) std::raise(signal); // SA_RESETHAND: the default action now
}

/// Installs onTerminate for SIGINT and SIGTERM while it lives (one-shot: a second signal
/// kills at once), and restores the previous handlers.
class TerminationGuard {
  public:
    TerminationGuard() {
        struct sigaction action {};
        action.sa_handler = onTerminate;
        sigemptyset(&action.sa_mask);
        action.sa_flags = SA_RESETHAND;
        sigaction(SIGINT, &action, &mOldInt);
        sigaction(SIGTERM, &action, &mOldTerm);
    }
    ~TerminationGuard() {
        sigaction(SIGINT, &mOldInt, nullptr);
        sigaction(SIGTERM, &mOldTerm, nullptr);
    }
    TerminationGuard(const TerminationGuard&) = delete;
    TerminationGuard& operator=(const TerminationGuard&) = delete;

    /// Ends the process by the signal that cancelled the ingest (exit status 128 + signal in
    /// a shell), with its default action.
    static void dieOfSignal() {
        const int signal = gSignal;
        std::signal(signal, SIG_DFL);
        std::raise(signal);
    }

  private:
    struct sigaction mOldInt {
    }, mOldTerm{};
};

constexpr const char* kLimitsHelp =
    "Limits (checked before anything is allocated; each error names the file and field):\n"
    "  an edge of at most 1048576 voxels, a slice (x*y) of at most 2^30 voxels (32768^2), a\n"
    "  volume of at most 2^42 voxels and 1 PiB; a raw or uncompressed file must hold exactly\n"
    "  the declared bytes, a gzip payload at least 1/1032 and a zstd one 1/32768 of them (the\n"
    "  codecs' largest ratios; zstd frames that declare their size must declare exactly them);\n"
    "  a volume over 64 MiB at most --max-expansion (32768) times the bytes its input holds (a\n"
    "  Zarr, HDF5, TIFF, VDB or DICOM header cannot ask for work its files do not back), at\n"
    "  most --max-chunks (2^20) chunks and --max-volume-gb; inputs that are not regular files\n"
    "  (a FIFO, a device) are refused;\n"
    "  every DICOM slice's PixelData must hold Rows x Columns x bytes per pixel; and the\n"
    "  memory ingest needs (2B+2A slices of every pyramid level, or B+2A if only that fits,\n"
    "  the workers' bricks, the brick index) must fit --memory-budget-mb (default: half of\n"
    "  physical memory, at most half of the address-space limit). SIGINT/SIGTERM remove the\n"
    "  partial store before exiting.";

brickstore::SourceSpec toSpec(const IngestOptions& o) {
    brickstore::SourceSpec spec;
    spec.input = o.input;
    if (!o.dims.empty()) spec.dims = tools::parseTriple(o.dims, "--dims");
    if (!o.type.empty()) {
        spec.type = brickstore::parseVoxelType(o.type);
        if (!spec.type)
            throw brickstore::FormatError(o.input, "type",
                                          "unknown type '" + o.type + "'; use u8, u16, i16 or f32");
    }
    if (!o.spacing.empty()) spec.spacingMm = tools::parseTripleDouble(o.spacing, "--spacing");
    if (o.endian != "little" && o.endian != "big")
        throw brickstore::FormatError(o.input, "endian",
                                      "'" + o.endian + "' is neither little nor big");
    spec.endian = o.endian == "big" ? brickstore::Endian::Big : brickstore::Endian::Little;
    spec.gridName = o.grid;
    spec.dataset = o.dataset;
    spec.level = o.level;
    spec.seed = o.seed;
    if (!o.mosaic.empty()) spec.mosaic = tools::parseTriple(o.mosaic, "--mosaic");
    return spec;
}

std::unique_ptr<brickstore::VolumeSource> openInput(const IngestOptions& o) {
    brickstore::ParserSandboxLimits limits;
    limits.addressSpaceBytes = o.parserMemoryMb << 20;
    limits.parseSeconds = o.parserTimeS;
    brickstore::setParserSandboxLimits(limits);
    brickstore::setInputLimits({o.maxVolumeGb << 30, o.maxExpansion, o.maxChunks});
    try {
        return brickstore::openSource(toSpec(o));
    } catch (const std::bad_alloc&) {
        throw std::runtime_error("out of memory while opening " + o.input +
                                 " (std::bad_alloc reading its header)");
    }
}

brickstore::IngestReport ingestInput(brickstore::VolumeSource& source, const IngestOptions& o) {
    brickstore::IngestConfig config;
    config.geometry = {o.brick, o.apron, o.leaf};
    config.threads = o.threads;
    config.zstdLevel = o.zstdLevel;
    config.memoryBudgetBytes = o.memoryBudgetMb << 20;
    config.inputName = o.input;
    config.cancel = &gCancel;
    config.staleFileRemoved = [](const std::string& path) {
        std::fprintf(stderr, "brickcast: removed %s, left by an ingest that was killed\n",
                     path.c_str());
    };
    ProgressLine line(!o.quiet);
    gIngesting.store(true); // from here a signal only sets gCancel (see onTerminate)
    try {
        auto report = brickstore::ingest(
            source, o.output, config, [&](const brickstore::IngestProgress& p) { line.update(p); });
        line.finish();
        return report;
    } catch (const std::bad_alloc&) {
        line.finish();
        throw std::runtime_error("out of memory while ingesting " + o.input + " (" +
                                 brickstore::dimsText(source.info().dims) + ") into " + o.output +
                                 "; the partial store was removed (try a lower "
                                 "--memory-budget-mb or fewer --threads)");
    } catch (const brickstore::IngestCancelled&) {
        line.finish();
        std::fprintf(stderr, "brickcast: ingest of %s interrupted by signal %d; %s not written\n",
                     o.input.c_str(), int(gSignal), o.output.c_str());
        TerminationGuard::dieOfSignal();
        throw;
    }
}

/// The report as JSON (--stats): what the ingest benchmark reads.
void writeStats(const std::string& path, const brickstore::VolumeInfo& info,
                const brickstore::IngestReport& r) {
    const brickstore::IngestTimes& t = r.times;
    const nlohmann::json j = {
        {"input", info.description},
        {"dims", info.dims},
        {"type", brickstore::voxelTypeName(info.type)},
        {"sourceBytes", r.sourceBytes},
        {"bricks", r.bricks},
        {"storedBricks", r.storedBricks},
        {"constantBricks", r.constantBricks},
        {"storedBytes", r.storedBytes},
        {"fileBytes", r.fileBytes},
        {"memoryBytes", r.memoryBytes},
        {"seconds", r.seconds},
        {"times",
         {{"read", t.read},
          {"cut", t.cut},
          {"ringWait", t.ringWait},
          {"brickCut", t.brickCut},
          {"compress", t.compress},
          {"write", t.write},
          {"histogram", t.histogram},
          {"finish", t.finish}}},
    };
    std::ofstream out(path);
    out << j.dump(2) << "\n";
    if (!out) throw std::runtime_error("cannot write " + path);
}

void runIngest(const IngestOptions& o) {
    const TerminationGuard guard;
    auto source = openInput(o);
    auto report = ingestInput(*source, o);
    if (gCancel.load()) TerminationGuard::dieOfSignal(); // a signal after the commit
    if (!o.statsPath.empty()) writeStats(o.statsPath, source->info(), report);
    if (o.quiet) return;
    std::printf("ingested %s -> %s\n", source->info().description.c_str(), o.output.c_str());
    std::printf(
        "  %llu bricks (%llu stored, %llu constant, not stored), %s in %.2f s (%.1f MB/s)\n",
        (unsigned long long)report.bricks, (unsigned long long)report.storedBricks,
        (unsigned long long)report.constantBricks,
        tools::formatBytes(double(report.sourceBytes)).c_str(), report.seconds,
        double(report.sourceBytes) / 1e6 / report.seconds);
    std::printf("  store %s; stored bricks compress %.2fx; constant bricks saved %s\n",
                tools::formatBytes(double(report.fileBytes)).c_str(),
                report.storedBytes
                    ? double(report.uncompressedBrickBytes) / double(report.storedBytes)
                    : 0.0,
                tools::formatBytes(double(report.constantBrickBytes)).c_str());
    const brickstore::IngestTimes& t = report.times;
    std::printf("  time: read+decode %.2f s, slices and pyramid %.2f s, waiting on workers %.2f s; "
                "workers (summed): cut %.2f s, compress %.2f s, write %.2f s; histogram %.2f s, "
                "index %.2f s\n",
                t.read, t.cut, t.ringWait, t.brickCut, t.compress, t.write, t.histogram, t.finish);
    std::printf("  memory: %s estimated for the buffers, budget %s\n",
                tools::formatBytes(double(report.memoryBytes)).c_str(),
                tools::formatBytes(double(report.memoryBudgetBytes)).c_str());
    // Leaf tables hold the leaves inside the volume only (FORMAT.md, version 2); they still
    // outweigh the frames when the leaves are small against what the frames compress to.
    if (report.leafTableBytes * 2 > report.storedBytes)
        std::printf("  note: %s of the store are leaf tables (8 bytes per %u³ leaf inside the "
                    "volume; --leaf sets their size)\n",
                    tools::formatBytes(double(report.leafTableBytes)).c_str(), o.leaf);
}

} // namespace

void addIngestCommand(CLI::App& app) {
    auto o = std::make_shared<IngestOptions>();
    auto* cmd =
        app.add_subcommand("ingest", "Tile a volume into an overlapped, compressed brick store");
    cmd->add_option(
           "INPUT", o->input,
           "Raw (.raw, .raw.zst), NRRD (.nrrd, .nhdr), NIfTI (.nii, .nii.gz), a DICOM folder, "
           "OpenVDB (.vdb), TIFF (.tif, .tiff, .btf; or a folder of .tif slices), a Zarr or "
           "OME-Zarr folder, HDF5 (.h5, .hdf5, .hdf, .he5, .ims; with --dataset), MetaImage "
           "(.mha, .mhd), VTK image data (.vti), or synth:phantom|vessels|checker")
        ->required();
    cmd->add_option("-o,--output", o->output, "Store file to write (replaced only when complete)")
        ->required();
    cmd->add_option("--dims", o->dims, "X,Y,Z voxels (raw input and generators)");
    cmd->add_option("--type", o->type, "u8|u16|i16|f32 (raw input)");
    cmd->add_option("--spacing", o->spacing,
                    "A,B,C voxel size in mm (raw input, default 1,1,1; overrides a TIFF's own)");
    cmd->add_option("--endian", o->endian, "little|big (raw input)")->capture_default_str();
    cmd->add_option("--brick", o->brick, "Brick payload edge in voxels")->capture_default_str();
    cmd->add_option("--apron", o->apron, "Overlap voxels on every side of a brick")
        ->capture_default_str();
    cmd->add_option("--leaf", o->leaf, "Leaf block edge of the per-brick min/max summaries")
        ->capture_default_str();
    cmd->add_option("--grid", o->grid, "OpenVDB grid name (default: the first scalar grid)");
    cmd->add_option("--dataset", o->dataset,
                    "HDF5: the dataset's path in the file, e.g. /entry/data (without it, the "
                    "error lists the file's 3D datasets)");
    cmd->add_option("--level", o->level, "OME-Zarr: the multiscale level to ingest (0: the finest)")
        ->capture_default_str();
    cmd->add_option("--stats", o->statsPath,
                    "Write the ingest's report (sizes, seconds, where the time went) as JSON");
    cmd->add_option("--parser-memory-mb,--vdb-memory-mb", o->parserMemoryMb,
                    "Address-space limit of the sandboxed process that parses an OpenVDB, TIFF "
                    "or HDF5 file or a DICOM series (MiB)")
        ->capture_default_str()
        ->check(CLI::Range(std::uint64_t(64), std::uint64_t(1) << 30));
    cmd->add_option("--parser-time-s,--vdb-parse-s", o->parserTimeS,
                    "Seconds the sandboxed parser may take (OpenVDB, HDF5: to parse the file; "
                    "DICOM, TIFF: per file read) before it is killed")
        ->capture_default_str()
        ->check(CLI::Range(1u, 86400u));
    cmd->add_option("--max-volume-gb", o->maxVolumeGb,
                    "Most voxel bytes an input may declare, in GiB")
        ->capture_default_str()
        ->check(CLI::Range(std::uint64_t(1), brickstore::kMaxVolumeBytes >> 30));
    cmd->add_option("--max-expansion", o->maxExpansion,
                    "Most voxel bytes a volume over 64 MiB may declare per byte its input holds "
                    "(unwritten Zarr or HDF5 chunks, compressed data)")
        ->capture_default_str()
        ->check(CLI::PositiveNumber);
    cmd->add_option("--max-chunks", o->maxChunks,
                    "Most chunks a Zarr array or HDF5 dataset may declare")
        ->capture_default_str()
        ->check(CLI::PositiveNumber);
    cmd->add_option("--mosaic", o->mosaic, "I,J,K: tile the input I x J x K times");
    cmd->add_option("--seed", o->seed, "Generator seed")->capture_default_str();
    cmd->add_option("--threads", o->threads, "Compression workers (0 = all cores)")
        ->capture_default_str();
    cmd->add_option("--zstd-level", o->zstdLevel, "zstd compression level")->capture_default_str();
    cmd->add_option("--memory-budget-mb", o->memoryBudgetMb,
                    "Most memory ingest may use, in MiB (0 = half of physical memory, at most "
                    "half of the address-space limit)")
        ->capture_default_str();
    cmd->footer(kLimitsHelp);
    cmd->add_flag("-q,--quiet", o->quiet, "Print nothing on success");
    cmd->callback([o] { runIngest(*o); });
}

} // namespace bc::cli
