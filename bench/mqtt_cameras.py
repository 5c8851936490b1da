#!/usr/bin/python3
# SPDX-License-Identifier: LGPL-2.1-or-later
"""Many cameras to one MQTT broker: messages per second and end-to-end latency (from the
frame's capture time to the message's receipt by a subscriber) with CAMERAS simulated
cameras, each

    appsrc is-live=true do-timestamp=true ! WxH@FPS GRAY8 ! lftagdetect late-frames=skip
        ! lftagpublish target=mqtt ! fakesink sync=true

all in this process, on a realtime clock (so a frame's capture time is the pipeline's
base time plus the frame's "running_time"), publishing at QoS 1 to a mosquitto started on
a free loopback port; mosquitto_sub receives and this script stamps each line as it comes.
A camera's frames are lftagtestsrc's (two moving markers, its own seed), rendered once
before the run and pushed in a loop at FPS, so that the run measures detection and
publishing, not lftagtestsrc's rendering (about 30 ms a 720p frame). The first WARMUP
seconds are left out. Writes mqtt_cameras.csv to RESULTS_DIR: one row per camera and one
for all.

    mqtt_cameras.py RESULTS_DIR [--cameras 8] [--size 1280x720] [--fps 30] [--seconds 30]
                                [--warmup 5]

Needs the build's plugin on GST_PLUGIN_PATH (scripts/bench.sh sets it), python3-gi,
python3-gst-1.0, mosquitto and mosquitto-clients.
"""
import argparse
import csv
import json
import os
import shutil
import socket
import statistics
import subprocess
import sys
import tempfile
import threading
import time

import gi

gi.require_version("Gst", "1.0")
from gi.repository import GObject, Gst  # noqa: E402


def free_port():
    with socket.socket() as s:
        s.bind(("127.0.0.1", 0))
        return s.getsockname()[1]


def render(caps, seed, frames):
    """`frames` frames of lftagtestsrc (two moving markers, `seed`) in `caps`."""
    p = Gst.parse_launch(f"lftagtestsrc seed={seed} count=2 num-buffers={frames} ! {caps} ! "
                         "appsink name=out sync=false")
    sink = p.get_by_name("out")
    p.set_state(Gst.State.PLAYING)
    clip = []
    while (sample := sink.emit("try-pull-sample", 60 * Gst.SECOND)) is not None:
        clip.append(sample.get_buffer())
    p.set_state(Gst.State.NULL)
    return clip


def percentile(values, p):
    ordered = sorted(values)
    return ordered[min(len(ordered) - 1, int(round(p / 100 * (len(ordered) - 1))))] if ordered else float("nan")


def main():
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("results")
    parser.add_argument("--cameras", type=int, default=8)
    parser.add_argument("--size", default="1280x720")
    parser.add_argument("--fps", type=int, default=30)
    parser.add_argument("--seconds", type=float, default=30)

    parser.add_argument("--warmup", type=float, default=5)
    parser.add_argument("--loop", type=int, default=30, help="frames rendered per camera, pushed in a loop")
    args = parser.parse_args()
    width, height = (int(v) for v in args.size.split("x"))
    broker = shutil.which("mosquitto") or shutil.which("mosquitto", path="/usr/sbin")
    if not broker or not shutil.which("mosquitto_sub"):
        sys.exit("mqtt_cameras.py: needs mosquitto and mosquitto-clients (Debian packages)")
    Gst.init(None)

    work = tempfile.mkdtemp(prefix="lftag-mqtt-bench-")
    port = free_port()
    with open(os.path.join(work, "mosquitto.conf"), "w") as f:
        f.write(f"listener {port} 127.0.0.1\nallow_anonymous true\nmax_queued_messages 100000\n")
    mosquitto = subprocess.Popen([broker, "-c", os.path.join(work, "mosquitto.conf")], stderr=subprocess.DEVNULL)
    for _ in range(600):
        with socket.socket() as s:
            if s.connect_ex(("127.0.0.1", port)) == 0:
                break
        time.sleep(0.1)

    received = []  # (receipt time ns, line)
    sub = subprocess.Popen(["mosquitto_sub", "-h", "127.0.0.1", "-p", str(port), "-t", "lftag/+/detections", "-q",
                            "1", "-v"], stdout=subprocess.PIPE, text=True, bufsize=1)

    def read():
        for line in sub.stdout:
            received.append((time.time_ns(), line))

    reader = threading.Thread(target=read, daemon=True)
    reader.start()
    time.sleep(1)  # subscribed

    caps = f"video/x-raw,format=GRAY8,width={width},height={height},framerate={args.fps}/1"
    clips = [render(caps, seed, args.loop) for seed in range(1, args.cameras + 1)]
    clock = GObject.new(Gst.SystemClock, clock_type=Gst.ClockType.REALTIME)
    pipelines, sources, base = [], [], {}
    for i in range(1, args.cameras + 1):
        p = Gst.parse_launch(
            f"appsrc name=src is-live=true do-timestamp=true format=time caps={caps} ! "
            f"lftagdetect fx={width} late-frames=skip ! "
            f"lftagpublish target=mqtt broker=127.0.0.1:{port} camera=cam{i} ! fakesink sync=true")
        p.use_clock(clock)
        pipelines.append(p)
        sources.append(p.get_by_name("src"))
    for p in pipelines:
        p.set_state(Gst.State.PLAYING)  # live: no preroll to wait for
    start = time.time_ns()
    # Every camera's next frame at each tick, a fresh (shallow) copy of the rendered one.
    period = 1 / args.fps
    tick = time.monotonic()
    n = 0
    while time.monotonic() - tick < args.seconds:
        for src, clip in zip(sources, clips):
            frame = clip[n % len(clip)].copy()
            frame.pts = frame.dts = Gst.CLOCK_TIME_NONE  # appsrc stamps it with its capture time
            src.emit("push-buffer", frame)
        n += 1
        time.sleep(max(0.0, tick + n * period - time.monotonic()))
    # Set when each went to PLAYING, as the first frames went through.
    for i, p in enumerate(pipelines, 1):
        base[f"cam{i}"] = p.get_base_time()
    for src in sources:
        src.emit("end-of-stream")
    for p in pipelines:
        p.get_bus().timed_pop_filtered(60 * Gst.SECOND, Gst.MessageType.EOS | Gst.MessageType.ERROR)
        p.set_state(Gst.State.NULL)
    time.sleep(2)
    sub.terminate()
    mosquitto.terminate()
    mosquitto.wait()
    shutil.rmtree(work, ignore_errors=True)

    # Measured: frames captured from start + warmup to start + seconds.
    begin, end = start + int(args.warmup * 1e9), start + int(args.seconds * 1e9)
    per = {}
    for t, line in list(received):
        topic, _, payload = line.rstrip("\n").partition(" ")
        camera = topic.split("/")[1]
        record = json.loads(payload)
        captured = base[camera] + record["running_time"]
        if not begin <= captured < end:
            continue
        per.setdefault(camera, []).append(((t - captured) / 1e6, record["analysed"]))
    window = (end - begin) / 1e9
    rows = []
    for camera in sorted(per, key=lambda c: int(c[3:])) + ["all"]:
        items = [x for c in per for x in per[c]] if camera == "all" else per[camera]
        latency = [ms for ms, _ in items]
        analysed = sum(1 for _, a in items if a)
        rows.append({
            "camera": camera, "size": args.size, "fps": args.fps, "cameras": args.cameras,
            "seconds": round(window, 1), "messages": len(items),
            "messages_per_s": round(len(items) / window, 1),
            "analysed_fraction": round(analysed / len(items), 3) if items else 0,
            "latency_median_ms": round(statistics.median(latency), 1) if latency else "",
            "latency_p95_ms": round(percentile(latency, 95), 1) if latency else "",
            "latency_p99_ms": round(percentile(latency, 99), 1) if latency else "",
            "latency_max_ms": round(max(latency), 1) if latency else "",
            "cpus": os.cpu_count(),
        })
    os.makedirs(args.results, exist_ok=True)
    out = os.path.join(args.results, "mqtt_cameras.csv")
    with open(out, "w", newline="") as f:
        writer = csv.DictWriter(f, fieldnames=list(rows[0]))
        writer.writeheader()
        writer.writerows(rows)
    for row in rows:
        print(" ".join(f"{k}={v}" for k, v in row.items()))
    print(f"wrote {out}")


if __name__ == "__main__":
    main()
