#!/usr/bin/env bash
# The benchmark command: installs what is missing, configures (once) and builds the
# benchmark program, runs the experiments and draws the plots.
#
#   scripts/bench.sh [--quick] [lftag-bench options] [EXPERIMENT...]
#
# Results (CSV, meta.json, PNG) go to bench/results/quick or bench/results/full, or to
# $BENCH_RESULTS. BUILD_DIR (default: build) picks the build directory. Every lftag-bench
# option works here: --systems, --threads, --seed, --list (see docs/BENCHMARKS.md).
set -euo pipefail
root=$(cd "$(dirname "$0")/.." && pwd)
"$root/scripts/install-deps.sh"
cd "$root"
build=${BUILD_DIR:-build}
if [ ! -f "$build/build.ninja" ]; then
  meson setup "$build"
fi
ninja -C "$build" bench/lftag-bench

mode=full
for arg in "$@"; do [ "$arg" = --quick ] && mode=quick; done
out=${BENCH_RESULTS:-$root/bench/results/$mode}
status=0
"$build/bench/lftag-bench" --out "$out" "$@" || status=$?
# Debian's python3: python3-matplotlib and python3-numpy are installed for it.
/usr/bin/python3 "$root/bench/plot.py" "$out"
echo "results: $out"
exit $status
