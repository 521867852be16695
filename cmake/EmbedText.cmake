# bc_embed_text: text files compiled into a library as string literals, so the files stay the one
# source of truth and the binary reads none at run time. Embeds the GLSL of render/shaders, the
# transfer-function presets of configs/tf and the daemon's default config (configs/brickcastd.toml).
#
#   bc_embed_text(TARGET <target> SOURCE <name.cpp> HEADER <header> NAMESPACE <ns>
#                 TYPE <struct> ARRAY <array> COUNT <count> FILES <files...> [NAMES <names...>]
#                 [GLSL])
#
# writes <name.cpp> into the current build folder and adds it to <target>. It includes <header>
# (from the repository root), which declares in <ns> the struct and the two constants it defines:
#
#   struct <struct> { const char* name; const char* text; };  // fields in this order, any names;
#                                                             // GLSL: name, includes, text
#   extern const <struct> <array>[];                          // one per file, sorted by name
#   extern const std::size_t <count>;
#
# A name is the file's name unless NAMES gives one per file; a text is the file's exact bytes as a
# raw string literal, whatever `)"` sequences it holds (the compiler checks its length; a file with
# a carriage return or a NUL is refused). The step reruns when a file or this script changes; a
# file added to a folder the caller globs is picked up when cmake reruns.
#
# GLSL: the files are render/shaders' (render/shaders/README.md). Stage files
# (NAME.vert|geom|frag|comp.glsl) start with their #version line. A line `#include "NAME.inc.glsl"`
# of a stage file is replaced by that snippet, between #line directives: the compiler's log then
# gives the stage file's own lines as they are, and line k of the n-th included snippet as
# n * 1000 + k (files have fewer than 1000 lines). `includes` lists a stage file's snippets.
#
# Script mode, what the build step runs: cmake -DOUTPUT=<file.cpp> -DHEADER=... -DNAMESPACE=...
#   -DTYPE=... -DARRAY=... -DCOUNT=... "-DFILES=a;b" ["-DNAMES=x;y"] [-DGLSL=ON] -P EmbedText.cmake

if(CMAKE_SCRIPT_MODE_FILE STREQUAL CMAKE_CURRENT_LIST_FILE)
  cmake_policy(VERSION 3.20)

  # Sets ${out} to `text` of stage file `name` with its include lines expanded, and
  # ${outIncludes} to the included snippets, space-separated, in order.
  function(bc_expand_includes name text dir out outIncludes)
    set(rest "${text}")
    set(done "")
    set(includes "")
    set(line 1) # the original line number of rest's first line
    set(count 0)
    while(TRUE)
      string(REGEX MATCH "(^|\n)#include \"([^\"\n]*)\"\n" match "${rest}")
      if(NOT match)
        break()
      endif()
      set(snippetName "${CMAKE_MATCH_2}")
      string(FIND "${rest}" "${match}" pos)
      if(match MATCHES "^\n")
        math(EXPR pos "${pos} + 1")
      endif()
      string(SUBSTRING "${rest}" 0 ${pos} before)
      string(REGEX REPLACE "[^\n]" "" newlines "${before}")
      string(LENGTH "${newlines}" skipped)
      math(EXPR line "${line} + ${skipped}")
      if(NOT snippetName MATCHES "^[a-z0-9_]+\\.inc\\.glsl$" OR NOT EXISTS "${dir}/${snippetName}")
        message(FATAL_ERROR "${name}:${line}: no snippet ${dir}/${snippetName} (NAME.inc.glsl)")
      endif()
      file(READ "${dir}/${snippetName}" snippet)
      if(NOT snippet MATCHES "\n$" OR snippet MATCHES "#include|#version")
        message(FATAL_ERROR "${snippetName}: a snippet ends with a newline and has no #include or #version")
      endif()
      math(EXPR count "${count} + 1")
      math(EXPR next "${line} + 1")
      math(EXPR first "${count} * 1000 + 1")
      string(APPEND done "${before}#line ${first}\n${snippet}#line ${next}\n")
      string(APPEND includes " ${snippetName}")
      string(LENGTH "${match}" matchLength)
      string(FIND "${match}" "#" hash)
      math(EXPR start "${pos} + ${matchLength} - ${hash}")
      string(SUBSTRING "${rest}" ${start} -1 rest)
      set(line ${next})
    endwhile()
    string(APPEND done "${rest}")
    if(done MATCHES "#include")
      message(FATAL_ERROR "${name}: #include \"NAME.inc.glsl\" goes on a line of its own")
    endif()
    string(STRIP "${includes}" includes)
    set(${out} "${done}" PARENT_SCOPE)
    set(${outIncludes} "${includes}" PARENT_SCOPE)
  endfunction()

  # Sets ${out} to the text of GLSL file `input` as embedded and ${outIncludes} to its snippets.
  function(bc_glsl_text input text out outIncludes)
    get_filename_component(name "${input}" NAME)
    get_filename_component(dir "${input}" DIRECTORY)
    string(REGEX REPLACE "[^\n]" "" newlines "${text}")
    string(LENGTH "${newlines}" lines)
    if(lines GREATER_EQUAL 1000)
      message(FATAL_ERROR "${input}: 1000 lines or more (an included snippet's lines start at 1001)")
    endif()
    set(includes "")
    if(name MATCHES "^[a-z0-9_]+\\.(vert|geom|frag|comp)\\.glsl$")
      if(NOT text MATCHES "^#version [^\n]*\n")
        message(FATAL_ERROR "${input}: a stage file starts with its #version line")
      endif()
      bc_expand_includes("${name}" "${text}" "${dir}" text includes)
    elseif(NOT name MATCHES "^[a-z0-9_]+\\.inc\\.glsl$")
      message(FATAL_ERROR "${input}: name it NAME.vert|geom|frag|comp.glsl or NAME.inc.glsl")
    endif()
    set(${out} "${text}" PARENT_SCOPE)
    set(${outIncludes} "${includes}" PARENT_SCOPE)
  endfunction()

  # Sets ${out} to `text` as a raw string literal, its delimiter one that `text` does not hold.
  function(bc_raw_string text out)
    set(delimiter "bc")
    set(n 0)
    while(TRUE)
      string(FIND "${text}" ")${delimiter}\"" clash)
      if(clash EQUAL -1)
        break()
      endif()
      math(EXPR n "${n} + 1")
      set(delimiter "bc${n}")
    endwhile()
    set(${out} "R\"${delimiter}(${text})${delimiter}\"" PARENT_SCOPE)
  endfunction()

  # Sets ${out} to the bytes of `input`. file(READ) drops carriage returns (as the compiler would
  # in a raw string literal) and a variable ends at a NUL: such a file is refused.
  function(bc_read_text input out)
    file(READ "${input}" text)
    file(SIZE "${input}" size)
    string(LENGTH "${text}" length)
    if(NOT length EQUAL size)
      message(FATAL_ERROR "${input}: read ${length} of its ${size} bytes (carriage returns?)")
    endif()
    file(READ "${input}" hex HEX)
    string(REGEX REPLACE "(..)" "\\1," hex "${hex}")
    string(FIND ",${hex}" ",00," nul)
    if(NOT nul EQUAL -1)
      message(FATAL_ERROR "${input}: has a NUL byte, so it is no text")
    endif()
    set(${out} "${text}" PARENT_SCOPE)
  endfunction()

  if(NOT FILES)
    message(FATAL_ERROR "EmbedText.cmake: no FILES for ${ARRAY}")
  endif()
  if(NOT NAMES)
    set(NAMES "")
    foreach(input IN LISTS FILES)
      get_filename_component(name "${input}" NAME)
      list(APPEND NAMES "${name}")
    endforeach()
  endif()
  list(LENGTH FILES count)
  list(LENGTH NAMES nameCount)
  set(sorted ${NAMES})
  list(REMOVE_DUPLICATES sorted)
  list(LENGTH sorted uniqueCount)
  if(NOT nameCount EQUAL count OR NOT uniqueCount EQUAL count)
    message(FATAL_ERROR "EmbedText.cmake: ${ARRAY} needs one name per file, each once: ${NAMES}")
  endif()
  list(SORT sorted)
  foreach(name IN LISTS sorted)
    if(NOT name MATCHES "^[^\"\\\\]+$")
      message(FATAL_ERROR "EmbedText.cmake: '${name}' is no name for a string literal")
    endif()
  endforeach()
  # Each text is a constant of its own whose length the compiler checks: the string it made holds
  # the file's bytes and no NUL.
  set(texts "")
  set(body "")
  set(i 0)
  foreach(name IN LISTS sorted)
    list(FIND NAMES "${name}" index)
    list(GET FILES ${index} input)
    bc_read_text("${input}" text)
    if(GLSL)
      bc_glsl_text("${input}" "${text}" text includes)
      string(APPEND body "    {\"${name}\", \"${includes}\", kText${i}},\n")
    else()
      string(APPEND body "    {\"${name}\", kText${i}},\n")
    endif()
    bc_raw_string("${text}" literal)
    string(LENGTH "${text}" length)
    string(APPEND texts "// ${input}\nconstexpr char kText${i}[] = ${literal};\n")
    string(APPEND texts "static_assert(std::char_traits<char>::length(kText${i}) == ${length},\n")
    string(APPEND texts "              \"${name}: not its ${length} bytes, or a NUL among them\");\n\n")
    math(EXPR i "${i} + 1")
  endforeach()
  set(code "// Generated by cmake/EmbedText.cmake (bc_embed_text): do not edit.\n")
  string(APPEND code "#include \"${HEADER}\"\n\n#include <string>\n\n")
  string(APPEND code "namespace ${NAMESPACE} {\nnamespace {\n\n${texts}} // namespace\n\n")
  string(APPEND code "extern const ${TYPE} ${ARRAY}[] = {\n${body}};\n")
  string(APPEND code "extern const std::size_t ${COUNT} = ${count};\n\n")
  string(APPEND code "} // namespace ${NAMESPACE}\n")
  file(WRITE "${OUTPUT}" "${code}")
  return()
endif()

include_guard(GLOBAL)

function(bc_embed_text)
  cmake_parse_arguments(PARSE_ARGV 0 arg "GLSL" "TARGET;SOURCE;HEADER;NAMESPACE;TYPE;ARRAY;COUNT"
                        "FILES;NAMES")
  foreach(key TARGET SOURCE HEADER NAMESPACE TYPE ARRAY COUNT FILES)
    if(NOT arg_${key})
      message(FATAL_ERROR "bc_embed_text: ${key} is missing or empty")
    endif()
  endforeach()
  set(script ${CMAKE_CURRENT_FUNCTION_LIST_FILE})
  set(output ${CMAKE_CURRENT_BINARY_DIR}/${arg_SOURCE})
  set(glsl OFF)
  if(arg_GLSL)
    set(glsl ON)
  endif()
  add_custom_command(
    OUTPUT ${output}
    COMMAND ${CMAKE_COMMAND} -DOUTPUT=${output} -DHEADER=${arg_HEADER} -DNAMESPACE=${arg_NAMESPACE}
            -DTYPE=${arg_TYPE} -DARRAY=${arg_ARRAY} -DCOUNT=${arg_COUNT} "-DFILES=${arg_FILES}"
            "-DNAMES=${arg_NAMES}" -DGLSL=${glsl} -P ${script}
    DEPENDS ${arg_FILES} ${script}
    COMMENT "Embedding ${arg_ARRAY} (${arg_SOURCE})"
    VERBATIM)
  target_sources(${arg_TARGET} PRIVATE ${output})
endfunction()
