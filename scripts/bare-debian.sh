#!/usr/bin/env bash
# Runs the README's commands, as written, in a bare Debian 12 root (debootstrap: the base system,
# nothing of minemap's installed) on a fresh clone of this repository's HEAD. It proves that what
# a new machine needs is what the scripts install: a package installed here by hand cannot help.
#
# usage: scripts/bare-debian.sh [--cache DIR] [--keep] [STEP...]
#   STEP   plain (scripts/install-deps.sh build, then a plain cmake -S . -B build && cmake --build
#          build, with only the build level installed), demo (scripts/demo.sh), test (scripts/test.sh),
#          bench (bench/run_benchmarks.sh --quick); default: plain demo test bench, in that order
#   --cache DIR  where the debootstrapped base is kept as a tarball (default /var/tmp/minemap-bare);
#          each run unpacks a fresh root from it
#   --keep       leave the root in place afterwards (it is printed), for a look inside
# environment: MIRROR (default: the first Debian URI of this machine's apt sources)
# Needs root and debootstrap (apt-get install debootstrap). Logs: <root>/work/logs/<step>.log,
# and a line per step with its exit code and minutes.
set -euo pipefail
repo_root="$(cd "$(dirname "${BASH_SOURCE[0]}")/.." && pwd)"
cache=/var/tmp/minemap-bare
keep=0
steps=()
while [ $# -gt 0 ]; do
  case "$1" in
    --cache) cache="$2"; shift ;;
    --keep) keep=1 ;;
    plain|demo|test|bench) steps+=("$1") ;;
    -h|--help) sed -n '2,/^set -euo/p' "$0" | sed '$d'; exit 0 ;;
    *) echo "usage: $0 [--cache DIR] [--keep] [plain|demo|test|bench ...]" >&2; exit 2 ;;
  esac
  shift
done
[ ${#steps[@]} -gt 0 ] || steps=(plain demo test bench)
[ "$(id -u)" -eq 0 ] || { echo "$0: needs root (debootstrap, chroot, mount)" >&2; exit 2; }
command -v debootstrap >/dev/null || { echo "$0: apt-get install debootstrap" >&2; exit 2; }

mirror="${MIRROR:-$(sed -n 's/^URIs: *\(http[^ ]*debian\)\/\{0,1\}$/\1/p' /etc/apt/sources.list.d/*.sources 2>/dev/null | head -n 1)}"
mirror="${mirror:-http://deb.debian.org/debian}"
mkdir -p "$cache"
if [ ! -f "$cache/bookworm-base.tar" ]; then
  echo "== debootstrap bookworm from $mirror (once; kept in $cache)"
  rm -rf "$cache/base"
  debootstrap bookworm "$cache/base" "$mirror" > "$cache/debootstrap.log" 2>&1 ||
    { tail -n 20 "$cache/debootstrap.log" >&2; exit 1; }
  tar -C "$cache/base" -cf "$cache/bookworm-base.tar.part" . && mv "$cache/bookworm-base.tar.part" "$cache/bookworm-base.tar"
  rm -rf "$cache/base"
fi

root="$(mktemp -d "$cache/root.XXXXXX")"
mounted=()
cleanup() {
  for ((i = ${#mounted[@]} - 1; i >= 0; i--)); do umount -l "${mounted[$i]}" 2>/dev/null || true; done
  if [ $keep = 1 ]; then echo "root kept: $root"; else rm -rf "$root"; fi
}
trap cleanup EXIT
tar -C "$root" -xf "$cache/bookworm-base.tar"
# The same apt sources and name resolution as this machine; nothing else of it.
cp /etc/apt/sources.list.d/*.sources "$root/etc/apt/sources.list.d/" 2>/dev/null || true
[ -f /etc/apt/sources.list ] && cp /etc/apt/sources.list "$root/etc/apt/sources.list"
cp -L /etc/resolv.conf "$root/etc/resolv.conf" 2>/dev/null || true
# The network's trust: certificate authorities this machine adds to Debian's (a proxy's, say), which
# pip needs to reach PyPI; apt's ca-certificates puts them in the bundle when install-deps installs it.
if compgen -G "/usr/local/share/ca-certificates/*.crt" > /dev/null; then
  mkdir -p "$root/usr/local/share/ca-certificates"
  cp /usr/local/share/ca-certificates/*.crt "$root/usr/local/share/ca-certificates/"
  [ -x "$root/usr/sbin/update-ca-certificates" ] && chroot "$root" /usr/sbin/update-ca-certificates > /dev/null 2>&1 || true
fi
for m in proc sys dev dev/pts; do
  mkdir -p "$root/$m"
  case "$m" in
    proc) mount -t proc proc "$root/proc" ;;
    sys) mount -t sysfs sysfs "$root/sys" ;;  # PoCL aborts without /sys
    *) mount --bind "/$m" "$root/$m" ;;
  esac
  mounted+=("$root/$m")
done
# A fresh clone of HEAD (what CI clones), with the shared data beside it, read-only, as in CI.
mkdir -p "$root/work/logs" "$root/work/shared"
git clone -q --no-hardlinks "$repo_root" "$root/work/minemap"
if [ -d "$repo_root/../shared" ]; then
  mount --bind "$repo_root/../shared" "$root/work/shared" && mount -o remount,bind,ro "$root/work/shared"
  mounted+=("$root/work/shared")
fi
echo "== bare Debian 12 root: $root; clone of $(git -C "$repo_root" rev-parse --short HEAD)"

failed=0
for step in "${steps[@]}"; do
  case "$step" in
    plain) command='scripts/install-deps.sh build && cmake -S . -B build && cmake --build build -j"$(nproc)"' ;;
    demo) command='scripts/demo.sh' ;;
    test) command='scripts/test.sh' ;;
    bench) command='bench/run_benchmarks.sh --quick' ;;
  esac
  start=$SECONDS
  status=0
  chroot "$root" /usr/bin/env -i HOME=/root TERM=dumb PATH=/usr/local/sbin:/usr/local/bin:/usr/sbin:/usr/bin:/sbin:/bin \
    LANG=C.UTF-8 CI=true /bin/bash -c "cd /work/minemap && $command" > "$root/work/logs/$step.log" 2>&1 < /dev/null || status=$?
  minutes="$(awk -v s=$((SECONDS - start)) 'BEGIN { printf "%.1f", s / 60 }')"
  echo "== $step: exit $status in $minutes min ($command)"
  if [ $status -ne 0 ]; then
    failed=1
    tail -n 40 "$root/work/logs/$step.log" | sed 's/^/   /'
    break
  fi
  tail -n 3 "$root/work/logs/$step.log" | sed 's/^/   /'
done
if [ $keep = 1 ] || [ $failed = 1 ]; then keep=1; fi
exit $failed
