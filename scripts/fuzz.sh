#!/usr/bin/env bash
# Fuzzes minemap's file readers with libFuzzer.
#
# Builds the tests/fuzz/fuzz_*.cpp targets with clang, AddressSanitizer and UndefinedBehaviorSanitizer
# (only those targets and the library they need), then runs each for FUZZ_SECONDS seconds (default 5)
# on a scratch copy of its seed corpus tests/fuzz/corpus/<name>, so the repository is never written
# to. Fails when any target crashes, leaks, trips a sanitizer, times out or runs out of memory; the
# input that did it is kept under $FUZZ_BUILD_DIR/artifacts/<name>/ and named in the output.
#
# usage: scripts/fuzz.sh [--merge] [name ...]
#   name     targets to run, without the fuzz_ prefix (uos pose frames pcd ply kitti_bin tum
#            trajectory); default: all of tests/fuzz/fuzz_*.cpp
#   --merge  afterwards, merge inputs that reach new code into tests/fuzz/corpus/<name>
#            (libFuzzer -merge=1, which adds only what increases coverage)
# environment: FUZZ_SECONDS (5), FUZZ_BUILD_DIR (build-fuzz), FUZZ_CXX (clang++), FUZZ_JOBS (nproc),
#              TMPDIR (default /dev/shm when writable)
set -euo pipefail

repo_root="$(cd "$(dirname "${BASH_SOURCE[0]}")/.." && pwd)"
cd "$repo_root"

seconds="${FUZZ_SECONDS:-5}"
build_dir="${FUZZ_BUILD_DIR:-build-fuzz}"
cxx="${FUZZ_CXX:-clang++}"
jobs="${FUZZ_JOBS:-$(nproc)}"
merge=0
names=()
for arg in "$@"; do
  case "$arg" in
    --merge) merge=1 ;;
    -h|--help) sed -n '2,/^set -euo/p' "$0" | sed '$d'; exit 0 ;;
    -*) echo "fuzz.sh: unknown option $arg" >&2; exit 2 ;;
    *) names+=("${arg#fuzz_}") ;;
  esac
done
if [ ${#names[@]} -eq 0 ]; then
  for source in tests/fuzz/fuzz_*.cpp; do
    name="$(basename "$source" .cpp)"
    names+=("${name#fuzz_}")
  done
fi
for name in "${names[@]}"; do
  if [ ! -f "tests/fuzz/fuzz_${name}.cpp" ]; then echo "fuzz.sh: no target tests/fuzz/fuzz_${name}.cpp" >&2; exit 2; fi
  if [ ! -d "tests/fuzz/corpus/${name}" ]; then echo "fuzz.sh: no seed corpus tests/fuzz/corpus/${name}" >&2; exit 2; fi
done

echo "== building ${#names[@]} fuzz targets in $build_dir ($cxx, address+undefined)"
# RelWithDebInfo: optimised like the real readers, with line numbers in sanitizer reports.
mkdir -p "$build_dir"
cmake -S . -B "$build_dir" -DCMAKE_CXX_COMPILER="$cxx" -DCMAKE_BUILD_TYPE=RelWithDebInfo \
  -DMINEMAP_BUILD_FUZZ=ON -DMINEMAP_SANITIZE=address,undefined -DMINEMAP_BUILD_BENCH=OFF > "$build_dir/configure.log" 2>&1 ||
  { cat "$build_dir/configure.log" >&2; exit 1; }
targets=()
for name in "${names[@]}"; do targets+=(--target "fuzz_${name}"); done
cmake --build "$build_dir" -j "$jobs" "${targets[@]}"

# UBSan only reports by default; halt_on_error turns each report into a crash libFuzzer keeps.
export UBSAN_OPTIONS="halt_on_error=1:print_stacktrace=1:${UBSAN_OPTIONS:-}"
export ASAN_OPTIONS="detect_leaks=1:${ASAN_OPTIONS:-}"

# The targets write every input to a temp file and the round-trip checks write (and fsync) more:
# on tmpfs that costs nothing, on a disk it cuts the speed tenfold.
if [ -z "${TMPDIR:-}" ] && [ -d /dev/shm ] && [ -w /dev/shm ]; then export TMPDIR=/dev/shm; fi
work_dir="$(mktemp -d "${TMPDIR:-/tmp}/minemap-fuzz.XXXXXX")"
trap 'rm -rf "$work_dir"' EXIT
failed=()
for name in "${names[@]}"; do
  binary="$(find "$build_dir" -type f -name "fuzz_${name}" -perm -u+x | head -n 1)"
  if [ -z "$binary" ]; then echo "fuzz.sh: fuzz_${name} was not built" >&2; exit 1; fi
  corpus="$work_dir/$name/corpus"
  artifacts="$repo_root/$build_dir/artifacts/$name"
  mkdir -p "$corpus" "$artifacts"
  cp -R "tests/fuzz/corpus/$name/." "$corpus/"
  log="$work_dir/$name/log"
  echo "== fuzz_${name}: ${seconds} s on a copy of tests/fuzz/corpus/${name} ($(ls "$corpus" | wc -l) seeds)"
  if "$binary" "$corpus" -max_total_time="$seconds" -timeout=10 -rss_limit_mb=2048 \
       -artifact_prefix="$artifacts/" -print_final_stats=1 > "$log" 2>&1; then
    grep -E "^stat::number_of_executed_units|^Done [0-9]+ runs" "$log" | sed 's/^/   /' || true
  else
    echo "!! fuzz_${name} FAILED; the last lines of its log:" >&2
    tail -n 40 "$log" >&2
    echo "!! inputs kept in $artifacts/ (replay: $binary <file>)" >&2
    failed+=("$name")
    continue
  fi
  if [ "$merge" -eq 1 ]; then
    "$binary" -merge=1 "tests/fuzz/corpus/$name" "$corpus" > "$work_dir/$name/merge.log" 2>&1 ||
      { tail -n 20 "$work_dir/$name/merge.log" >&2; failed+=("$name (merge)"); continue; }
    echo "   merged into tests/fuzz/corpus/$name: $(ls "tests/fuzz/corpus/$name" | wc -l) files"
  fi
done

if [ ${#failed[@]} -gt 0 ]; then
  echo "fuzz.sh: FAILED: ${failed[*]}" >&2
  exit 1
fi
echo "fuzz.sh: all ${#names[@]} targets ran ${seconds} s without a crash"
