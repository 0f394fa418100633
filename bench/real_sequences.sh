#!/bin/bash
# Real moving-LiDAR sequences with reference poses, side by side (minemap and KISS-ICP through
# bench/moving_lidar.py). The scans are not in this repository: they are in two public GitHub
# repositories, in their git trees (no LFS), which this script reads from clones or bare mirrors.
#
# usage: bench/real_sequences.sh FASTLIO_REPO BALM_REPO [WORKDIR] [-- moving_lidar.py options...]
#   FASTLIO_REPO  a clone (or bare mirror) of github.com/daxuanzi515/Fast-LIO2_SC-SLAM: Livox Avia
#                 keyframes (x y z intensity PCD, ~5 000 points, the sensor frame, already deskewed
#                 by FAST-LIO2) with SC-PGO's optimized_poses.txt (KITTI 3x4, T_world_sensor) as the
#                 reference: output/HKU_MB_2020-09-20-13-34-51_bag (457 keyframes, a 95 m walk
#                 through a building), output/HKU_1_bag (314, a 63.5 m loop), output/HKU_2_bag (266,
#                 a 58.5 m loop)
#   BALM_REPO     a clone (or bare mirror) of github.com/hku-mars/BALM: datas/benchmark_realworld,
#                 177 360-degree sweeps (~75 000 points, a 64-ring sensor) with alidarPose.csv (4x4,
#                 T_world_sensor, the LIO poses BALM's benchmark starts from) as the reference
#   WORKDIR       where the scans are unpacked and the outputs go (default bench/out/real)
# The references are SLAM outputs (loop-closed or LIO), not survey truth: figures of a few
# centimetres are within their own error.
set -euo pipefail
HERE=$(cd "$(dirname "$0")" && pwd)
[ $# -ge 2 ] || { sed -n 2,20p "$0"; exit 2; }
FASTLIO=$1; BALM=$2; shift 2
WORK=$HERE/out/real
if [ $# -gt 0 ] && [ "$1" != "--" ]; then WORK=$1; shift; fi
[ "${1:-}" = "--" ] && shift
gitdir() { if [ -d "$1/.git" ]; then echo "$1/.git"; else echo "$1"; fi; }
unpack() {  # REPO DEST PATH...: those paths of HEAD, into DEST (once), each by its last name
  local repo=$1 dest=$2; shift 2
  [ -e "$dest/.unpacked" ] && return 0
  rm -rf "$dest" "$dest.tmp"; mkdir -p "$dest" "$dest.tmp"
  # Paths one by one: a mirror may lack the big blobs beside them (maps, PDFs) that no sequence needs.
  local path
  for path in "$@"; do
    git --git-dir="$(gitdir "$repo")" archive HEAD "$path" | tar -x -C "$dest.tmp"
    mv "$dest.tmp/$path" "$dest/"
  done
  rm -rf "$dest.tmp"
  touch "$dest/.unpacked"
}
mkdir -p "$WORK"
sequences=()
for bag in HKU_MB_2020-09-20-13-34-51_bag:hku-building-walk HKU_1_bag:hku-loop-1 HKU_2_bag:hku-loop-2; do
  name=${bag##*:}; from=output/${bag%%:*}
  unpack "$FASTLIO" "$WORK/$name" "$from/Scans" "$from/optimized_poses.txt"
  sequences+=(--sequence "$name=$WORK/$name/Scans,$WORK/$name/optimized_poses.txt")
done
balm=$WORK/balm-realworld
if [ ! -e "$balm/.unpacked" ]; then
  unpack "$BALM" "$balm" datas/benchmark_realworld
  rm "$balm/.unpacked"
  mkdir -p "$balm/scans"
  find "$balm/benchmark_realworld" -maxdepth 1 -name 'full*.pcd' -exec mv -t "$balm/scans" {} +
  mv "$balm/benchmark_realworld/alidarPose.csv" "$balm/"
  rm -rf "$balm/benchmark_realworld"
  touch "$balm/.unpacked"
fi
sequences+=(--sequence "balm-realworld=$balm/scans,$balm/alidarPose.csv")
exec "$HERE/moving_lidar.py" --sequences '' "${sequences[@]}" --workdir "$WORK" --out "$WORK/real.json" "$@"
