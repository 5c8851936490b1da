#!/usr/bin/env bash
# The detector library (liblftag) builds without cairo and without GStreamer: no command
# that ninja runs for it (compiling its sources, archiving) names either, so a program
# that embeds the detector needs neither. Usage: check-detector-deps.sh BUILD_DIR
set -euo pipefail
build=${1:?usage: check-detector-deps.sh BUILD_DIR}
commands=$(ninja -C "$build" -t commands src/liblftag.a)
if [ -z "$commands" ]; then
  echo "no build commands for src/liblftag.a in $build" >&2
  exit 1
fi
found=$(grep -Ei 'cairo|gstreamer|/gst/' <<<"$commands" || true)
if [ -n "$found" ]; then
  echo "liblftag's build names cairo or GStreamer:" >&2
  echo "$found" >&2
  exit 1
fi
echo "liblftag: $(grep -c . <<<"$commands") commands, none with cairo or GStreamer"
