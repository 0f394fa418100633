# Embeds OpenCL C sources into one header at build time, as raw-string chunks (one kernel source
# string with no #include: PoCL will not cache programs that #include, and NVIDIA's JIT cache misses
# header changes). The header is rebuilt whenever a .cl file changes.
set(MINEMAP_EMBED_SCRIPT ${CMAKE_CURRENT_LIST_DIR}/embed_cl_script.cmake)
function(minemap_embed_opencl)
  cmake_parse_arguments(ARG "" "OUTPUT" "SOURCES" ${ARGN})
  set(abs_sources)
  foreach(src ${ARG_SOURCES})
    list(APPEND abs_sources ${CMAKE_CURRENT_SOURCE_DIR}/${src})
  endforeach()
  string(REPLACE ";" "::" joined "${abs_sources}")
  add_custom_command(OUTPUT ${ARG_OUTPUT}
    COMMAND ${CMAKE_COMMAND} -DOUT=${ARG_OUTPUT} "-DINPUTS=${joined}" -P ${MINEMAP_EMBED_SCRIPT}
    VERBATIM
    DEPENDS ${abs_sources} ${MINEMAP_EMBED_SCRIPT}
    COMMENT "Embedding OpenCL kernels into ${ARG_OUTPUT}")
endfunction()
