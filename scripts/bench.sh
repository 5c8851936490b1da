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
ninja -C "$build"

mode=full
for arg in "$@"; do [ "$arg" = --quick ] && mode=quick; done
out=${BENCH_RESULTS:-$root/bench/results/$mode}

# "throughput" is not lftag-bench's: it times the plugin in pipelines (bench/throughput.py).
# The whole suite (no experiment named) includes it.
args=() throughput=0 only_throughput=0
for arg in "$@"; do
  if [ "$arg" = throughput ]; then throughput=1; else args+=("$arg"); fi
done
if [ "${args[*]:-}" = "" ] || [ "${args[*]:-}" = --quick ]; then
  [ $throughput = 1 ] && only_throughput=1
  throughput=1
fi

status=0
if [ $only_throughput = 0 ]; then
  "$build/bench/lftag-bench" --out "$out" "${args[@]}" || status=$?
fi
if [ $throughput = 1 ]; then
  if [ -f "$build/gst/libgstlftag.so" ]; then
    quick=(); [ $mode = quick ] && quick=(--quick)
    builddir=$(cd "$build" && pwd)
    GST_PLUGIN_PATH="$builddir/gst" GST_REGISTRY="$builddir/gst-registry.dat" \
      /usr/bin/python3 "$root/bench/throughput.py" "$out" "${quick[@]}" || status=$?
  else
    echo "bench.sh: no GStreamer plugin in $build, so no throughput measurement" >&2
  fi
fi
# Debian's python3: python3-matplotlib and python3-numpy are installed for it.
/usr/bin/python3 "$root/bench/plot.py" "$out"
echo "results: $out"
exit $status
