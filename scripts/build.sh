#!/usr/bin/env bash
# Installs what is missing, then configures (once) and builds into ./build. With
# LFTAG_WERROR=1 (as CI sets it) a compiler warning fails the build.
set -euo pipefail
root=$(cd "$(dirname "$0")/.." && pwd)
"$root/scripts/install-deps.sh"
cd "$root"
if [ ! -f build/build.ninja ]; then
  meson setup build ${LFTAG_WERROR:+-Dwerror=true}
fi
ninja -C build
