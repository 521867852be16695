#!/usr/bin/env bash
# Tests scripts/check_modules.sh on copies of the library folders: the copy as it is passes,
# and each planted violation (an upward include, an include of a program's header, a relative
# include out of the folder, a link to a module above, a main, an executable) fails it with
# the planted line named.
set -euo pipefail
here=$(cd "$(dirname "$0")" && pwd)
root=$(cd "$here/.." && pwd)
scratch=$(mktemp -d)
trap 'rm -rf "$scratch"' EXIT
failures=0

fresh() { # a clean copy of the library folders in $scratch/tree
  rm -rf "$scratch/tree"
  mkdir -p "$scratch/tree"
  for m in protocol brickstore render server client; do cp -r "$root/$m" "$scratch/tree/"; done
}

expectPass() {
  if ! out=$(bash "$here/check_modules.sh" "$scratch/tree" 2>&1); then
    echo "FAIL: the unchanged library folders fail the check:"
    echo "$out"
    failures=$((failures + 1))
  fi
}

expectCaught() { # what file pattern: the planted line must be named as file:line
  local what=$1 file=$2 pattern=$3 out
  if out=$(bash "$here/check_modules.sh" "$scratch/tree" 2>&1); then
    echo "FAIL: $what: not caught"
    failures=$((failures + 1))
  elif ! grep -qF "$file:" <<<"$out" || ! grep -qF -- "$pattern" <<<"$out"; then
    echo "FAIL: $what: caught, but the line is not named:"
    echo "$out"
    failures=$((failures + 1))
  else
    echo "ok: $what"
  fi
}

fresh
expectPass

fresh
echo '#include "server/Daemon.h"' >>"$scratch/tree/render/Camera.h"
expectCaught "render includes server" render/Camera.h '#include "server/Daemon.h"'

fresh
echo '#include <client/Client.h>' >>"$scratch/tree/server/Log.cpp"
expectCaught "server includes client (angle brackets)" server/Log.cpp '#include <client/Client.h>'

fresh
echo '#include "tools/TransferFunctionFile.h"' >>"$scratch/tree/server/Log.cpp"
expectCaught "server includes a program's header" server/Log.cpp 'tools/TransferFunctionFile.h'

fresh
echo '#include "../brickstore/BrickStore.h"' >>"$scratch/tree/protocol/Wire.h"
expectCaught "protocol includes brickstore by a relative path" protocol/Wire.h '../brickstore/BrickStore.h'

fresh
printf 'target_link_libraries(bc_client\n  PUBLIC bc_protocol bc_render)\n' >>"$scratch/tree/client/CMakeLists.txt"
expectCaught "client links render" client/CMakeLists.txt 'bc_render'

fresh
printf 'int main(int argc, char** argv) { return 0; }\n' >"$scratch/tree/brickstore/Tool.cpp"
expectCaught "a main in brickstore" brickstore/Tool.cpp 'int main('

fresh
echo 'add_executable(bc_tool Tool.cpp)' >>"$scratch/tree/protocol/CMakeLists.txt"
expectCaught "an executable in protocol" protocol/CMakeLists.txt 'add_executable(bc_tool'

if ((failures)); then
  echo "check_modules_test: $failures failure(s)"
  exit 1
fi
echo "check_modules_test: every planted violation caught and named"
