#!/usr/bin/env bash
# Builds minemap and runs every test: the unit tests (OpenCL ones on PoCL, failing when no OpenCL
# platform is found), the fuzz corpora, the unit tests again under ASan+UBSan and under TSan
# (scripts/sanitize.sh), and a short libFuzzer run of every parser.
# Usage: scripts/test.sh   (SANITIZERS=0 skips the sanitizer runs, FUZZ_SECONDS=0 the libFuzzer run)
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
fuzz_build_dir=build-fuzz
if [ "${SANITIZERS:-1}" != "0" ]; then
  echo "--- unit tests under ASan+UBSan and TSan"
  scripts/sanitize.sh all
  # The fuzz targets need the same library build (clang, address+undefined, RelWithDebInfo): reuse it.
  fuzz_build_dir=build-asan
fi
if [ "${FUZZ_SECONDS:-10}" != "0" ]; then
  echo "--- libFuzzer, ${FUZZ_SECONDS:-10} s per parser"
  FUZZ_BUILD_DIR="$fuzz_build_dir" scripts/fuzz.sh
fi
