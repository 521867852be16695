#!/usr/bin/env bash
# Builds and runs the test suites under sanitizers, each in a build folder of its own:
#
#   scripts/sanitize.sh asan [BUILD_DIR]   ASan+UBSan (-DBC_SANITIZE=ON), the module suites'
#                                          non-GL tests (protocol, brickstore, render, server;
#                                          ctest -LE 'gl|slow|fuzz'); default build-asan.
#                                          SANITIZE_ALL=1 adds the programs' suites (tools, bench)
#   scripts/sanitize.sh tsan [BUILD_DIR]   ThreadSanitizer, the server suite's non-GL tests
#                                          (tests/server); default build-tsan
#
# Prints the build and test wall times; exits non-zero on a build failure, a failing test or a
# sanitizer report (the report is in BUILD_DIR/Testing/Temporary/LastTest.log). JOBS sets the
# build parallelism (default 2); CXX/CC pick the compiler (default: CMake's, gcc on Debian).
# Non-GL tests run with BC_TEST_NO_GL=1 (set by ctest, see tests/CMakeLists.txt).
set -euo pipefail

kind=${1:?usage: scripts/sanitize.sh asan|tsan [BUILD_DIR]}
src=$(cd "$(dirname "${BASH_SOURCE[0]}")/.." && pwd)
jobs=${JOBS:-2}
launcher=()
command -v ccache >/dev/null && launcher=(-DCMAKE_CXX_COMPILER_LAUNCHER=ccache
    -DCMAKE_C_COMPILER_LAUNCHER=ccache)
# -O1: sanitizers' usual level (readable stacks, a fraction of -O3's compile time).
common=(-G Ninja -DCMAKE_BUILD_TYPE=Debug "${launcher[@]}")
flags="-O1 -fno-omit-frame-pointer"

case $kind in
asan)
    build=${2:-$src/build-asan}
    cmake_args=(-DBC_SANITIZE=ON "-DCMAKE_CXX_FLAGS=$flags")
    targets=(bc_protocol_tests bc_brickstore_tests bc_render_tests bc_server_tests)
    [[ ${SANITIZE_ALL:-0} == 1 ]] && targets+=(bc_tools_tests bc_bench_tests)
    # Suites not built leave a placeholder test (*_NOT_BUILT): skipped.
    ctest_args=(-LE 'gl|slow|fuzz' -E NOT_BUILT)
    # LeakSanitizer on; UBSan reports abort the test (-fno-sanitize-recover is in BC_SANITIZE).
    export ASAN_OPTIONS=${ASAN_OPTIONS:-detect_leaks=1:abort_on_error=0:detect_stack_use_after_return=1}
    export UBSAN_OPTIONS=${UBSAN_OPTIONS:-print_stacktrace=1:halt_on_error=1}
    export BC_TEST_TIME_SCALE=${BC_TEST_TIME_SCALE:-3}
    ;;
tsan)
    build=${2:-$src/build-tsan}
    cmake_args=("-DCMAKE_CXX_FLAGS=$flags -fsanitize=thread" "-DCMAKE_C_FLAGS=$flags -fsanitize=thread"
        -DCMAKE_EXE_LINKER_FLAGS=-fsanitize=thread -DBC_BUILD_TOOLS=OFF -DBC_BUILD_BENCH=OFF)
    targets=(bc_server_tests)
    # Only the server suite is built: the other suites' placeholders (*_NOT_BUILT) are skipped.
    ctest_args=(-LE 'gl|slow|fuzz' -E 'NOT_BUILT|^check_modules|^clang_format')
    # libtbb is not built with TSan: its scheduler's synchronization is invisible, so every
    # parallel_for (the CPU renderers) reports races. scripts/tsan.supp suppresses stacks
    # through oneTBB, which also hides a race inside a parallel_for body: TSAN_OPTIONS without
    # it shows everything.
    # history_size=7: the longest per-thread history, so that the stack of a TBB worker's
    # earlier access is restored (and matched by the suppressions) rather than "failed to
    # restore the stack". BC_TEST_TIME_SCALE: tests that bound a wait scale it (TSan runs the
    # CPU renderers 5-15x slower).
    export TSAN_OPTIONS=${TSAN_OPTIONS:-halt_on_error=0:second_deadlock_stack=1:history_size=7:suppressions=$src/scripts/tsan.supp}
    export BC_TEST_TIME_SCALE=${BC_TEST_TIME_SCALE:-10}
    ;;
*)
    echo "sanitize.sh: unknown kind '$kind' (asan or tsan)" >&2
    exit 2
    ;;
esac

start=$(date +%s)
cmake -S "$src" -B "$build" "${common[@]}" "${cmake_args[@]}" >/dev/null
nice ninja -C "$build" -j"$jobs" "${targets[@]}"
built=$(date +%s)
echo "sanitize.sh $kind: build ${targets[*]} took $((built - start)) s"

status=0
nice ctest --test-dir "$build" "${ctest_args[@]}" -j"$jobs" --output-on-failure --timeout 1800 || status=$?
done_at=$(date +%s)
echo "sanitize.sh $kind: tests took $((done_at - built)) s; total $(( (done_at - start) / 60 )) min; exit $status"
exit $status
