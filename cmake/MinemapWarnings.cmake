# Strict warnings on minemap's own targets only (never global flags).
function(minemap_set_warnings target)
  target_compile_options(${target} PRIVATE -Wall -Wextra -Wpedantic -Wno-unused-parameter
    $<$<CXX_COMPILER_ID:GNU>:-Wshadow=local>)
endfunction()

# Floating point as the OpenCL kernels compute it (kernels/common.cl: FP_CONTRACT OFF): no fused
# multiply-add contraction, so CPU and OpenCL poses stay bit-identical in every build, including
# MINEMAP_NATIVE (-march=native offers FMA and both g++ and clang would contract without this).
# -march=native stays PRIVATE: a consumer's binaries must not inherit the build machine's CPU.
function(minemap_set_fp_model target)
  target_compile_options(${target} PRIVATE -ffp-contract=off $<$<BOOL:${MINEMAP_NATIVE}>:-march=native>)
endfunction()
