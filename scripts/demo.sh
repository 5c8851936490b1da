#!/usr/bin/env bash
# The README's main command: installs what is missing, builds, and runs the demo
# without a camera. Output goes to ./demo-output.
set -euo pipefail
root=$(cd "$(dirname "$0")/.." && pwd)
"$root/scripts/build.sh"
out="$root/demo-output"
mkdir -p "$out"
lftag="$root/build/src/lftag"

echo "== Printable markers"
"$lftag" generate --family 3x3 --id 0-11 --size 50mm --paper a4 --output "$out/sheet-3x3.pdf"
"$lftag" generate --family 4x4 --id 6789 --size 100mm --output "$out/marker-4x4-6789.svg"
"$lftag" generate --family 4x4 --id 6789 --size 100mm --dpi 300 --output "$out/marker-4x4-6789.png"

echo "== A synthetic camera frame with ground truth"
"$lftag" render --family 3x3 --id 6789 --distance 4 --tilt 35 --roll 20 --noise 2 --light-gradient 0.4 \
  --photo /usr/share/doc/opencv-doc/examples/data/building.jpg --output "$out/scene.png"
python3 - "$out/scene.json" <<'PY'
import json, sys
truth = json.load(open(sys.argv[1]))
for m in truth["markers"]:
    print(f"  {m['family']} id {m['id']}: {m['edge_px']:.0f} px across, key points "
          + ", ".join(f"({x:.1f}, {y:.1f})" for x, y in m["keypoints"]))
PY
echo "Wrote $(ls "$out" | wc -l) files to $out"
