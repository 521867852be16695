#!/usr/bin/env bash
# Fails, naming each file, when a C++ source of the project is not formatted as .clang-format
# says (clang-format 14, Debian 12). Run by CTest (test "clang_format"); fix with
#   git ls-files '*.cpp' '*.h' | xargs clang-format -i
set -euo pipefail
cd "$(dirname "$0")/.."
format=$(command -v clang-format || command -v clang-format-14 || true)
if [ -z "$format" ]; then
  echo "check_format: clang-format not found (scripts/setup.sh installs it)" >&2
  exit 1
fi
if git rev-parse --is-inside-work-tree >/dev/null 2>&1; then
  mapfile -t files < <(git ls-files '*.cpp' '*.h')
else
  mapfile -t files < <(find protocol brickstore render server client tools bench tests \
                         -name '*.cpp' -o -name '*.h')
fi
# One clang-format for every file (a process per file takes 20 times as long); each unformatted
# place is reported as FILE:LINE:COL: error: ...
status=0
out=$("$format" --dry-run --Werror "${files[@]}" 2>&1) || status=$?
mapfile -t bad < <(sed -n 's/^\([^:]*\):[0-9]*:[0-9]*: error: .*/\1/p' <<<"$out" | sort -u)
if ((status != 0 && ${#bad[@]} == 0)); then # it failed for another reason: say what it said
  printf 'check_format: clang-format failed:\n%s\n' "$out" >&2
  exit 1
fi
if ((${#bad[@]})); then
  printf 'check_format: not formatted: %s\n' "${bad[@]}" >&2
  exit 1
fi
echo "check_format: ${#files[@]} files formatted as .clang-format says"
