#!/usr/bin/env bash
# Runs the benchmark suite and writes the paper's Table I, Fig. 5 and the search throughput table.
# Usage: bench/run_benchmarks.sh [--quick [--against BUILD]] [--no-build] [--out DIR]
#   --quick     2-core CI timing study (< 3 min): fewer rows, 5 repetitions, medians and spread
#   --against BUILD  with --quick: also time this build (e.g. main's) against build/, interleaved
#               (bench/ab_compare.py, ~1.5 min), the way that resolves a 10 % change on a shared VM;
#               exits 1 when a row is slower
#   --no-build  use an existing build/ (the GPU machine: nothing is built there)
# Output (default out/bench): *.json (Google Benchmark), table1.md, fig5.csv, fig5.png, search.md
set -euo pipefail
cd "$(dirname "$0")/.."
quick=0; build=1; out=out/bench; against=
while [ $# -gt 0 ]; do
  case "$1" in
    --quick) quick=1 ;;
    --no-build) build=0 ;;
    --out) out="$2"; shift ;;
    --against) against="$2"; shift ;;
    *) echo "usage: $0 [--quick [--against BUILD]] [--no-build] [--out DIR]" >&2; exit 2 ;;
  esac
  shift
done
if [ -n "$against" ] && [ "$quick" != 1 ]; then echo "$0: --against needs --quick" >&2; exit 2; fi
if [ -n "$against" ] && [ ! -x "$against/bench/bench_table1" ]; then
  echo "$0: $against/bench/bench_table1 not found (build it with -DMINEMAP_BUILD_BENCH=ON)" >&2; exit 2
fi
if [ "$build" = 1 ]; then
  scripts/install-deps.sh bench
  cmake -S . -B build -DCMAKE_BUILD_TYPE=Release -DMINEMAP_BUILD_BENCH=ON -DMINEMAP_BENCH_PCL=ON >/dev/null
  cmake --build build -j"$(nproc)" --target bench_search bench_table1
  cmake --build build -j"$(nproc)" --target bench_peers 2>/dev/null || echo "bench_peers not built (no Open3D)"
fi
mkdir -p "$out"
if [ "$quick" = 1 ]; then
  reps=(--benchmark_repetitions=5 --benchmark_report_aggregates_only=false)
  build/bench/bench_search --benchmark_filter='NearestNeighbour|SliceFilter' "${reps[@]}" \
    --benchmark_out="$out/search.json" --benchmark_out_format=json
  MINEMAP_BENCH_SLAM_SCANS=6 build/bench/bench_table1 \
    --benchmark_filter='Table1_Pair/mine/cpu/(all_kd|reduced_apx|reduced_kd_accelerated)/|Table1_Pair/lidar/cpu/reduced_apx/' "${reps[@]}" \
    --benchmark_out="$out/table1.json" --benchmark_out_format=json
else
  build/bench/bench_search --benchmark_out="$out/search.json" --benchmark_out_format=json
  build/bench/bench_table1 --benchmark_out="$out/table1.json" --benchmark_out_format=json
  if [ -x build/bench/bench_peers ]; then
    OMP_NUM_THREADS="$(nproc)" build/bench/bench_peers --benchmark_out="$out/peers.json" --benchmark_out_format=json
  fi
fi
# Debian's python3 has python3-matplotlib (Fig. 5's PNG); a python3 earlier on PATH may not.
python=python3; [ -x /usr/bin/python3 ] && python=/usr/bin/python3
"$python" bench/make_tables.py "$out"
if [ -n "$against" ]; then
  "$python" bench/ab_compare.py "$against" build --out "$out/ab"
fi
# Peers that land on another pose than minemap's (more than 1 mm away) fail the run.
if [ -f "$out/peers.json" ]; then
  "$python" - "$out/peers.json" <<'PY'
import json, sys
bad = [b for b in json.load(open(sys.argv[1]))["benchmarks"] if b.get("error_occurred")]
for b in bad:
    print(f"peers disagree: {b['name']}: {b.get('error_message', '')}", file=sys.stderr)
sys.exit(1 if bad else 0)
PY
fi
