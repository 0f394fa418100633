#!/usr/bin/env bash
# Proves that a build used nothing that scripts/install-deps.sh does not install, so that a bare
# Debian 12 builds what this machine built (a package installed here by hand cannot hide a gap).
#
# After a build it gathers every file the build read from outside the checkout: the headers in the
# compilers' dependency files (*.o.d), the libraries on the link lines (link.txt) and the CMake
# package files it found (CMakeCache's *_DIR). It asks dpkg which package owns each, and fails
# for each file that belongs to no package of the level (nor to what those packages depend on,
# recursively, as installed here). The optional peers (install-deps.sh --optional) are allowed only
# in the targets built where CMake finds them (bench_search, bench_peers).
#
# usage: scripts/check-deps.sh BUILD_DIR [LEVEL]   (LEVEL: build, the default, or test/bench)
set -euo pipefail
repo_root="$(cd "$(dirname "${BASH_SOURCE[0]}")/.." && pwd)"
build_dir="$(cd "${1:?usage: check-deps.sh BUILD_DIR [LEVEL]}" && pwd)"
level="${2:-build}"
optional_targets='/CMakeFiles/(bench_search|bench_peers|minemap_bench_nanoflann)\.dir/'
work="$(mktemp -d)"
trap 'rm -rf "$work"' EXIT

# --- the packages allowed: the level's and the optional ones, each closed under Depends ---------
dpkg-query -W -f='${Package}\t${Status}\t${Provides}\t${Depends}, ${Pre-Depends}\n' > "$work/db" 2>/dev/null
closure() {  # closure FILE_WITH_PACKAGE_NAMES -> installed packages they need, recursively
  awk -F'\t' '
    function strip(d) { sub(/:any$/, "", d); sub(/:[a-z0-9]+$/, "", d); return d }
    FNR == NR { want[$1] = 1; next }
    $2 ~ /install ok installed/ {
      installed[$1] = 1; deps[$1] = $4
      n = split($3, pv, /, */)
      for (i = 1; i <= n; i++) { split(pv[i], w, " "); if (w[1] != "") provider[strip(w[1])] = provider[strip(w[1])] " " $1 }
    }
    END {
      for (p in want) queue[++tail] = p
      while (head < tail) {
        p = queue[++head]
        if (p in seen) continue
        seen[p] = 1
        names = ""
        if (p in installed) names = p
        if (p in provider) names = names provider[p]
        m = split(names, list, " ")
        for (j = 1; j <= m; j++) {
          q = list[j]; if (q in done) continue; done[q] = 1; print q
          k = split(deps[q], alts, /, */)
          for (i = 1; i <= k; i++) {
            a = split(alts[i], choice, / *\| */)
            for (c = 1; c <= a; c++) { split(choice[c], w, " "); d = strip(w[1]); if (d != "" && !(d in seen)) queue[++tail] = d }
          }
        }
      }
    }' "$1" "$work/db" | sort -u
}
"$repo_root/scripts/install-deps.sh" --list "$level" > "$work/level"
"$repo_root/scripts/install-deps.sh" --optional > "$work/optional"
closure "$work/level" > "$work/allowed"
closure "$work/optional" > "$work/allowed-optional"
for p in $(cat "$work/level"); do
  grep -qx "$p" "$work/allowed" || echo "check-deps: note: $p (install-deps.sh $level) is not installed here" >&2
done

# --- the files the build read from outside the checkout -----------------------------------------
# Each line: <file> <tab> <target folder>
{
  find "$build_dir" -name '*.o.d' -not -path '*/_deps/*' -print0 | while IFS= read -r -d '' depfile; do
    target="$(echo "$depfile" | sed 's|\(.*\.dir/\).*|\1|')"
    tr ' \\' '\n\n' < "$depfile" | { grep '^/' || true; } | sed "s|\$|	$target|"
  done
  find "$build_dir" -name link.txt -print0 | while IFS= read -r -d '' linkfile; do
    tr ' ' '\n' < "$linkfile" | { grep -E '^/.*\.(so(\.[0-9.]+)?|a)$' || true; } | sed "s|\$|	${linkfile%/link.txt}/|"
  done
  # A *_DIR that is not there (MINEMAP_SHARED_DATA_DIR where the checkout has no ../shared) holds no
  # package file: skipped, not an error under pipefail.
  sed -n 's/^[A-Za-z0-9_]*_DIR:PATH=\(\/.*\)$/\1/p' "$build_dir/CMakeCache.txt" | while read -r dir; do
    [ -d "$dir" ] || continue
    find "$dir" -maxdepth 1 \( -name '*Config.cmake' -o -name '*-config.cmake' \) 2>/dev/null | sed "s|\$|	cmake-package/|"
  done
} | { grep -v -e "^$repo_root/" -e "^$build_dir/" || true; } | sort -u > "$work/used"
if [ ! -s "$work/used" ]; then
  echo "check-deps: no dependency files under $build_dir: build it first" >&2; exit 2
fi

# --- which package owns each file: one dpkg call (a file it does not know: '-') --------------------
cut -f1 "$work/used" | sort -u > "$work/files"
{ xargs -d '\n' dpkg -S < "$work/files" 2>/dev/null || true; } |
  awk '{ i = index($0, ": /"); if (i) print substr($0, i + 2) "\t" substr($0, 1, i - 1) }' > "$work/owned"
# Files known only under their resolved path (a symlink the package does not list).
awk -F'\t' 'NR == FNR { owned[$1] = 1; next } !($1 in owned)' "$work/owned" "$work/files" | while read -r f; do
  real="$(readlink -f "$f" 2>/dev/null || true)"
  owner="$([ -n "$real" ] && dpkg -S "$real" 2>/dev/null | head -n 1 | sed 's/: .*//' || true)"
  printf '%s\t%s\n' "$f" "${owner:--}"
done >> "$work/owned"

awk -F'\t' -v level="$level" -v optional_targets="$optional_targets" '
  FILENAME == ARGV[1] { allowed[$1] = 1; next }
  FILENAME == ARGV[2] { optional[$1] = 1; next }
  FILENAME == ARGV[3] { owners[$1] = $2; next }
  {  # used: file, target folder
    users[$1] = users[$1] " " $2
    if ($2 !~ optional_targets) required[$1] = 1
  }
  END {
    for (f in users) {
      total++
      n = split(owners[f], list, /, */); ok = 0
      for (i = 1; i <= n; i++) {
        p = list[i]; sub(/:.*/, "", p)
        if (p in allowed || (p in optional && !(f in required))) { ok = 1; break }
      }
      if (ok) continue
      failures++
      who = users[f]; gsub(/[^ ]*\/CMakeFiles\//, "", who); gsub(/\.dir\//, "", who); gsub(/\/ /, " ", who)
      printf "check-deps: %s (package: %s) is used by%s but \047scripts/install-deps.sh %s\047 does not install it\n", f, (owners[f] == "" ? "none" : owners[f]), who, level > "/dev/stderr"
    }
    if (failures) {
      printf "check-deps: FAILED: %d of %d files come from packages outside install-deps.sh %s\n", failures, total, level > "/dev/stderr"
      exit 1
    }
    printf "check-deps: %d files from outside the checkout, each from a package that \047install-deps.sh %s\047 installs\n", total, level
  }' "$work/allowed" "$work/allowed-optional" "$work/owned" "$work/used"
