#!/usr/bin/env bash
# Runs minemap on a lent GPU machine (NVIDIA through OpenCL) in one call: whole surveys mapped with
# --backend opencl and --backend cpu side by side (times, and whether the poses agree bit for bit),
# then the search and Table I benchmarks. Builds nothing there. Carry (built here, see
# docs/benchmarks.md "On a lent GPU"): build/minemap, build/bench/bench_search,
# build/bench/bench_table1, the shared libraries they need in .gpu-libs/ (bench/gpu_carry.sh makes
# it) and the real scans in .gpu-data/ (a copy of ../shared/data, which does not travel).
#
# The device tool brings back at most 8 files: everything lands in OUT/gpu-results.tar.gz (made again
# after every stage, so a run cut short still returns what it finished) and OUT/run_gpu.log.
# Every stage has its own time limit (seconds, below); on the H200 machine's 16 cores the whole run
# should take about 5 minutes.
# Usage: bench/run_gpu.sh   (OUT=DIR for the results, default out/gpu)
set -uo pipefail
cd "$(dirname "$0")/.."
out="${OUT:-out/gpu}"
results="$out/results"
work=/tmp/minemap-gpu
mkdir -p "$results" "$work" /etc/OpenCL/vendors
# NVIDIA's OpenCL driver: where the image puts it (the driver's folder is mounted on some machines).
if [ ! -f /etc/OpenCL/vendors/nvidia.icd ]; then
  for icd in /usr/lib/libnvidia-opencl.so.1 /usr/lib/x86_64-linux-gnu/libnvidia-opencl.so.1 \
             /usr/local/nvidia/lib64/libnvidia-opencl.so.1 /usr/local/nvidia/lib/libnvidia-opencl.so.1; do
    if [ -e "$icd" ]; then echo "$icd" > /etc/OpenCL/vendors/nvidia.icd; break; fi
  done
fi
export LD_LIBRARY_PATH="$PWD/.gpu-libs${LD_LIBRARY_PATH:+:$LD_LIBRARY_PATH}"
export MINEMAP_OPENCL_DEVICE="${MINEMAP_OPENCL_DEVICE:-NVIDIA}"
# The benchmarks read ../shared/data through the path compiled into them.
shared_data="$(grep -a -o -m1 '/[[:alnum:]/._-]*/shared/data' build/bench/bench_search | head -n 1)"
if [ -d .gpu-data ] && [ -n "$shared_data" ] && [ ! -e "$shared_data" ]; then
  mkdir -p "$(dirname "$shared_data")" && ln -s "$PWD/.gpu-data" "$(realpath -m "$shared_data")"
fi
started=$SECONDS
pack() { tar -C "$out" -czf "$out/gpu-results.tar.gz.tmp" results && mv "$out/gpu-results.tar.gz.tmp" "$out/gpu-results.tar.gz"; }
# stage NAME LIMIT_S COMMAND...: runs it with its output in results/NAME.txt; its exit status and wall
# time go to results/stages.tsv.
stage() {
  local name=$1 limit=$2; shift 2
  local t0=$SECONDS
  echo "--- $name (limit ${limit} s, at $((SECONDS - started)) s)"
  timeout "$limit" "$@" > "$results/$name.txt" 2>&1
  local rc=$?
  printf '%s\t%s\t%s\n' "$name" "$rc" "$((SECONDS - t0))" >> "$results/stages.tsv"
  grep -v -E 'progress|^\s*(Average|Major|Minor|Voluntary|Involuntary|Swaps|File system|Socket|Signals|Page size|Percent|System time|User time)' \
    "$results/$name.txt" | tail -n 6
  echo "    rc $rc, $((SECONDS - t0)) s"
  pack
  return 0
}
# map_both NAME SURVEY LIMIT_S [OPTIONS...]: maps SURVEY with --backend cpu and --backend opencl,
# keeps report.json, the poses (one file) and the console; poses_agree.tsv says whether they match.
map_both() {
  local name=$1 survey=$2 limit=$3; shift 3
  for backend in cpu opencl; do
    rm -rf "$work/$name-$backend"
    stage "map-$name-$backend" "$limit" /usr/bin/env time -v build/minemap map "$survey" --out "$work/$name-$backend" \
      --backend "$backend" "$@"
    cp "$work/$name-$backend/report.json" "$results/map-$name-$backend.report.json" 2>/dev/null
    cat "$work/$name-$backend"/*.pose > "$results/map-$name-$backend.poses" 2>/dev/null
  done
  if [ -s "$results/map-$name-cpu.poses" ] && cmp -s "$results/map-$name-cpu.poses" "$results/map-$name-opencl.poses"; then
    printf '%s\tidentical\n' "$name" >> "$results/poses_agree.tsv"
  else
    printf '%s\tDIFFERENT\n' "$name" >> "$results/poses_agree.tsv"
  fi
  pack
}

stage environment 30 bash -c 'nvidia-smi --query-gpu=name,driver_version,memory.total --format=csv; nproc; \
  free -g; cat /etc/os-release | head -2; ldd build/minemap build/bench/bench_search build/bench/bench_table1 | grep -i "not found"; \
  cat /etc/OpenCL/vendors/*.icd; ls /usr/local/nvidia/lib64 2>&1 | grep -i opencl; true'
stage simulate-64 60 build/minemap simulate --out "$work/sim64" --scans 64
stage simulate-200 120 build/minemap simulate --out "$work/sim200" --scans 200
stage simulate-spinning-200 60 build/minemap simulate --out "$work/spin200" --sensor spinning --scans 200
stage simulate-handheld-200 60 build/minemap simulate --out "$work/hand200" --sensor handheld --scans 200
# The default (voxel means, one match per scan against a metascan), then the paper's simultaneous
# matching, where the correspondence search is most of the time.
map_both sim64 "$work/sim64" 60
map_both sim64-simultaneous "$work/sim64" 120 --preset simultaneous
map_both sim200 "$work/sim200" 90
map_both spinning200 "$work/spin200" 90
map_both handheld200 "$work/hand200" 90
if [ -d .gpu-data ]; then
  map_both kitti07 .gpu-data/kitti07_sequence 30
  map_both jinchuan .gpu-data/mine_jinchuan_pcr 30
fi
stage bench_search 100 build/bench/bench_search --benchmark_out="$results/search.json" --benchmark_out_format=json
stage bench_table1 100 build/bench/bench_table1 \
  --benchmark_out="$results/table1.json" --benchmark_out_format=json
# The largest survey last: 1000 scans, 123 M points (issue 28's scale).
stage simulate-1000 150 build/minemap simulate --out "$work/sim1000" --scans 1000
map_both sim1000 "$work/sim1000" 150
echo "--- done at $((SECONDS - started)) s"
cat "$results/stages.tsv" "$results/poses_agree.tsv"
pack
