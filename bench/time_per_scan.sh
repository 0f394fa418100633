#!/usr/bin/env bash
# The cost of each new scan as a survey grows, side by side in one run: `minemap map` on one survey
# in each configuration below, in turn, then the time spent on each scan when it arrived (report.json
# "timings_s"."per_scan": its match and, in the simultaneous mode, the relaxation after it) plotted
# against the scan's index (OUT/time_per_scan.svg) with the totals (OUT/time_per_scan.json).
#   pairwise      --preset simultaneous --mode pairwise --no-loop-closing (each scan against the last)
#   simultaneous  --preset simultaneous (the paper's relaxation, minemap's bounds: a union of the 8
#                 nearest overlapping scans, 8 matches after each new scan, the rest queued)
#   unbounded     --preset simultaneous --max-relaxation-matches 0 --max-relaxation-neighbours 0
#                 (the paper's queue: emptied after every scan, over every overlapping scan)
#   default       minemap's default (the metascan)
#   baseline      with --baseline BINARY: another minemap program, --preset simultaneous (an older
#                 build, to compare with)
# The survey is one that `minemap simulate` writes (--scans N --step-m M; the default, 200 scans
# 0.5 m apart, is a survey where each scan overlaps dozens of others, as a moving LiDAR's), or
# --survey DIR. Pass --configs to run fewer.
#
# usage: bench/time_per_scan.sh [--scans 200] [--step-m 0.5] [--survey DIR] [--threads 2]
#                               [--configs "pairwise simultaneous unbounded default"] [--baseline BINARY]
#                               [--out out/bench/time_per_scan] [--no-build] [--build-dir build]
set -euo pipefail
cd "$(dirname "$0")/.."
scans=200; step_m=0.5; survey=""; threads=2; configs="pairwise simultaneous unbounded default"; baseline=""
out=out/bench/time_per_scan; build=1; build_dir=build
while [ $# -gt 0 ]; do
  case "$1" in
    --scans) scans="$2"; shift ;;
    --step-m) step_m="$2"; shift ;;
    --survey) survey="$2"; shift ;;
    --threads) threads="$2"; shift ;;
    --configs) configs="$2"; shift ;;
    --baseline) baseline="$2"; shift ;;
    --out) out="$2"; shift ;;
    --no-build) build=0 ;;
    --build-dir) build_dir="$2"; shift ;;
    -h|--help) sed -n '2,/^set -euo/p' "$0" | sed '$d'; exit 0 ;;
    *) echo "usage: $0 [--scans N] [--step-m M] [--survey DIR] [--configs \"...\"] [--baseline BINARY] [--out DIR]" >&2
       exit 2 ;;
  esac
  shift
done
if [ "$build" = 1 ]; then
  scripts/install-deps.sh bench
  cmake -S . -B "$build_dir" -DCMAKE_BUILD_TYPE=Release >/dev/null
  cmake --build "$build_dir" -j"$(nproc)" --target minemap_cli
fi
minemap="$build_dir/minemap"
[ -x "$minemap" ] || { echo "time_per_scan: $minemap is missing (build it, or drop --no-build)" >&2; exit 2; }
[ -z "$baseline" ] || [ -x "$baseline" ] || { echo "time_per_scan: --baseline $baseline is not a program" >&2; exit 2; }
[ -z "$baseline" ] || configs="$configs baseline"
mkdir -p "$out"
work="$(mktemp -d)"
trap 'rm -rf "$work"' EXIT
if [ -z "$survey" ]; then
  survey="$work/survey"
  "$minemap" simulate --out "$survey" --scans "$scans" --step-m "$step_m" --threads "$threads"
fi
runs=()
for config in $configs; do
  program="$minemap"
  case "$config" in
    pairwise) args=(--preset simultaneous --mode pairwise --no-loop-closing) ;;
    simultaneous) args=(--preset simultaneous) ;;
    unbounded) args=(--preset simultaneous --max-relaxation-matches 0 --max-relaxation-neighbours 0) ;;
    default) args=() ;;
    baseline) program="$baseline"; args=(--preset simultaneous) ;;
    *) echo "time_per_scan: unknown config '$config'" >&2; exit 2 ;;
  esac
  echo "== $config: $program map ${args[*]}" >&2
  start=$(date +%s.%N)
  "$program" map "$survey" --out "$work/$config" --threads "$threads" --quiet "${args[@]}" || {
    code=$?
    # 13: a doubtful map; its timings still count.
    [ "$code" = 13 ] || { echo "time_per_scan: $config failed ($code)" >&2; exit 1; }
  }
  end=$(date +%s.%N)
  cp "$work/$config/report.json" "$out/$config.report.json"
  runs+=("$config=$out/$config.report.json=$start=$end")
done
py=$(command -v /usr/bin/python3 || command -v python3)  # Debian's, which has matplotlib
"$py" bench/plot_time_per_scan.py --out "$out" "${runs[@]}"
