#!/usr/bin/env bash
# The README's test command: installs what is missing, builds, runs every test and ends
# with one line "N passed, N failed". Extra arguments go to `meson test`.
set -uo pipefail
root=$(cd "$(dirname "$0")/.." && pwd)
"$root/scripts/build.sh" || { echo "0 passed, 1 failed"; exit 1; }
cd "$root"
meson test -C build --print-errorlogs "$@"
python3 "$root/scripts/summarize-tests.py" build/meson-logs
