#!/usr/bin/env bash
# Surveys of any length on one machine (issue 28, docs/scaling.md): `minemap simulate --scans N`
# for each N, then `minemap map` with the defaults (the memory bound included), one survey after the
# other; each run's wall time and peak resident memory (GNU time), its report.json; then
# bench/scale_report.py writes the table (OUT/scale.md, OUT/scale.json) and the plot of time per
# scan and resident memory against the scan's index (OUT/scale.svg, from report.json's
# "timings_s"."per_scan" and "memory_mb"."per_scan").
#
# Disk: a simulated stop-and-go scan is 3.5 MB of uos text (10 000 scans: 35 GB); each survey is
# deleted after its run unless --keep, and a survey already in WORK/scansN is used as it is.
# --loop M drives loops of about M metres (the pillars' circuit) instead of the straight drive.
#
# usage: bench/scale.sh [--scans "1000 5000 10000"] [--loop 0] [--threads 2] [--work /tmp/minemap-scale]
#                       [--out out/bench/scale] [--minemap build/minemap] [--keep] [-- MAP OPTIONS...]
set -euo pipefail
cd "$(dirname "$0")/.."
scans="1000 5000 10000"; loop=0; threads=2; work=/tmp/minemap-scale; out=out/bench/scale
minemap=build/minemap; keep=0; extra=()
while [ $# -gt 0 ]; do
  case "$1" in
    --scans) scans="$2"; shift ;;
    --loop) loop="$2"; shift ;;
    --threads) threads="$2"; shift ;;
    --work) work="$2"; shift ;;
    --out) out="$2"; shift ;;
    --minemap) minemap="$2"; shift ;;
    --keep) keep=1 ;;
    --) shift; extra=("$@"); break ;;
    *) echo "scale.sh: unknown option $1" >&2; exit 2 ;;
  esac
  shift
done
[ -x "$minemap" ] || { echo "scale.sh: no $minemap (build it first: cmake --build build --target minemap_cli)" >&2; exit 2; }
[ -x /usr/bin/time ] || { echo "scale.sh: needs GNU time (apt-get install time)" >&2; exit 2; }
mkdir -p "$work" "$out"
runs=()
for n in $scans; do
  tag="scans$n"; [ "$loop" != 0 ] && tag="${tag}-loop$loop"
  survey="$work/$tag"
  if [ ! -f "$survey/.complete" ]; then
    need_kb=$((n * 3600)); free_kb=$(df -Pk "$work" | awk 'NR==2 {print $4}')
    if [ "$free_kb" -lt "$need_kb" ]; then
      echo "scale.sh: $n scans need about $((need_kb / 1048576)) GB in $work; $((free_kb / 1048576)) GB free" >&2; exit 3
    fi
    rm -rf "$survey"
    echo "simulating $n scans into $survey"
    "$minemap" simulate --out "$survey" --scans "$n" --loop "$loop" --threads "$threads" > "$out/$tag.simulate.txt"
    touch "$survey/.complete"
  fi
  echo "mapping $n scans"
  rm -rf "$work/out-$tag"
  /usr/bin/time -f "%e %M" -o "$out/$tag.time" \
    "$minemap" map "$survey" --out "$work/out-$tag" --threads "$threads" "${extra[@]}" > "$out/$tag.map.txt" 2>&1 || true
  cp "$work/out-$tag/report.json" "$out/$tag.report.json" 2>/dev/null || echo "scale.sh: $tag wrote no report (see $out/$tag.map.txt)" >&2
  runs+=("$tag=$out/$tag.report.json=$out/$tag.time")
  rm -rf "$work/out-$tag"
  [ "$keep" = 1 ] || rm -rf "$survey"
done
python3 bench/scale_report.py --out "$out" "${runs[@]}"
