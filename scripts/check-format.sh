#!/usr/bin/env bash
# The one code style of the C and C++ sources (src/, gst/, tests/, bench/, fuzz/,
# examples/), written down in .clang-format at the top of the tree, checked with
# clang-format 14 (Debian's clang-format package):
#
#   scripts/check-format.sh          names the files clang-format would change; exit 1 if any
#   scripts/check-format.sh --fix    reformats them in place
#
# Exit 77 (meson's "skipped") when clang-format 14 is not installed: another version
# formats some constructs differently, so its verdict would not be this style's.
set -uo pipefail
root=$(cd "$(dirname "$0")/.." && pwd)
fix=0
[ "${1:-}" = --fix ] && fix=1

format=""
for candidate in "${CLANG_FORMAT:-}" clang-format-14 clang-format; do
  [ -n "$candidate" ] && command -v "$candidate" >/dev/null || continue
  if "$candidate" --version | grep -q 'version 14\.'; then
    format=$candidate
    break
  fi
done
if [ -z "$format" ]; then
  echo "SKIP: clang-format 14 is not installed (Debian: apt-get install clang-format), so the" \
       "style of the sources is not checked"
  exit 77
fi

cd "$root" || exit 1
mapfile -t files < <(find src gst tests bench fuzz examples -type f \
  \( -name '*.cpp' -o -name '*.hpp' -o -name '*.h' -o -name '*.c' \) | sort)
if [ $fix -eq 1 ]; then
  exec "$format" -i --style=file "${files[@]}"
fi
bad=()
for f in "${files[@]}"; do
  "$format" --dry-run -Werror --style=file "$f" >/dev/null 2>&1 || bad+=("$f")
done
if [ ${#bad[@]} -ne 0 ]; then
  echo "Not in the style of .clang-format (${#bad[@]} of ${#files[@]} files):"
  for f in "${bad[@]}"; do
    echo "  $f"
    "$format" --style=file "$f" | diff -u "$f" - | head -n 20 | sed 's/^/    /'
  done
  echo "Fix with: scripts/check-format.sh --fix"
  exit 1
fi
echo "${#files[@]} source files in the style of .clang-format ($("$format" --version))"
