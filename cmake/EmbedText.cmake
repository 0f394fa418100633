# Embeds text files (here: Debian's three.js, inlined into map.html) into a generated C++ header at
# build time, each as an array of raw-string chunks that the program joins, the way
# embed_cl_script.cmake embeds the OpenCL kernels. The header is rebuilt when a file changes.
#
#   minemap_embed_text(OUTPUT <header> NAMESPACE <c++ namespace> ENTRIES <Name> <file> [<Name> <file>...]
#                      [FORBID <text>...])
# declares `inline constexpr const char* <Name>Chunks[]` in the namespace for each file. A file that
# holds a FORBID text (case-insensitive; e.g. "</script", which would end an inline <script>) fails
# the build, naming the file.
set(MINEMAP_EMBED_TEXT_SCRIPT ${CMAKE_CURRENT_LIST_DIR}/embed_text_script.cmake)
function(minemap_embed_text)
  cmake_parse_arguments(ARG "" "OUTPUT;NAMESPACE" "ENTRIES;FORBID" ${ARGN})
  list(LENGTH ARG_ENTRIES n)
  math(EXPR odd "${n} % 2")
  if(n EQUAL 0 OR odd)
    message(FATAL_ERROR "minemap_embed_text: ENTRIES takes <Name> <file> pairs")
  endif()
  set(files)
  math(EXPR last "${n} - 1")
  foreach(i RANGE 1 ${last} 2)
    list(GET ARG_ENTRIES ${i} file)
    list(APPEND files ${file})
  endforeach()
  string(REPLACE ";" "::" entries "${ARG_ENTRIES}")
  string(REPLACE ";" "::" forbid "${ARG_FORBID}")
  add_custom_command(OUTPUT ${ARG_OUTPUT}
    COMMAND ${CMAKE_COMMAND} -DOUT=${ARG_OUTPUT} -DNAMESPACE=${ARG_NAMESPACE} "-DENTRIES=${entries}"
            "-DFORBID=${forbid}" -P ${MINEMAP_EMBED_TEXT_SCRIPT}
    VERBATIM
    DEPENDS ${files} ${MINEMAP_EMBED_TEXT_SCRIPT}
    COMMENT "Embedding text into ${ARG_OUTPUT}")
endfunction()
