# Strict warnings on minemap's own targets only (never global flags).
function(minemap_set_warnings target)
  target_compile_options(${target} PRIVATE -Wall -Wextra -Wpedantic -Wno-unused-parameter
    $<$<CXX_COMPILER_ID:GNU>:-Wshadow=local>)
endfunction()

# Floating point as the OpenCL kernels compute it (kernels/common.cl: FP_CONTRACT OFF): no fused
# multiply-add contraction, so CPU and OpenCL poses stay bit-identical in every build, including
# MINEMAP_NATIVE (-march=native offers FMA and both g++ and clang would contract without this).
# -march=native is PUBLIC: Eigen aligns its fixed-size types (a Pose is a Matrix4d) to the widest
# vectors the target CPU has (16 bytes with SSE2, 32 with AVX, 64 with AVX-512), so a struct holding
# one (Scan, ScanOutcome) is laid out differently in a file compiled without it, and the two halves of
# a program disagree about it. Every file that links a native build must be compiled native too; seen
# 2026-12-05: a fuzz replay program (not native) freed a pointer that was a Pose's first double.
function(minemap_set_fp_model target)
  target_compile_options(${target} PRIVATE -ffp-contract=off)
  if(MINEMAP_NATIVE)  # a portable build exports no CPU option at all (install_and_find_package checks)
    target_compile_options(${target} PUBLIC -march=native)
  endif()
endfunction()
