#!/usr/bin/env bash
# SPDX-License-Identifier: LGPL-2.1-or-later
# Several cameras publishing their detections to one MQTT broker: one pipeline per camera
# (here lftagtestsrc stands in for each), each on its own topic lftag/camN/detections.
#
#   mosquitto -p 1883 &                                  a broker (Debian: mosquitto)
#   examples/mqtt-latest-pose.py --broker localhost:1883 &   the consumer
#   examples/mqtt-cameras.sh 4 localhost:1883                four cameras, until Ctrl-C
#
# On real cameras replace lftagtestsrc by the camera's source (v4l2src, rtspsrc ! decodebin,
# ...) and give each its own camera=NAME; run one pipeline per camera, on as many hosts as
# needed, all pointing at the same broker. FRAMES (default: none, run until stopped) ends
# each pipeline after that many frames; WIDTH, HEIGHT (default 1280x720) and FPS (30)
# shape the simulated frames.
# From an uninstalled build, prefix `meson devenv -C build --workdir .` (run from the checkout).
set -euo pipefail
cameras=${1:-4}
broker=${2:-localhost:1883}
width=${WIDTH:-1280}
height=${HEIGHT:-720}
fps=${FPS:-30}
frames=()
[ -n "${FRAMES:-}" ] && frames=(num-buffers="$FRAMES")

pids=()
stop() { kill "${pids[@]}" 2>/dev/null || true; }
trap stop INT TERM
for ((i = 1; i <= cameras; i++)); do
  # A different scene per camera (seed), live at its frame rate; lftagtestsrc renders with
  # fx = frame width, so telling lftagdetect makes the poses metric (tag-size 0.1 m).
  # late-frames=skip: a host that cannot keep up passes frames on unanalysed (their
  # messages say "analysed": false) rather than falling behind.
  gst-launch-1.0 -q lftagtestsrc is-live=true seed="$i" count=2 "${frames[@]}" \
    ! "video/x-raw,width=$width,height=$height,framerate=$fps/1" \
    ! lftagdetect fx="$width" tag-size=0.1 late-frames=skip \
    ! lftagpublish target=mqtt broker="$broker" camera="cam$i" \
    ! fakesink sync=true &
  pids+=($!)
done
status=0
for pid in "${pids[@]}"; do wait "$pid" || status=$?; done
exit "$status"
