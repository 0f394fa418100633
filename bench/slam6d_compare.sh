#!/usr/bin/env bash
# Whole surveys, side by side: minemap against 3DTK's slam6D (the paper group's program) on the same
# simulated surveys, both timed in one run, interleaved. A survey is SCANS:SEED for `minemap
# simulate` (0 scans: the whole 250 m drive, 64 scans; the default survey is 0:1). For each survey it writes the survey with
# `minemap simulate`, then runs, REPEATS times each, taking turns:
#   minemap  `minemap map SURVEY --out OUT --threads THREADS` (minemap's default, the whole-survey
#            mode) and the extra rows given with --minemap-modes: `pairwise` (--mode pairwise),
#            `simultaneous` (--preset simultaneous, the default before 2026-12), `paper`
#            (--preset paper), `threads1` (the default on one thread)
#   slam6D   `slam6D -s 0 -e N-1 -f uos -r 10 -O 1 -d 25 -a 1 -t 0 -i 50 --metascan -q SURVEY`
#            (its fastest configuration that reaches its best accuracy) and, with --slam6d-pairwise,
#            the same without --metascan
# and measures wall time and peak RSS (/usr/bin/time), and the mean and max pose error against the
# survey's truth, computed the same way for both (build/bench/pose_error: pose_errors relative to
# the first scan, the last line of each scanNNN.frames; and the mean error of each step from one
# scan to the next, which drifts less from survey to survey than the whole path's error). Medians
# of the repetitions go into a Markdown table (OUT/slam6d.md) and JSON (OUT/slam6d.json), with the
# ratios measured side by side: default vs slam6D --metascan, pairwise vs slam6D pairwise, and
# 2 threads vs 1.
#
# slam6D is not built here: build it yourself from a 3DTK checkout (its own README says how; build
# it serially, without its viewers, for a fair single-core figure) and give the path of the slam6D
# program. Without one the script says so and exits 0 having compared nothing.
#
# usage: bench/slam6d_compare.sh --slam6d PATH [--surveys "0:1 0:7 200:1"] [--repeats 3]
#                                [--threads 2] [--minemap-modes "pairwise threads1"] [--slam6d-pairwise]
#                                [--out out/bench/slam6d] [--no-build] [--build-dir build]
set -euo pipefail
cd "$(dirname "$0")/.."
slam6d=""; surveys="0:1 0:7 200:1"; repeats=3; threads=2; modes=""; slam_pairwise=0
out=out/bench/slam6d; build=1; build_dir=build
while [ $# -gt 0 ]; do
  case "$1" in
    --slam6d) slam6d="$2"; shift ;;
    --surveys) surveys="$2"; shift ;;
    --repeats) repeats="$2"; shift ;;
    --threads) threads="$2"; shift ;;
    --minemap-modes) modes="$2"; shift ;;
    --slam6d-pairwise) slam_pairwise=1 ;;
    --out) out="$2"; shift ;;
    --no-build) build=0 ;;
    --build-dir) build_dir="$2"; shift ;;
    -h|--help) sed -n '2,/^set -euo/p' "$0" | sed '$d'; exit 0 ;;
    *) echo "usage: $0 --slam6d PATH [--surveys \"64:1 64:7 200:1\"] [--repeats N] [--threads N] ..." >&2; exit 2 ;;
  esac
  shift
done
if [ -z "$slam6d" ] || [ ! -x "$slam6d" ]; then
  echo "slam6d_compare: no slam6D program given (--slam6d PATH): nothing compared." >&2
  echo "  Build slam6D from a 3DTK checkout (github.com/3DTK/3DTK; its README), then pass its bin/slam6D." >&2
  exit 0
fi
if [ "$build" = 1 ]; then
  scripts/install-deps.sh bench
  cmake -S . -B "$build_dir" -DCMAKE_BUILD_TYPE=Release -DMINEMAP_BUILD_BENCH=ON >/dev/null
  cmake --build "$build_dir" -j"$(nproc)" --target minemap_cli pose_error
fi
[ -x /usr/bin/time ] || { echo "slam6d_compare: /usr/bin/time is missing (apt-get install time)" >&2; exit 2; }
mkdir -p "$out"
work="$(mktemp -d)"
trap 'rm -rf "$work"' EXIT
results="$out/runs.tsv"
printf 'survey\tsystem\trun\twall_s\tpeak_rss_mb\tmean_cm\tmax_cm\tpercent\tstep_cm\tstep_deg\n' > "$results"

# Runs "$@" under /usr/bin/time; prints "wall_s peak_rss_mb".
timed() {
  /usr/bin/time -f '%e %M' -o "$work/time" "$@" > "$work/log" 2>&1 || { tail -n 20 "$work/log" >&2; return 1; }
  awk '{ printf "%s %.0f", $1, $2 / 1024 }' "$work/time"
}
error_of() {  # survey frames_dir -> "mean max percent step_cm step_deg"
  "$build_dir/bench/pose_error" "$1" "$2" | sed 's/[{}",]//g' |
    awk '{ for (i = 1; i <= NF; i++) v[$i] = $(i + 1) } END { printf "%s %s %s %s %s", v["mean_translation_cm:"], v["max_translation_cm:"], v["percent_of_path:"], v["mean_step_translation_cm:"], v["mean_step_rotation_deg:"] }'
}

for spec in $surveys; do
  scans="${spec%%:*}"; seed="${spec##*:}"; name="${scans}scans-seed${seed}"
  survey="$work/$name"
  "$build_dir/minemap" simulate --out "$survey" --scans "$scans" --seed "$seed" >/dev/null
  scans="$(find "$survey" -maxdepth 1 -name 'scan*.3d' | wc -l)"  # --scans 0: the whole drive
  systems=("minemap:default")
  for m in $modes; do systems+=("minemap:$m"); done
  systems+=("slam6d:metascan")
  [ "$slam_pairwise" = 1 ] && systems+=("slam6d:pairwise")
  for ((run = 1; run <= repeats; run++)); do
    for system in "${systems[@]}"; do
      kind="${system%%:*}"; mode="${system##*:}"
      if [ "$kind" = minemap ]; then
        args=(--threads "$threads")
        case "$mode" in
          default) ;;
          simultaneous|paper) args+=(--preset "$mode") ;;
          threads1) args=(--threads 1) ;;
          *) args+=(--mode "$mode") ;;
        esac
        rm -rf "$work/out"
        measured="$(timed "$build_dir/minemap" map "$survey" --out "$work/out" --quiet "${args[@]}")"
        errors="$(error_of "$survey" "$work/out")"
      else
        copy="$work/slam-$name"; rm -rf "$copy"; cp -r "$survey" "$copy"
        args=(-s 0 -e $((scans - 1)) -f uos -r 10 -O 1 -d 25 -a 1 -t 0 -i 50 -q)
        [ "$mode" = metascan ] && args+=(--metascan)
        measured="$(cd "$work" && timed "$slam6d" "${args[@]}" "$copy")"
        errors="$(error_of "$copy" "$copy")"
      fi
      printf '%s\t%s\t%s\t%s\t%s\n' "$name" "$system" "$run" "$(echo "$measured" | tr ' ' '\t')" \
        "$(echo "$errors" | tr ' ' '\t')" >> "$results"
      echo "$name $system run $run: $measured (s MB), error $errors (cm cm %)"
    done
  done
done

python=python3; [ -x /usr/bin/python3 ] && python=/usr/bin/python3
"$python" - "$results" "$out" "$threads" <<'PY'
import collections, json, statistics, sys
rows = [l.rstrip("\n").split("\t") for l in open(sys.argv[1])][1:]
groups = collections.OrderedDict()
for survey, system, run, *values in rows:
    groups.setdefault((survey, system), []).append([float(v) for v in values])
table, out = [], []
keys = ("wall_s", "peak_rss_mb", "mean_error_cm", "max_error_cm", "percent_of_path", "step_error_cm", "step_error_deg")
for (survey, system), runs in groups.items():
    record = {"survey": survey, "system": system, "runs": len(runs)}
    record.update({k: statistics.median(r[i] for r in runs) for i, k in enumerate(keys)})
    out.append(record)
lines = ["| survey | system | wall time (median) | peak RSS | mean error | max error | % of path | mean step error |",
         "|---|---|---|---|---|---|---|---|"]
for o in out:
    lines.append(f"| {o['survey']} | {o['system']} | {o['wall_s']:.2f} s | {o['peak_rss_mb']:.0f} MB | "
                 f"{o['mean_error_cm']:.1f} cm | {o['max_error_cm']:.1f} cm | {o['percent_of_path']:.3f} % | "
                 f"{o['step_error_cm']:.2f} cm, {o['step_error_deg']:.3f}° |")
# Ratios measured side by side, per survey: (faster, slower, what it says).
pairs = (("minemap:default", "slam6d:metascan", "slam6D --metascan"),
         ("minemap:pairwise", "slam6d:pairwise", "slam6D pairwise"),
         ("minemap:default", "minemap:threads1", "minemap on 1 thread"))
lines.append("")
for survey in dict.fromkeys(o["survey"] for o in out):
    by = {o["system"]: o for o in out if o["survey"] == survey}
    for mine, other, label in pairs:
        if mine in by and other in by:
            ratio = by[other]["wall_s"] / by[mine]["wall_s"]
            lines.append(f"* {survey}: {mine} is {ratio:.2f}x {label}'s speed; mean error "
                         f"{by[mine]['mean_error_cm']:.1f} cm vs {by[other]['mean_error_cm']:.1f} cm")
open(f"{sys.argv[2]}/slam6d.md", "w").write("\n".join(lines) + "\n")
json.dump(out, open(f"{sys.argv[2]}/slam6d.json", "w"), indent=1)
print("\n".join(lines))
PY
