#!/usr/bin/env bash
# The README's main command: installs what is missing, builds, and runs the demo
# without a camera. Output goes to ./demo-output.
set -euo pipefail
root=$(cd "$(dirname "$0")/.." && pwd)
"$root/scripts/build.sh"
out="$root/demo-output"
mkdir -p "$out"
lftag="$root/build/src/lftag"
# Debian's interpreter: it has python3-gi and python3-gst-1.0 (a python3 earlier on the
# PATH, from pyenv say, may not).
python=/usr/bin/python3
# GStreamer finds the build's plugin (and keeps its registry in the build).
export GST_PLUGIN_PATH="$root/build/gst${GST_PLUGIN_PATH:+:$GST_PLUGIN_PATH}"
export GST_REGISTRY="$root/build/gst-registry.dat"

echo "== Printable markers"
"$lftag" generate --family 3x3 --id 0-11 --size 50mm --paper a4 --output "$out/sheet-3x3.pdf"
"$lftag" generate --family 4x4 --id 6789 --size 100mm --output "$out/marker-4x4-6789.svg"
"$lftag" generate --family 4x4 --id 6789 --size 100mm --dpi 300 --output "$out/marker-4x4-6789.png"

echo "== A synthetic camera frame with ground truth"
"$lftag" render --family 3x3 --id 6789 --distance 4 --tilt 35 --roll 20 --noise 2 --light-gradient 0.4 \
  --photo /usr/share/doc/opencv-doc/examples/data/building.jpg --output "$out/scene.png"
"$python" - "$out/scene.json" <<'PY'
import json, sys
truth = json.load(open(sys.argv[1]))
for m in truth["markers"]:
    print(f"  {m['family']} id {m['id']}: {m['edge_px']:.0f} px across, key points "
          + ", ".join(f"({x:.1f}, {y:.1f})" for x, y in m["keypoints"]))
PY

echo "== GStreamer: lftagtestsrc ! lftagdetect"
echo "   six moving markers at 1280x720 with noise and motion blur, 100 frames of each of"
echo "   3x3, 4x4 and 6x6; every detection is checked against the truth on its frame"
"$python" "$root/examples/score-testsrc.py" --families 3x3,4x4,6x6 --frames 100 --count 6 --size 1280x720

echo "== lftag annotate: a recording, annotated"
echo "   ten seconds of four 3x3 markers over a photo, with noise and motion blur, recorded as"
echo "   H.264 in MP4 (recording.mp4), then outlined and labelled into annotated.mp4, with the"
echo "   detections of every frame in detections.jsonl"
rm -f "$out/recording.mp4"
gst-launch-1.0 -q -e lftagtestsrc num-buffers=300 count=4 noise=2 motion-blur=0.3 background=photo \
  background-location=/usr/share/doc/opencv-doc/examples/data/building.jpg \
  ! video/x-raw,width=1280,height=720 ! videoconvert ! x264enc speed-preset=veryfast ! mp4mux \
  ! filesink location="$out/recording.mp4"
"$lftag" annotate "$out/recording.mp4" --output "$out/annotated.mp4" --jsonl "$out/detections.jsonl"

echo "== lftag annotate: a real recording (opencv-doc's vtest.avi, MPEG-4 part 2; no markers in it)"
"$lftag" annotate /usr/share/doc/opencv-doc/examples/data/vtest.avi --jsonl "$out/vtest.jsonl"
echo "Wrote $(ls "$out" | wc -l) files to $out (the annotated video is annotated.mp4)"
