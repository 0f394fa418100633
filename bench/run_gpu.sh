#!/usr/bin/env bash
# Runs the benchmark suite on a lent GPU machine (NVIDIA through OpenCL). Builds nothing: carry
# build/ (built here with -DMINEMAP_BUILD_BENCH=ON) and the shared libraries it needs in .gpu-libs/
# (libtbb, liblzf, libpng, libbenchmark; see docs/benchmarks.md). Results land in $OUT or out/gpu.
set -euo pipefail
cd "$(dirname "$0")/.."
out="${OUT:-out/gpu}"
mkdir -p "$out" /etc/OpenCL/vendors
[ -f /etc/OpenCL/vendors/nvidia.icd ] || echo /usr/lib/libnvidia-opencl.so.1 > /etc/OpenCL/vendors/nvidia.icd
export LD_LIBRARY_PATH="$PWD/.gpu-libs${LD_LIBRARY_PATH:+:$LD_LIBRARY_PATH}"
export MINEMAP_OPENCL_DEVICE="${MINEMAP_OPENCL_DEVICE:-NVIDIA}"
nvidia-smi --query-gpu=name,driver_version,memory.total --format=csv > "$out/gpu.txt" 2>&1 || true
build/minemap simulate --out /tmp/minemap-gpu-survey --scans 48 > "$out/simulate.txt"
build/bench/bench_search --benchmark_out="$out/search.json" --benchmark_out_format=json | tee "$out/search.txt"
build/bench/bench_table1 --benchmark_out="$out/table1.json" --benchmark_out_format=json | tee "$out/table1.txt"
python3 bench/make_tables.py "$out" > "$out/tables.md" || true
