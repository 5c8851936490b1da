#!/usr/bin/env bash
# The sanitizer builds, with clang:
#   build-sanitize  AddressSanitizer + UndefinedBehaviorSanitizer (and the fuzz targets):
#                   every test of the plain build except the valgrind suite `leaks`
#                   (valgrind cannot run ASan programs; see tests/gst/meson.build), plus
#                   every checked-in fuzz input once through its target (suite `fuzz`)
#   build-tsan      ThreadSanitizer: only the tests of the suite `threads` (several
#                   detectors at once, properties changed while frames flow)
# Each is configured once and built incrementally. Any sanitizer report fails its test
# (tests/meson.build sets the options). Extra arguments go to both `meson test` runs.
# Exit status: 0 all passed, 1 a test failed, 2 a build failed.
#   scripts/test-sanitizers.sh [--only address|thread] [meson test arguments]
set -uo pipefail
root=$(cd "$(dirname "$0")/.." && pwd)
cd "$root"
"$root/scripts/install-deps.sh" || exit 2
only=
if [ "${1:-}" = --only ]; then only=$2; shift 2; fi
export CC=clang CXX=clang++
status=0

if [ -z "$only" ] || [ "$only" = address ]; then
  "$root/scripts/setup-sanitize.sh" || exit 2
  rm -f build-sanitize/meson-logs/testlog.*
  ninja -C build-sanitize || exit 2
  meson test -C build-sanitize --print-errorlogs "$@" || status=1
fi

if [ -z "$only" ] || [ "$only" = thread ]; then
  if [ ! -f build-tsan/build.ninja ]; then
    meson setup build-tsan -Dbuildtype=debugoptimized -Db_ndebug=true -Db_sanitize=thread -Db_lundef=false \
      -Dbench=disabled ${LFTAG_WERROR:+-Dwerror=true} || exit 2
  fi
  rm -f build-tsan/meson-logs/testlog.*
  ninja -C build-tsan tests/lib/test_threads tests/gst/gst_threads gst/libgstlftag.so || exit 2
  meson test -C build-tsan --no-rebuild --suite threads --print-errorlogs "$@" || status=1
fi
exit $status
