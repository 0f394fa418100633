#!/usr/bin/env bash
# Shows what the two quick timing studies resolve on this machine:
#   1. builds a copy of HEAD with a deliberate regression in the CPU backend, in a git worktree
#      under /tmp (the repo is not touched): every 6th query is searched a second time without its
#      hint (about 17 % more search work);
#   2. bench/count_instructions.py, HEAD against the regressed copy: every row must be SLOWER
#      (over 3 % more instructions); HEAD against itself: every count must be the same;
#   3. bench/ab_compare.py (wall time, interleaved), HEAD against the regressed copy: the rows that
#      search must be SLOWER, while the two controls it cannot touch (nanoflann, the slice filter)
#      must not; HEAD against itself: no row may be SLOWER.
# usage: bench/regression_drill.sh [BUILD]   (default build/, holding HEAD's bench binaries)
# Output: out/bench-drill/. About 12 min on 2 cores, a third of it the build.
set -euo pipefail
cd "$(dirname "$0")/.."
build="$(cd "${1:-build}" && pwd)"
drill=/tmp/minemap-regression-drill
out=out/bench-drill
git worktree remove --force "$drill" 2>/dev/null || rm -rf "$drill"
git worktree add --detach "$drill" HEAD >/dev/null
trap 'git worktree remove --force "$drill" 2>/dev/null || true' EXIT
target=src/minemap/search/pairing_cpu.cpp
line='          const NearestPair pair = find_nearest(points[i], placed, method, max_squared, hints.data());'
grep -qF "$line" "$drill/$target" || { echo "regression_drill.sh: $target changed; update the drill" >&2; exit 2; }
slower='          if (i % 6 == 0) { std::vector<std::int32_t> spare(placed.size(), -1); volatile float sink = find_nearest(points[i], placed, method, max_squared, spare.data()).squared_distance_cm2; (void)sink; }'
python3 - "$drill/$target" "$line" "$slower" <<'PY'
import pathlib, sys
path, line, slower = pathlib.Path(sys.argv[1]), sys.argv[2], sys.argv[3]
path.write_text(path.read_text().replace(line + "\n", slower + "\n" + line + "\n", 1))
PY
grep -qF "$slower" "$drill/$target" || { echo "regression_drill.sh: the regression was not applied" >&2; exit 2; }
cmake -S "$drill" -B "$drill/build" -DCMAKE_BUILD_TYPE=Release -DMINEMAP_BUILD_BENCH=ON \
  -DMINEMAP_BUILD_TESTS=OFF -DMINEMAP_BUILD_FUZZ=OFF >/dev/null
cmake --build "$drill/build" -j"$(nproc)" --target bench_table1 bench_search >/dev/null
status=0
fail() { echo "regression_drill.sh: $*" >&2; status=1; }
echo "== instructions: HEAD against HEAD with every 6th query searched twice"
bench/count_instructions.py "$build" "$drill/build" --out "$out/instructions-regressed" &&
  fail "instructions: the regression was NOT detected"
echo "== instructions: HEAD against itself"
bench/count_instructions.py "$build" "$build" --out "$out/instructions-same" || fail "instructions: false alarm"
echo "== wall time (interleaved A/B): HEAD against the regressed copy"
bench/ab_compare.py "$build" "$drill/build" --out "$out/time-regressed" && fail "time: the regression was NOT detected"
python3 - "$out/time-regressed/ab.json" <<'PY' || fail "time: a control row moved, or a searching row did not"
import json, sys
rows = json.load(open(sys.argv[1]))
controls = [r for r in rows if "nanoflann" in r["row"] or "SliceFilter" in r["row"]]
searching = [r for r in rows if r not in controls]
sys.exit(0 if all(r["verdict"] != "SLOWER" for r in controls) and all(r["verdict"] == "SLOWER" for r in searching) else 1)
PY
echo "== wall time (interleaved A/B): HEAD against itself"
bench/ab_compare.py "$build" "$build" --out "$out/time-same" || fail "time: false alarm"
exit $status
