#!/usr/bin/env bash
# The README's test command: installs what is missing, builds, runs every test and ends
# with one line "N passed, N failed". Without arguments that is every test of the plain
# build (./build), then of the sanitizer builds (scripts/test-sanitizers.sh: ASan+UBSan,
# ThreadSanitizer) and a short run of the fuzz targets (scripts/fuzz.sh, FUZZ_SECONDS
# each, default 20), all counted in that line. Extra arguments go to the plain build's
# `meson test` only, and then only the plain build runs; LFTAG_SANITIZERS=0 skips the
# sanitizer builds and the fuzzing.
set -uo pipefail
root=$(cd "$(dirname "$0")/.." && pwd)
"$root/scripts/build.sh" || { echo "0 passed, 1 failed"; exit 1; }
cd "$root"
meson test -C build --print-errorlogs "$@"
logs=(build/meson-logs)
failed=0
if [ $# -eq 0 ] && [ "${LFTAG_SANITIZERS:-1}" != 0 ]; then
  # No log of an earlier run may count: a build that fails now leaves none.
  rm -f build-sanitize/meson-logs/testlog.* build-tsan/meson-logs/testlog.* build-sanitize/fuzz-logs/testlog.*
  scripts/test-sanitizers.sh
  [ $? -eq 2 ] && failed=$((failed + 1))  # a build failed: no log counts it
  logs+=(build-sanitize/meson-logs build-tsan/meson-logs)
  scripts/fuzz.sh "${FUZZ_SECONDS:-20}" frames scenes ids families calibration image_header json element
  [ $? -eq 2 ] && failed=$((failed + 1))
  logs+=(build-sanitize/fuzz-logs)
fi
python3 "$root/scripts/summarize-tests.py" --failed "$failed" "${logs[@]}"
