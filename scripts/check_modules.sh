#!/usr/bin/env bash
# The module graph of ../shared/DESIGN.md, enforced: each library folder includes and links
# only the modules it may use, and holds no main (programs live in tools/, benchmarks in
# bench/; they and the tests may use anything).
#   protocol    nothing of ours
#   brickstore  nothing of ours
#   render      brickstore
#   server      protocol, brickstore, render
#   client      protocol
# Checks every `#include "X/..."` and `#include <X/...>` naming a folder of ours, every
# relative include that leaves the module's folder, every bc_* target in the module's
# target_link_libraries, and every add_executable or main. Prints each offending line as
# FILE:LINE: TEXT (why) and exits 1 if there is one. Usage: check_modules.sh [ROOT]
set -euo pipefail
root=$(cd "${1:-$(dirname "$0")/..}" && pwd)

libraries=(protocol brickstore render server client)
ours=(protocol brickstore render server client tools bench tests configs)
declare -A allowed=(
  [protocol]="protocol"
  [brickstore]="brickstore"
  [render]="render brickstore"
  [server]="server protocol brickstore render"
  [client]="client protocol"
)

bad=0
report() { # file line text why
  echo "${1#"$root"/}:$2: $3 ($4)"
  bad=1
}
isAllowed() { # module name
  local m
  for m in ${allowed[$1]}; do [ "$m" = "$2" ] && return 0; done
  return 1
}
isOurs() {
  local m
  for m in "${ours[@]}"; do [ "$m" = "$1" ] && return 0; done
  return 1
}

checkIncludes() { # module
  local module=$1 file line text target name dir resolved
  while IFS= read -r hit; do
    file=${hit%%:*}
    hit=${hit#*:}
    line=${hit%%:*}
    text=${hit#*:}
    [[ $text =~ include[[:space:]]*[\"\<]([^\">]*) ]] || continue
    target=${BASH_REMATCH[1]}
    if [[ $target == ../* || $target == */../* ]]; then
      dir=$(dirname "$file")
      resolved=$(realpath -m "$dir/$target")
      if [[ $resolved != "$root/$module/"* ]]; then
        report "$file" "$line" "$text" "$module/ may not include outside itself by a relative path"
      fi
      continue
    fi
    name=${target%%/*}
    [ "$name" = "$target" ] && continue # no folder: a system or same-folder header
    isOurs "$name" || continue
    isAllowed "$module" "$name" ||
      report "$file" "$line" "$text" "$module/ may use only: ${allowed[$module]}"
  done < <(grep -rnE '^[[:space:]]*#[[:space:]]*include[[:space:]]*["<]' "$root/$module" \
             --include='*.h' --include='*.hpp' --include='*.hh' --include='*.inl' \
             --include='*.ipp' --include='*.c' --include='*.cc' --include='*.cpp' \
             --include='*.cxx' --include='*.in' || true)
}

checkMains() { # module
  local hit
  while IFS= read -r hit; do
    local file=${hit%%:*} rest=${hit#*:}
    report "$file" "${rest%%:*}" "${rest#*:}" \
      "a library folder holds no main: programs go to tools/, benchmarks to bench/"
  done < <(grep -rnE '^[^/]*\bint[[:space:]]+main[[:space:]]*\(' "$root/$1" \
             --include='*.c' --include='*.cc' --include='*.cpp' --include='*.cxx' || true)
}

# CMake: every bc_<module> (and bc_tools*, bc_bench*) named in a target_link_libraries call
# of the module's CMakeLists.txt files, except the target being linked; and add_executable.
checkCMake() { # module
  local module=$1 file
  while IFS= read -r file; do
    local -a lines=()
    mapfile -t lines <"$file"
    local i n=${#lines[@]} call="" start=0 depth=0 text word first
    for ((i = 0; i < n; ++i)); do
      text=${lines[i]%%#*}
      if [ -z "$call" ]; then
        if [[ $text =~ add_executable[[:space:]]*\( ]]; then
          report "$file" $((i + 1)) "${lines[i]}" \
            "a library folder holds no main: programs go to tools/, benchmarks to bench/"
        fi
        [[ $text =~ target_link_libraries[[:space:]]*\( ]] || continue
        call="" start=$((i + 1)) depth=0
        text=${text#*target_link_libraries}
      fi
      call+=" $text"
      local opens=${text//[^(]/} closes=${text//[^)]/}
      depth=$((depth + ${#opens} - ${#closes}))
      ((depth > 0)) && continue
      call=${call#*(}
      call=${call%)*}
      first=""
      for word in $call; do
        if [ -z "$first" ]; then
          first=$word
          continue
        fi
        [[ $word =~ ^bc_([a-z]+) ]] || continue
        name=${BASH_REMATCH[1]}
        if [[ $name == tools* || $name == bench* ]] ||
          { isOurs "$name" && ! isAllowed "$module" "$name"; }; then
          report "$file" "$start" "target_link_libraries($first ... $word ...)" \
            "$module/ may link only: ${allowed[$module]}"
        fi
      done
      call=""
    done
  done < <(find "$root/$module" -name CMakeLists.txt -o -name '*.cmake' | sort)
}

for module in "${libraries[@]}"; do
  [ -d "$root/$module" ] || continue
  checkIncludes "$module"
  checkMains "$module"
  checkCMake "$module"
done
if ((bad)); then
  echo "check_modules: the module graph of DESIGN.md is broken (lines above)" >&2
  exit 1
fi
echo "check_modules: ${libraries[*]} include and link only what DESIGN.md allows; no main in them"
