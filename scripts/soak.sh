#!/usr/bin/env bash
# The long soak (docs/reliability.md, "Long runs"): 100,000 frames of 1280x720 markers moving
# through lftagdetect with the overlay, resident memory sampled, then 1,000
# NULL -> PLAYING -> NULL cycles. Extra arguments go to the soak program (for example
# --frames 20000). Takes about half an hour on two cores.
set -euo pipefail
root=$(cd "$(dirname "$0")/.." && pwd)
"$root/scripts/build.sh"
cd "$root"
exec meson devenv -C build --workdir "$root" build/tests/gst/soak --frames 100000 --width 1280 --height 720 \
  --cycles 1000 "$@"
