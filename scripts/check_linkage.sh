#!/usr/bin/env bash
# Every function and variable a library source defines with external linkage at namespace scope
# is declared in a header: a file's own helpers sit in an anonymous namespace, where two files'
# helpers of the same name cannot collide (an ODR violation the linker does not report) and
# the reader sees at once that nothing else calls them. Reads the object files of the
# libraries (protocol, brickstore, render, server, client) in BUILD_DIR (default ./build) with
# nm; prints each offender with its object and exits 1.
#
#   scripts/check_linkage.sh [BUILD_DIR]
set -euo pipefail
cd "$(dirname "$0")/.."
build=${1:-build}
[[ -d $build ]] || { echo "check_linkage: no build folder '$build'" >&2; exit 2; }

declared=$(mktemp)
trap 'rm -f "$declared"' EXIT
# Every word of every header of the libraries.
find protocol brickstore render server client -name '*.h' -print0 |
    xargs -0 grep -ohE '[A-Za-z_][A-Za-z0-9_]*' | sort -u >"$declared"

status=0
while IFS= read -r -d '' object; do
    # Defined, external, text or data (W: inline functions and templates from headers);
    # demangled; in namespace bc; qualified by namespaces only (lower case by STYLE.md, classes
    # are upper case): free functions and variables.
    while IFS= read -r symbol; do
        name=${symbol%%(*}
        name=${name%%\[*}
        name=${name##*::}
        if ! grep -qxF -- "$name" "$declared"; then
            echo "check_linkage: ${object#"$build"/}: $symbol is external but declared in no header" \
                "(an anonymous namespace?)"
            status=1
        fi
    done < <(nm -C -g --defined-only "$object" | awk '$2 ~ /^[TDBR]$/ { $1 = ""; $2 = ""; print substr($0, 3) }' |
        grep -E '^bc::([a-z][a-z0-9_]*::)+[a-z_][A-Za-z0-9_]*(\[abi:cxx11\])?(\(|$)' || true)
done < <(find "$build"/protocol "$build"/brickstore "$build"/render "$build"/server "$build"/client \
    -name '*.o' -print0 2>/dev/null)
exit $status
