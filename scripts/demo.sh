#!/usr/bin/env bash
# The main job on the built-in simulated mine survey: build, simulate the paper's 250 m drive with a
# tilting 2D scanner, map it with minemap's default (each scan matched against the metascan of the
# scans before it), and print the pose error against ground truth before (odometry) and after
# registration. Outputs land in out/demo/.
# Usage: scripts/demo.sh [extra `minemap map` options, e.g. --backend opencl]
set -euo pipefail
cd "$(dirname "$0")/.."
scripts/install-deps.sh build
# Same build folder and options as the test command; only the program is built here.
cmake -S . -B build -DCMAKE_BUILD_TYPE=Release >/dev/null
cmake --build build -j"$(nproc)" --target minemap_cli
mkdir -p out
build/minemap simulate --out out/demo-survey
echo "--- pairwise matching (for comparison)"
# Its pose error line only; the full printout follows for the default.
pairwise_status=0
build/minemap map out/demo-survey --out out/demo-pairwise --mode pairwise > out/demo-pairwise.log 2>&1 || pairwise_status=$?
grep -E '^  (odometry|registered) ' out/demo-pairwise.log || { cat out/demo-pairwise.log; exit "$pairwise_status"; }
echo "--- minemap's default: incremental matching against the metascan"
build/minemap map out/demo-survey --out out/demo "$@"
