#!/usr/bin/env bash
# Builds one libFuzzer target of tests/fuzz with clang (-fsanitize=fuzzer,address,undefined),
# seeds its corpus and fuzzes it for a while; exits non-zero on a finding: a crash, a
# sanitizer report, an uncaught exception, a broken property, a timeout (-timeout), an input
# using too much memory (-rss_limit_mb, -malloc_limit_mb). The crashing input is kept as
# BUILD/fuzz/TARGET/crash-* (or leak-*, timeout-*, oom-*); replay it with
# `BUILD/fuzz/TARGET/TARGET_fuzz FILE`.
#
#   scripts/fuzz.sh TARGET [SECONDS] [BUILD_DIR]     (defaults: 30, ./build)
#   scripts/fuzz.sh TARGET build [BUILD_DIR]         (build it only: the CMake build does)
#   scripts/fuzz.sh list                             (the targets)
#
# Targets: protocol_decoder, nrrd_header, nifti_header, dicom, metaimage, vti, brick_store,
# frame_codec, daemon_config. Each is compiled from the sources it needs only, into object
# files that the targets share (BUILD/fuzz/obj; also cached by ccache when present), and
# rebuilt when one of its module's sources or headers is newer. The build (tests/CMakeLists.txt)
# builds every target, so that the tests only fuzz.
# The corpus (BUILD/fuzz/TARGET/corpus) is kept between runs and re-seeded each time from
# the real scans (BC_SHARED_DATA_DIR, default ../shared/data) and configs/. CTest runs every
# target for 30 s (label fuzz); a long run is e.g. `scripts/fuzz.sh nifti_header 600 build`.
# Needs clang++ with libFuzzer (clang-14 and libclang-rt-14-dev on Debian); CXX_FUZZ picks
# another compiler. Extra libFuzzer flags: FUZZ_FLAGS (e.g. FUZZ_FLAGS=-jobs=2).
set -euo pipefail

targets=(protocol_decoder nrrd_header nifti_header dicom metaimage vti brick_store frame_codec
    daemon_config)
target=${1:?usage: scripts/fuzz.sh TARGET|list [SECONDS] [BUILD_DIR]}
if [[ $target == list ]]; then printf '%s\n' "${targets[@]}"; exit 0; fi
seconds=${2:-30}
src=$(cd "$(dirname "${BASH_SOURCE[0]}")/.." && pwd)
build=$(mkdir -p "${3:-$src/build}" && cd "${3:-$src/build}" && pwd)
out=$build/fuzz/$target
objdir=$build/fuzz/obj
mkdir -p "$out/corpus" "$objdir"

cxx=${CXX_FUZZ:-}
if [[ -z $cxx ]]; then
    for candidate in clang++ clang++-14; do
        if command -v "$candidate" >/dev/null; then cxx=$candidate; break; fi
    done
fi
[[ -n $cxx ]] || { echo "fuzz.sh: no clang++ found (set CXX_FUZZ)" >&2; exit 1; }
launcher=()
command -v ccache >/dev/null && launcher=(ccache)

# Per target: the sources (besides tests/fuzz/<Harness>.cpp), the folders whose headers it
# depends on, the libraries, the largest input and the libFuzzer memory limits.
cd "$src"
reader_common=(brickstore/VolumeSource.cpp brickstore/VoxelType.cpp brickstore/detail/RegularFile.cpp)
cflags=()
asan_options=detect_leaks=1
rss_mb=2048
malloc_mb=1024
case $target in
protocol_decoder)
    harness=ProtocolDecoderFuzz
    sources=(protocol/Wire.cpp protocol/Messages.cpp protocol/MessageRules.cpp
        protocol/PayloadDecoder.cpp protocol/Decoder.cpp)
    folders=(protocol)
    libs=()
    max_len=4096
    ;;
nrrd_header)
    harness=NrrdHeaderFuzz
    sources=(brickstore/readers/NrrdReader.cpp brickstore/readers/detail/FolderPath.cpp
        brickstore/readers/detail/RawStream.cpp brickstore/readers/detail/GzipStream.cpp
        brickstore/readers/detail/ReadAhead.cpp "${reader_common[@]}")
    folders=(brickstore brickstore/readers brickstore/readers/detail)
    libs=(-lzstd -lz)
    max_len=65536
    ;;
nifti_header)
    harness=NiftiHeaderFuzz
    sources=(brickstore/readers/NiftiReader.cpp "${reader_common[@]}")
    folders=(brickstore brickstore/readers)
    cflags=(-isystem /usr/include/nifti)
    libs=(-lniftiio -lznz -lz -lm)
    max_len=65536
    ;;
dicom)
    harness=DicomFuzz
    sources=(brickstore/readers/DicomReader.cpp brickstore/readers/detail/DicomHeaders.cpp
        brickstore/readers/detail/DicomLengths.cpp brickstore/readers/detail/SandboxedSource.cpp
        brickstore/readers/detail/ReadAhead.cpp
        "${reader_common[@]}")
    folders=(brickstore brickstore/readers brickstore/readers/detail)
    cflags=(-isystem "$(ls -d /usr/include/gdcm-* | tail -1)")
    libs=(-lgdcmMSFF -lgdcmDSED -lgdcmCommon)
    max_len=65536
    # The harness forks the parser sandbox per input; fork and exit cost grows with the
    # resident size, which ASan's 256 MiB quarantine mostly is (69 -> 88 inputs/s).
    asan_options=detect_leaks=1:quarantine_size_mb=16
    ;;
metaimage)
    harness=MetaImageFuzz
    sources=(brickstore/readers/MetaImageReader.cpp brickstore/readers/detail/FolderPath.cpp
        brickstore/readers/detail/RawStream.cpp brickstore/readers/detail/GzipStream.cpp
        brickstore/readers/detail/ReadAhead.cpp "${reader_common[@]}")
    folders=(brickstore brickstore/readers brickstore/readers/detail)
    libs=(-lzstd -lz)
    max_len=65536
    ;;
vti)
    harness=VtiFuzz
    sources=(brickstore/readers/VtiReader.cpp brickstore/readers/detail/VtiXml.cpp
        brickstore/readers/detail/VtiStreams.cpp brickstore/readers/detail/RawStream.cpp
        brickstore/readers/detail/GzipStream.cpp brickstore/readers/detail/ReadAhead.cpp
        "${reader_common[@]}")
    folders=(brickstore brickstore/readers brickstore/readers/detail)
    libs=(-lexpat -lzstd -lz)
    max_len=65536
    ;;
brick_store)
    harness=BrickStoreFuzz
    sources=(brickstore/BrickStore.cpp brickstore/StoreLayout.cpp brickstore/detail/StoreFormat.cpp
        brickstore/detail/StoreReadFile.cpp brickstore/detail/BrickSummary.cpp
        brickstore/Ingest.cpp brickstore/detail/LevelBuilder.cpp brickstore/detail/StoreFile.cpp
        brickstore/readers/SyntheticVolume.cpp "${reader_common[@]}")
    folders=(brickstore brickstore/detail brickstore/readers)
    libs=(-lzstd -lxxhash -lpthread)
    max_len=65536
    ;;
frame_codec)
    harness=FrameCodecFuzz
    sources=(protocol/FrameCodec.cpp protocol/PngImage.cpp protocol/Wire.cpp)
    folders=(protocol)
    libs=(-lzstd -lturbojpeg -lpng)
    max_len=65536
    ;;
daemon_config)
    harness=DaemonConfigFuzz
    # The presets of configs/tf and the default config, embedded as bc_render and bc_server embed
    # them (bc_embed_text, cmake/EmbedText.cmake).
    embed() { # OUTPUT HEADER NAMESPACE TYPE ARRAY COUNT FILES [NAMES]
        cmake -DOUTPUT="$1" -DHEADER="$2" -DNAMESPACE="$3" -DTYPE="$4" -DARRAY="$5" -DCOUNT="$6" \
            "-DFILES=$7" "-DNAMES=${8:-}" -P cmake/EmbedText.cmake
    }
    presets=(configs/tf/*.json)
    if [[ ! -e $out/TfPresets.cpp ||
        -n $(find configs/tf cmake/EmbedText.cmake -newer "$out/TfPresets.cpp") ]]; then
        names=("${presets[@]##*/}")
        embed "$out/TfPresets.cpp" render/detail/TfPresets.h bc::render::detail TfPresetText \
            kTfPresets kTfPresetCount "$(IFS=';'; echo "${presets[*]/#/$src/}")" \
            "$(IFS=';'; echo "${names[*]%.json}")"
    fi
    if [[ ! -e $out/DaemonConfigDefault.cpp ||
        -n $(find configs/brickcastd.toml cmake/EmbedText.cmake -newer "$out/DaemonConfigDefault.cpp") ]]; then
        embed "$out/DaemonConfigDefault.cpp" server/detail/DaemonConfigDefault.h bc::server::detail \
            DefaultConfigText kDefaultConfigFiles kDefaultConfigFileCount "$src/configs/brickcastd.toml"
    fi
    sources=(server/DaemonConfig*.cpp "$out/DaemonConfigDefault.cpp"
        render/TransferFunction.cpp "$out/TfPresets.cpp"
        brickstore/HostMemory.cpp "${reader_common[@]}" brickstore/Sources.cpp
        brickstore/readers/*.cpp brickstore/readers/detail/*.cpp)
    folders=(server render render/detail brickstore brickstore/readers protocol)
    # The config checks generator names with parseSynthKind (Sources.cpp), which comes with
    # openSource and so every reader.
    cflags+=(-isystem /usr/include/nifti -isystem "$(ls -d /usr/include/gdcm-* | tail -1)")
    libs+=(-lopenvdb -ltbb -lImath -lniftiio -lznz -lgdcmMSFF -lgdcmDSED -lgdcmCommon -lzstd -lz)
    read -ra toml_cflags <<<"$(pkg-config --cflags tomlplusplus)"
    read -ra toml_libs <<<"$(pkg-config --libs tomlplusplus)"
    cflags+=("${toml_cflags[@]}")
    libs+=("${toml_libs[@]}")
    # The TIFF, HDF5, Zarr (blosc) and .vti (expat) readers (their libraries).
    read -ra reader_cflags <<<"$(pkg-config --cflags hdf5 libtiff-4 blosc expat)"
    read -ra reader_libs <<<"$(pkg-config --libs hdf5 libtiff-4 blosc expat)"
    cflags+=("${reader_cflags[@]/#-I/-isystem}")
    libs+=("${reader_libs[@]}")
    max_len=16384
    ;;
*)
    echo "fuzz.sh: unknown target '$target'; one of: ${targets[*]}" >&2
    exit 2
    ;;
esac
harness_src=tests/fuzz/$harness.cpp
fuzzer=$out/${target}_fuzz

# True when the binary is missing or older than a source, a header of its folders or a
# harness file.
stale() {
    [[ ! -x $fuzzer ]] && return 0
    local f
    for f in "${sources[@]}" tests/fuzz/*; do
        [[ $f -nt $fuzzer ]] && return 0
    done
    for d in "${folders[@]}"; do
        for f in "$d"/*.h "$d"/detail/*.h; do
            [[ -e $f && $f -nt $fuzzer ]] && return 0
        done
    done
    return 1
}

flags=(-std=c++20 -O1 -g -fsanitize=fuzzer,address,undefined -fno-sanitize-recover=undefined
    -Wall -Wextra -Wno-unused-parameter -I"$src" "${cflags[@]}")
# The newest header of the target's folders: a shared object older than it is compiled again.
newest_header=
for d in "${folders[@]}"; do
    for f in "$d"/*.h "$d"/detail/*.h; do
        [[ -e $f ]] && [[ -z $newest_header || $f -nt $newest_header ]] && newest_header=$f
    done
done
if stale; then
    echo "building $fuzzer with $cxx"
    objects=()
    failed=$objdir/.failed.$$
    rm -f "$failed"
    compile() { # SOURCE OBJECT; a failure leaves $failed
        if "${launcher[@]}" "$cxx" "${flags[@]}" -c "$1" -o "$2.$$.tmp"; then
            mv -f "$2.$$.tmp" "$2"
        else
            touch "$failed"
        fi
    }
    for s in "${sources[@]}" "$harness_src"; do
        o=$objdir/$(echo "${s#"$build"/}" | tr / _).o
        # One object per source, shared by the targets that use it (the flags are the same but
        # for include folders); written under another name and renamed, so that two targets
        # built at once never link half an object. Compiled on every core: the build starts
        # the fuzz targets last, and one of them alone would leave the other cores idle.
        # -fsanitize=fuzzer at link time brings libFuzzer's main.
        if [[ ! -e $o || $s -nt $o || (-n $newest_header && $newest_header -nt $o) ]]; then
            while (($(jobs -rp | wc -l) >= $(nproc))); do wait -n || true; done
            compile "$s" "$o" &
        fi
        objects+=("$o")
    done
    wait
    if [[ -e $failed ]]; then
        rm -f "$failed"
        echo "fuzz.sh: compiling $target's sources failed" >&2
        exit 1
    fi
    "$cxx" "${flags[@]}" "${objects[@]}" "${libs[@]}" -o "$fuzzer.$$.tmp"
    mv -f "$fuzzer.$$.tmp" "$fuzzer"
fi
[[ $seconds == build ]] && exit 0

echo "fuzzing $target for ${seconds}s"
# BC_FUZZ_SEED_DIR: the binary writes its seeds into the corpus first.
export BC_FUZZ_SEED_DIR=$out/corpus
export BC_SHARED_DATA_DIR=${BC_SHARED_DATA_DIR:-$src/../shared/data}
export BC_CONFIGS_DIR=$src/configs
# Scratch files (the inputs as files) in a folder of this run, removed when it ends.
scratch_parent=/dev/shm
[[ -d $scratch_parent && -w $scratch_parent ]] || scratch_parent=${TMPDIR:-/tmp}
BC_FUZZ_SCRATCH=$(mktemp -d "$scratch_parent/bc-fuzz-$target.XXXXXX")
export BC_FUZZ_SCRATCH
trap 'rm -rf "$BC_FUZZ_SCRATCH"' EXIT
# LeakSanitizer on; UBSan reports are fatal (-fno-sanitize-recover above).
export ASAN_OPTIONS=${ASAN_OPTIONS:-$asan_options}
# shellcheck disable=SC2086
"$fuzzer" -max_total_time="$seconds" -max_len="$max_len" -timeout=10 -rss_limit_mb="$rss_mb" \
    -malloc_limit_mb="$malloc_mb" -print_final_stats=1 -print_funcs=0 -artifact_prefix="$out/" \
    ${FUZZ_FLAGS:-} "$out/corpus" || {
    status=$?
    echo "fuzz.sh: $target found a problem (exit $status); the input is in $out/ (crash-*, leak-*," \
        "timeout-*, oom-*); replay: $fuzzer FILE" >&2
    exit $status
}
