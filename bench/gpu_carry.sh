#!/usr/bin/env bash
# Prepares what bench/run_gpu.sh needs on a lent GPU machine, which builds nothing and reaches no
# package source: the shared libraries the carried programs link against (Debian 12's, the OpenCL ICD
# loader among them) in .gpu-libs/, and a copy of ../shared/data (which does not travel) in
# .gpu-data/. Both folders are ignored by git. Run after building build/ with -DMINEMAP_BUILD_BENCH=ON.
# Usage: bench/gpu_carry.sh
set -euo pipefail
cd "$(dirname "$0")/.."
rm -rf .gpu-libs .gpu-data
mkdir -p .gpu-libs
# Everything the three programs load but the C library and the compiler's runtime (the machine has
# newer ones of its own).
ldd build/minemap build/bench/bench_search build/bench/bench_table1 | awk '/=> \// {print $3}' | sort -u |
  grep -v -E '/(libc|libm|libstdc\+\+|libgcc_s|ld-linux[^/]*)\.so' | while read -r lib; do cp -L "$lib" .gpu-libs/; done
cp -rL ../shared/data .gpu-data
du -sh .gpu-libs .gpu-data build/minemap build/bench/bench_search build/bench/bench_table1
