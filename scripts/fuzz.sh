#!/usr/bin/env bash
# Builds the libFuzzer targets (fuzz/, in build-sanitize: AddressSanitizer and
# UndefinedBehaviorSanitizer) and runs each for SECONDS (default 20), one after the other,
# starting from its checked-in seeds (fuzz/corpus/TARGET) and the corpus of earlier runs
# (build-sanitize/fuzz-corpus/TARGET). Prints the executions of each target; a crash,
# a sanitizer report, a leak, an input slower than the timeout or an uncaught exception
# fails the target, and its input is kept in build-sanitize/fuzz-artifacts/TARGET/.
# Writes build-sanitize/fuzz-logs/testlog.junit.xml (one case per target) for
# scripts/summarize-tests.py. Exit status: 0 all passed, 1 a target failed, 2 the build failed.
#   scripts/fuzz.sh [SECONDS] [TARGET...]   targets: frames scenes ids families calibration
#                                           image_header json element (element and json
#                                           need GStreamer's gstreamer-check-1.0)
#   scripts/fuzz.sh --hour [TARGET...]      one hour in all, shared between the targets
# A finding is replayed with `build-sanitize/fuzz/fuzz_TARGET FILE`; once fixed, copy FILE into
# fuzz/corpus/TARGET/ so that the sanitizer suite (suite `fuzz`) replays it from then on.
set -uo pipefail
root=$(cd "$(dirname "$0")/.." && pwd)
cd "$root"
seconds=${1:-20}
shift || true
targets=("$@")
[ ${#targets[@]} -gt 0 ] || targets=(frames scenes ids families calibration image_header json element)
[ "$seconds" = --hour ] && seconds=$((3600 / ${#targets[@]}))

"$root/scripts/install-deps.sh" || exit 2
"$root/scripts/setup-sanitize.sh" || exit 2
ninja -C build-sanitize $(printf 'fuzz/fuzz_%s ' "${targets[@]}") || exit 2

# As in the sanitizer suite (tests/meson.build): every report is fatal, leaks included.
export ASAN_OPTIONS=halt_on_error=1:detect_leaks=1:print_summary=1
export UBSAN_OPTIONS=halt_on_error=1:print_stacktrace=1:print_summary=1
export LSAN_OPTIONS=suppressions=$root/tests/sanitizers/lsan.supp:print_suppressions=0
# GLib's slice allocator would hide a use after free of a GStreamer object (as in tests/meson.build).
export G_SLICE=always-malloc

# frames, scenes: 128 x 128 pixels and their padding (frame_input.hpp's kMaxInput);
# calibration: the loader's limit plus one byte (kMaxCalibrationBytes, calibration_file.hpp);
# element: a 64 KB pixel pattern (element_input.hpp); image_header: small files.
declare -A max_len=([frames]=18295 [scenes]=18295 [ids]=1024 [families]=256 [calibration]=1048577
                    [image_header]=65536 [json]=16384 [element]=65600)
declare -A timeout=([frames]=20 [scenes]=20 [ids]=10 [families]=10 [calibration]=10
                    [image_header]=10 [json]=10 [element]=20)
logs=build-sanitize/fuzz-logs
mkdir -p "$logs"
cases=() failures=0 total=0
for t in "${targets[@]}"; do
  corpus=build-sanitize/fuzz-corpus/$t artifacts=build-sanitize/fuzz-artifacts/$t
  mkdir -p "$corpus" "$artifacts"
  args=(-max_total_time="$seconds" -print_final_stats=1 -timeout="${timeout[$t]:-10}" -rss_limit_mb=2560
        -max_len="${max_len[$t]:-4096}" -artifact_prefix="$artifacts/")
  [ -f "fuzz/$t.dict" ] && args+=(-dict="fuzz/$t.dict")
  start=$(date +%s)
  build-sanitize/fuzz/fuzz_"$t" "${args[@]}" "$corpus" "fuzz/corpus/$t" >"$logs/$t.log" 2>&1
  rc=$?
  elapsed=$(($(date +%s) - start))
  execs=$(sed -n 's/^stat::number_of_executed_units: *//p' "$logs/$t.log" | tail -1)
  execs=${execs:-0}
  total=$((total + execs))
  if [ $rc -eq 0 ]; then
    printf 'fuzz %-12s %12d executions in %3d s: passed\n' "$t" "$execs" "$elapsed"
    cases+=("<testcase name=\"$t\" classname=\"fuzz\" time=\"$elapsed\"/>")
  else
    failures=$((failures + 1))
    printf 'fuzz %-12s %12d executions in %3d s: FAILED (exit %d), see %s\n' "$t" "$execs" "$elapsed" $rc "$logs/$t.log"
    grep -E '^(==[0-9]+==ERROR|SUMMARY|.*runtime error|artifact_prefix|Test unit written)' "$logs/$t.log" | head -5
    cases+=("<testcase name=\"$t\" classname=\"fuzz\" time=\"$elapsed\"><failure message=\"exit $rc\"/></testcase>")
  fi
done
echo "fuzz: $total executions in all"
{
  echo '<?xml version="1.0" encoding="utf-8"?>'
  echo "<testsuites><testsuite name=\"fuzz\" tests=\"${#targets[@]}\" failures=\"$failures\">"
  printf '%s\n' "${cases[@]}"
  echo '</testsuite></testsuites>'
} >"$logs/testlog.junit.xml"
[ $failures -eq 0 ]
