#!/usr/bin/env bash
# Installs the build tree into a temp prefix, then configures, builds and runs tests/install (the
# README's library example) as an outside project with find_package(minemap), on a 3-scan simulated
# survey. Usage: run_install_test.sh BUILD_DIR
set -euo pipefail
build_dir="$1"
here="$(cd "$(dirname "$0")" && pwd)"
work="$(mktemp -d)"
trap 'rm -rf "$work"' EXIT
cmake --install "$build_dir" --prefix "$work/prefix" >/dev/null
# The exported target must not point at this build tree or name a library by this machine's path.
if grep -nE "$build_dir|/usr/lib/[^ ]*liblzf|-march=native" "$work"/prefix/lib*/cmake/minemap/minemapTargets*.cmake; then
  echo "minemapTargets.cmake is not portable (above)" >&2; exit 1
fi
cmake -S "$here" -B "$work/consumer" -DCMAKE_PREFIX_PATH="$work/prefix" >/dev/null
cmake --build "$work/consumer" >/dev/null
# The build tree's program makes the survey: the installed one has no RPATH, and in a sanitizer
# build it would load the system's TBB instead of the instrumented one the build linked.
"$build_dir/minemap" simulate --out "$work/survey" --scans 3 >/dev/null
test -x "$work/prefix/bin/minemap"
"$work/consumer/consumer" "$work/survey" | tee "$work/out.txt"
grep -q "^pair: converged" "$work/out.txt"
echo "find_package(minemap) consumer built and ran"
