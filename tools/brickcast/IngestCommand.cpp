// brickcast ingest INPUT -o STORE [...]: any reader or generator into a brick store.
#include "brickstore/Error.h"
#include "brickstore/Ingest.h"
#include "brickstore/Readers.h"
#include "tools/Parse.h"
#include "tools/brickcast/Commands.h"
#include "tools/brickcast/Progress.h"

#include <CLI/CLI.hpp>
#include <cstdio>
#include <memory>

namespace bc::cli {
namespace {

struct IngestOptions {
    std::string input, output, dims, type, spacing, endian = "little", grid, mosaic;
    std::uint64_t seed = 1;
    std::uint32_t brick = 64, apron = 2, leaf = 8;
    unsigned threads = 0;
    int zstdLevel = 3;
    std::uint64_t vdbMemoryMb = brickstore::VdbSandboxLimits{}.addressSpaceBytes >> 20;
    std::uint32_t vdbParseS = brickstore::VdbSandboxLimits{}.parseSeconds;
    bool quiet = false;
};

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
    spec.seed = o.seed;
    if (!o.mosaic.empty()) spec.mosaic = tools::parseTriple(o.mosaic, "--mosaic");
    return spec;
}

void runIngest(const IngestOptions& o) {
    brickstore::VdbSandboxLimits limits;
    limits.addressSpaceBytes = o.vdbMemoryMb << 20;
    limits.parseSeconds = o.vdbParseS;
    brickstore::setVdbSandboxLimits(limits);
    auto source = brickstore::openSource(toSpec(o));
    brickstore::IngestConfig config;
    config.geometry = {o.brick, o.apron, o.leaf};
    config.threads = o.threads;
    config.zstdLevel = o.zstdLevel;
    ProgressLine line(!o.quiet);
    auto report = brickstore::ingest(*source, o.output, config,
                                     [&](const brickstore::IngestProgress& p) { line.update(p); });
    line.finish();
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
}

} // namespace

void addIngestCommand(CLI::App& app) {
    auto o = std::make_shared<IngestOptions>();
    auto* cmd =
        app.add_subcommand("ingest", "Tile a volume into an overlapped, compressed brick store");
    cmd->add_option(
           "INPUT", o->input,
           "Raw (.raw, .raw.zst), NRRD (.nrrd, .nhdr), NIfTI (.nii, .nii.gz), a DICOM folder, "
           "OpenVDB (.vdb), or synth:phantom|vessels|checker")
        ->required();
    cmd->add_option("-o,--output", o->output, "Store file to write (replaced only when complete)")
        ->required();
    cmd->add_option("--dims", o->dims, "X,Y,Z voxels (raw input and generators)");
    cmd->add_option("--type", o->type, "u8|u16|i16|f32 (raw input)");
    cmd->add_option("--spacing", o->spacing, "A,B,C voxel size in mm (raw input; default 1,1,1)");
    cmd->add_option("--endian", o->endian, "little|big (raw input)")->capture_default_str();
    cmd->add_option("--brick", o->brick, "Brick payload edge in voxels")->capture_default_str();
    cmd->add_option("--apron", o->apron, "Overlap voxels on every side of a brick")
        ->capture_default_str();
    cmd->add_option("--leaf", o->leaf, "Leaf block edge of the per-brick min/max summaries")
        ->capture_default_str();
    cmd->add_option("--grid", o->grid, "OpenVDB grid name (default: the first scalar grid)");
    cmd->add_option("--vdb-memory-mb", o->vdbMemoryMb,
                    "Address-space limit of the process that parses an OpenVDB file (MiB)")
        ->capture_default_str()
        ->check(CLI::Range(std::uint64_t(64), std::uint64_t(1) << 30));
    cmd->add_option("--vdb-parse-s", o->vdbParseS,
                    "Seconds the OpenVDB parser may take before it is killed")
        ->capture_default_str()
        ->check(CLI::Range(1u, 86400u));
    cmd->add_option("--mosaic", o->mosaic, "I,J,K: tile the input I x J x K times");
    cmd->add_option("--seed", o->seed, "Generator seed")->capture_default_str();
    cmd->add_option("--threads", o->threads, "Compression workers (0 = all cores)")
        ->capture_default_str();
    cmd->add_option("--zstd-level", o->zstdLevel, "zstd compression level")->capture_default_str();
    cmd->add_flag("-q,--quiet", o->quiet, "Print nothing on success");
    cmd->callback([o] { runIngest(*o); });
}

} // namespace bc::cli
