# Strict warnings on minemap's own targets only (never global flags).
function(minemap_set_warnings target)
  target_compile_options(${target} PRIVATE -Wall -Wextra -Wpedantic -Wno-unused-parameter
    $<$<CXX_COMPILER_ID:GNU>:-Wshadow=local>)
endfunction()
