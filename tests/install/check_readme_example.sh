#!/usr/bin/env bash
# The README's library example is tests/install/main.cpp, character for character, so the code a
# user copies is the code the install test compiles and runs. Usage: check_readme_example.sh REPO
set -euo pipefail
repo="$1"
shown="$(awk '/<!-- library example: tests\/install\/main.cpp -->/ { marked = 1; next }
              marked && /^```cpp$/ { inside = 1; next }
              inside && /^```$/ { exit }
              inside { print }' "$repo/README.md")"
if [ -z "$shown" ]; then echo "README.md has no library example block" >&2; exit 1; fi
diff <(echo "$shown") "$repo/tests/install/main.cpp" || {
  echo "README.md's library example differs from tests/install/main.cpp (above)" >&2; exit 1; }
echo "README's library example is tests/install/main.cpp"
