#!/usr/bin/env bash
# SPDX-License-Identifier: LGPL-2.1-or-later
# The launch lines of docs/gstreamer.md ("Pipelines and examples") for lftagdetect, runnable:
#
#   examples/pipelines.sh screen                                  synthetic markers on screen
#   examples/pipelines.sh testsrc-to-file annotated.webm          the same into a video file
#   examples/pipelines.sh file-to-file recording.mp4 annotated.webm   a recording, annotated
#
# From an uninstalled build, prefix `meson devenv -C build --workdir .` (run from the checkout).
# SINK (default autovideosink) and FRAMES (default 300) change the screen's sink and the
# synthetic videos' length; the tests run every line with SINK=fakesink.
set -euo pipefail
sink=${SINK:-autovideosink}
frames=${FRAMES:-300}
usage() {
  echo "usage: $0 screen | testsrc-to-file OUT.webm | file-to-file IN OUT.webm" >&2
  exit 2
}

case "${1:-}" in
  screen)
    # lftagtestsrc renders with fx = frame width: telling lftagdetect makes the axes metric.
    gst-launch-1.0 lftagtestsrc count=3 num-buffers="$frames" \
      ! lftagdetect overlay=outline+id+axes fx=640 ! videoconvert ! "$sink"
    ;;
  testsrc-to-file)
    [ $# -eq 2 ] || usage
    gst-launch-1.0 -e lftagtestsrc family=4x4 count=4 num-buffers="$frames" \
      ! video/x-raw,width=1280,height=720 \
      ! lftagdetect families=4x4 overlay=outline+id+axes fx=1280 \
      ! videoconvert ! vp8enc ! webmmux ! filesink location="$2"
    ;;
  file-to-file)
    [ $# -eq 3 ] || usage
    [ -f "$2" ] || { echo "$0: no such file: $2" >&2; exit 1; }
    gst-launch-1.0 -e filesrc location="$2" ! decodebin ! videoconvert \
      ! lftagdetect overlay=outline+id ! videoconvert ! vp8enc ! webmmux ! filesink location="$3"
    ;;
  *)
    usage
    ;;
esac
