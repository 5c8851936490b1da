#!/usr/bin/env bash
# Configures (once) build-sanitize: clang with AddressSanitizer and UndefinedBehaviorSanitizer,
# and the fuzz targets. Optimised as the release build, with debug information for the
# reports, so that the whole suite runs in minutes; the benchmarks are not tests and are
# left out. Used by scripts/test-sanitizers.sh and scripts/fuzz.sh. LFTAG_WERROR=1: a
# warning fails the build.
set -euo pipefail
cd "$(dirname "$0")/.."
if [ ! -f build-sanitize/build.ninja ]; then
  CC=clang CXX=clang++ meson setup build-sanitize -Dbuildtype=debugoptimized -Db_ndebug=true \
    -Db_sanitize=address,undefined -Db_lundef=false -Dbench=disabled -Dfuzz=enabled ${LFTAG_WERROR:+-Dwerror=true}
fi
