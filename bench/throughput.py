#!/usr/bin/python3
# SPDX-License-Identifier: LGPL-2.1-or-later
"""Pipeline throughput of lftagdetect: frames per second of

    filesrc ! rawvideoparse ! ELEMENT ! fakesink sync=false

for ELEMENT = identity (the pipeline's own cost), lftagdetect, and lftagdetect with the
overlay, over the same decoded video. The video is lftagtestsrc's moving markers encoded
as VP8 and decoded once into raw I420 frames (so decoding is not timed), or a recording
given with --video. Runs alternate between the variants; the medians go to
throughput.csv in the results directory.

    throughput.py RESULTS_DIR [--video FILE] [--sizes 1280x720,1920x1080] [--frames 300]
                              [--runs 5] [--quick]

Needs the build's plugin on GST_PLUGIN_PATH (scripts/bench.sh sets it) and Debian's
python3-gi and python3-gst-1.0.
"""
import argparse
import csv
import os
import statistics
import sys
import tempfile
import time

import gi

gi.require_version("Gst", "1.0")
from gi.repository import Gst  # noqa: E402

VARIANTS = [
    ("identity", "identity"),
    ("lftagdetect", "lftagdetect"),
    ("lftagdetect-overlay", "lftagdetect overlay=outline+id+axes"),
]


def run(description):
    """Runs a pipeline to its end; returns the wall time from PLAYING to EOS, seconds."""
    pipeline = Gst.parse_launch(description)
    bus = pipeline.get_bus()
    pipeline.set_state(Gst.State.PAUSED)
    pipeline.get_state(Gst.CLOCK_TIME_NONE)  # prerolled: the first frame is already in
    start = time.perf_counter()
    pipeline.set_state(Gst.State.PLAYING)
    message = bus.timed_pop_filtered(Gst.CLOCK_TIME_NONE, Gst.MessageType.EOS | Gst.MessageType.ERROR)
    elapsed = time.perf_counter() - start
    pipeline.set_state(Gst.State.NULL)
    if message.type == Gst.MessageType.ERROR:
        error, debug = message.parse_error()
        raise RuntimeError(f"{description}: {error.message} ({debug})")
    return elapsed


def decode_to_raw(source, width, height, path):
    """Decodes `source` (a pipeline fragment ending in raw video) to I420 frames in `path`;
    returns the number of frames."""
    run(f"{source} ! videoconvert ! videoscale ! video/x-raw,format=I420,width={width},height={height} "
        f"! filesink location={path}")
    frame_bytes = width * height * 3 // 2
    return os.path.getsize(path) // frame_bytes


def main():
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("results")
    parser.add_argument("--video", help="a recording to use instead of the synthetic video")
    parser.add_argument("--sizes", default="1280x720,1920x1080")
    parser.add_argument("--frames", type=int, default=300, help="frames of synthetic video (default 300)")
    parser.add_argument("--runs", type=int, default=5, help="timed runs of each variant (default 5)")
    parser.add_argument("--quick", action="store_true", help="30 frames, 1 run: proves the script works")
    args = parser.parse_args()
    if args.quick:
        args.frames, args.runs = 30, 1
    if args.video and not os.path.isfile(args.video):
        sys.exit(f"throughput.py: no such file: {args.video}")
    Gst.init(None)
    for factory in ("lftagdetect", "lftagtestsrc", "rawvideoparse", "vp8enc", "webmmux"):
        if Gst.ElementFactory.find(factory) is None:
            sys.exit(f"throughput.py: GStreamer element {factory} not found (is the build's plugin on GST_PLUGIN_PATH?)")
    os.makedirs(args.results, exist_ok=True)

    rows = []
    with tempfile.TemporaryDirectory() as work:
        for size in args.sizes.split(","):
            width, height = (int(v) for v in size.split("x"))
            if args.video:
                source = f"filesrc location={args.video} ! decodebin"
            else:
                encoded = os.path.join(work, "markers.webm")
                run(f"lftagtestsrc count=6 noise=2 motion-blur=0.5 num-buffers={args.frames} "
                    f"! video/x-raw,width={width},height={height} ! videoconvert ! vp8enc deadline=1 "
                    f"! webmmux ! filesink location={encoded}")
                source = f"filesrc location={encoded} ! decodebin"
            raw = os.path.join(work, "frames.i420")
            frames = decode_to_raw(source, width, height, raw)
            head = (f"filesrc location={raw} blocksize={width * height * 3 // 2} ! rawvideoparse format=i420 "
                    f"width={width} height={height} framerate=30/1")
            times = {name: [] for name, _ in VARIANTS}
            run(f"{head} ! lftagdetect ! fakesink sync=false")  # warm the page cache and the code
            for _ in range(args.runs):
                for name, element in VARIANTS:
                    times[name].append(run(f"{head} ! {element} ! fakesink sync=false"))
            base = statistics.median(times["identity"])
            for name, _ in VARIANTS:
                seconds = statistics.median(times[name])
                rows.append({
                    "size": size, "frames": frames, "runs": args.runs, "variant": name,
                    "fps": round(frames / seconds, 1),
                    "ms_per_frame": round(1000 * seconds / frames, 3),
                    "ms_over_identity": round(1000 * (seconds - base) / frames, 3),
                })
                print(f"{size} {name:22s} {rows[-1]['fps']:8.1f} fps  {rows[-1]['ms_per_frame']:7.3f} ms/frame  "
                      f"(+{rows[-1]['ms_over_identity']:.3f} ms over identity)", flush=True)
            os.remove(raw)

    with open(os.path.join(args.results, "throughput.csv"), "w", newline="") as f:
        writer = csv.DictWriter(f, fieldnames=list(rows[0]))
        writer.writeheader()
        writer.writerows(rows)


if __name__ == "__main__":
    main()
