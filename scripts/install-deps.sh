#!/usr/bin/env bash
# Installs the Debian 12 packages minemap needs, only those missing (apt-get update runs only then).
# Usage: scripts/install-deps.sh [build|test|bench]   (each level includes the ones before)
set -euo pipefail
level="${1:-build}"
packages=(build-essential cmake pkg-config libeigen3-dev libtbb-dev ocl-icd-opencl-dev opencl-c-headers
          opencl-clhpp-headers pocl-opencl-icd clinfo libcli11-dev nlohmann-json3-dev liblzf-dev libpng-dev
          libgtest-dev libbenchmark-dev)
case "$level" in
  build) ;;
  test) packages+=(clang libclang-rt-14-dev locales) ;;
  bench) packages+=(clang libclang-rt-14-dev libnanoflann-dev python3 python3-matplotlib libopen3d-dev libpcl-dev libopenmpi-dev) ;;
  *) echo "usage: $0 [build|test|bench]" >&2; exit 2 ;;
esac
missing=()
for p in "${packages[@]}"; do
  dpkg-query -W -f='${Status}' "$p" 2>/dev/null | grep -q "install ok installed" || missing+=("$p")
done
if [ ${#missing[@]} -gt 0 ]; then
  echo "installing: ${missing[*]}"
  sudo_cmd=""; [ "$(id -u)" -ne 0 ] && sudo_cmd="sudo"
  $sudo_cmd apt-get update -qq
  DEBIAN_FRONTEND=noninteractive $sudo_cmd apt-get install -y -qq --no-install-recommends "${missing[@]}"
fi
# The uos reader test proves parsing ignores the process locale; it needs one with a decimal comma.
if [ "$level" != build ] && ! locale -a 2>/dev/null | grep -qi '^de_DE.utf8$'; then
  sudo_cmd=""; [ "$(id -u)" -ne 0 ] && sudo_cmd="sudo"
  $sudo_cmd sed -i 's/^# *de_DE.UTF-8 UTF-8/de_DE.UTF-8 UTF-8/' /etc/locale.gen
  grep -q '^de_DE.UTF-8 UTF-8' /etc/locale.gen || echo 'de_DE.UTF-8 UTF-8' | $sudo_cmd tee -a /etc/locale.gen >/dev/null
  $sudo_cmd locale-gen >/dev/null
fi
