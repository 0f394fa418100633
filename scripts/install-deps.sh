#!/usr/bin/env bash
# Installs the Debian 12 packages minemap needs, only those missing (apt-get update runs only then).
# This file is the one list of them: scripts/check-deps.sh proves that a build uses no package
# outside it, and scripts/bare-debian.sh runs the README's commands on a bare Debian 12 root.
#
# Usage: scripts/install-deps.sh [build|test|bench]   (each level includes the ones before)
#        scripts/install-deps.sh --list LEVEL         prints the level's packages, installs nothing
#        scripts/install-deps.sh --optional           prints the optional peers (bench level only)
#   build  library, CLI, unit tests and the benchmarks that need nothing optional: what a plain
#          `cmake -S . -B build && cmake --build build` builds (scripts/demo.sh); and what `pip install .`
#          needs to build the Python package (python3-dev, python3-venv; ca-certificates for PyPI).
#          libjs-three: three.js, which the build inlines into map.html
#   test   + clang with its sanitizer runtimes and llvm-symbolizer, a de_DE locale, chromium (headless:
#          the test that renders map.html) (scripts/test.sh)
#   bench  + the peers the benchmarks compare with, and the tools of the timing studies
set -euo pipefail

build_packages=(build-essential cmake pkg-config libeigen3-dev libtbb-dev ocl-icd-opencl-dev opencl-c-headers
                opencl-clhpp-headers pocl-opencl-icd clinfo libcli11-dev nlohmann-json3-dev liblzf-dev libpng-dev
                libgtest-dev libbenchmark-dev libjs-three
                python3-dev python3-venv ca-certificates)
# llvm: llvm-symbolizer, which the sanitizer runtimes call; dpkg-dev: dpkg-source, which unpacks
# oneTBB's source for the TSan build (scripts/sanitize.sh); chromium: tests/viewer/check_map_html.py.
test_packages=(clang libclang-rt-14-dev llvm dpkg-dev locales chromium)
# Optional peers: CMake builds what uses them only where it finds them (bench/CMakeLists.txt).
optional_packages=(libnanoflann-dev libopen3d-dev libpcl-dev libopenmpi-dev)
bench_tools=(python3 python3-matplotlib valgrind time)

packages_of() {
  case "$1" in
    build) echo "${build_packages[@]}" ;;
    test) echo "${build_packages[@]} ${test_packages[@]}" ;;
    bench) echo "${build_packages[@]} ${test_packages[@]} ${optional_packages[@]} ${bench_tools[@]}" ;;
    *) echo "usage: $0 [build|test|bench] | --list LEVEL | --optional" >&2; return 2 ;;
  esac
}

case "${1:-build}" in
  --list) packages_of "${2:-build}" | tr ' ' '\n'; exit 0 ;;
  --optional) printf '%s\n' "${optional_packages[@]}"; exit 0 ;;
esac
level="${1:-build}"
read -r -a packages <<< "$(packages_of "$level")"

sudo_cmd=""; [ "$(id -u)" -ne 0 ] && sudo_cmd="sudo"
missing=()
for p in "${packages[@]}"; do
  dpkg-query -W -f='${Status}' "$p" 2>/dev/null | grep -q "install ok installed" || missing+=("$p")
done
if [ ${#missing[@]} -gt 0 ]; then
  echo "installing: ${missing[*]}"
  $sudo_cmd apt-get update -qq
  DEBIAN_FRONTEND=noninteractive $sudo_cmd apt-get install -y -qq --no-install-recommends "${missing[@]}"
fi
# The uos reader test proves parsing ignores the process locale; it needs one with a decimal comma.
if [ "$level" != build ] && ! locale -a 2>/dev/null | grep -qi '^de_DE.utf8$'; then
  $sudo_cmd sed -i 's/^# *de_DE.UTF-8 UTF-8/de_DE.UTF-8 UTF-8/' /etc/locale.gen
  grep -q '^de_DE.UTF-8 UTF-8' /etc/locale.gen || echo 'de_DE.UTF-8 UTF-8' | $sudo_cmd tee -a /etc/locale.gen >/dev/null
  $sudo_cmd locale-gen >/dev/null
fi
