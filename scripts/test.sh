#!/usr/bin/env bash
# Builds minemap and runs every test: the unit tests (OpenCL ones on PoCL, failing when no OpenCL
# platform is found), the fuzz corpora, and a short libFuzzer run of every parser.
# Usage: scripts/test.sh   (FUZZ_SECONDS=0 skips the libFuzzer run)
set -euo pipefail
cd "$(dirname "$0")/.."
scripts/install-deps.sh test
echo "--- OpenCL platforms"
clinfo -l || true
jobs="$(nproc)"
cmake -S . -B build -DCMAKE_BUILD_TYPE=Release -DMINEMAP_BUILD_BENCH=ON
cmake --build build -j"$jobs"
echo "--- unit tests"
(cd build && ctest --output-on-failure -j"$jobs" --timeout 900)
if [ "${FUZZ_SECONDS:-10}" != "0" ]; then
  echo "--- libFuzzer, ${FUZZ_SECONDS:-10} s per parser"
  scripts/fuzz.sh
fi
