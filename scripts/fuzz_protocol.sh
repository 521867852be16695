#!/usr/bin/env bash
# Fuzzes the protocol decoder with libFuzzer (tests/fuzz/ProtocolDecoderFuzz.cpp) under
# AddressSanitizer and UndefinedBehaviorSanitizer for a while; exits non-zero on a crash, a
# sanitizer report or a broken round trip (the crashing input is left in BUILD/fuzz/).
#
#   scripts/fuzz_protocol.sh [SECONDS] [BUILD_DIR]     (defaults: 30, ./build)
#
# Needs clang++ with libFuzzer (clang-14 and libclang-rt-14-dev on Debian); CXX_FUZZ picks
# another compiler. The binary is rebuilt only when a protocol source is newer; the corpus
# (BUILD/fuzz/corpus) is kept between runs and re-seeded with valid messages each time.
set -euo pipefail

seconds=${1:-30}
src=$(cd "$(dirname "${BASH_SOURCE[0]}")/.." && pwd)
build=$(mkdir -p "${2:-$src/build}" && cd "${2:-$src/build}" && pwd)
out=$build/fuzz
mkdir -p "$out/corpus"

cxx=${CXX_FUZZ:-}
if [[ -z $cxx ]]; then
    for candidate in clang++ clang++-14; do
        if command -v "$candidate" >/dev/null; then cxx=$candidate; break; fi
    done
fi
[[ -n $cxx ]] || { echo "fuzz_protocol.sh: no clang++ found (set CXX_FUZZ)" >&2; exit 1; }

cd "$src"
# The message sources; not the frame codecs (which would need zstd and libjpeg-turbo).
sources=(protocol/Wire.cpp protocol/Messages.cpp protocol/MessageRules.cpp
    protocol/PayloadDecoder.cpp protocol/Decoder.cpp)
harness=tests/fuzz/ProtocolDecoderFuzz.cpp
fuzzer=$out/protocol_decoder_fuzz

# True when the binary is missing or older than a source, a protocol header or the harness.
stale() {
    [[ ! -x $fuzzer ]] && return 0
    local f
    for f in "${sources[@]}" "$harness" protocol/*.h protocol/detail/*.h; do
        [[ $f -nt $fuzzer ]] && return 0
    done
    return 1
}

if stale; then
    echo "building $fuzzer with $cxx"
    "$cxx" -std=c++20 -O1 -g -fsanitize=fuzzer,address,undefined -fno-sanitize-recover=undefined \
        -Wall -Wextra -I"$src" "${sources[@]}" "$harness" -o "$fuzzer"
fi

echo "fuzzing for ${seconds}s"
# BC_FUZZ_SEED_DIR: the binary writes its seeds (valid messages) into the corpus first.
BC_FUZZ_SEED_DIR="$out/corpus" "$fuzzer" -max_total_time="$seconds" -max_len=4096 -timeout=10 \
    -print_final_stats=1 -artifact_prefix="$out/" "$out/corpus"
