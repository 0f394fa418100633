#!/usr/bin/env bash
# Installs the build tree into a temp prefix, then configures, builds and runs tests/install as an
# outside project with find_package(minemap). Usage: run_install_test.sh BUILD_DIR
set -euo pipefail
build_dir="$1"
here="$(cd "$(dirname "$0")" && pwd)"
work="$(mktemp -d)"
trap 'rm -rf "$work"' EXIT
cmake --install "$build_dir" --prefix "$work/prefix" >/dev/null
cmake -S "$here" -B "$work/consumer" -DCMAKE_PREFIX_PATH="$work/prefix" >/dev/null
cmake --build "$work/consumer" >/dev/null
"$work/consumer/consumer" | grep -q "pose ok 1"
echo "find_package(minemap) consumer built and ran"
