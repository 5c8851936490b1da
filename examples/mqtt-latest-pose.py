#!/usr/bin/env python3
# SPDX-License-Identifier: LGPL-2.1-or-later
"""The consumer of examples/mqtt-cameras.sh: subscribes to every camera's detections on
one MQTT broker and prints the latest pose of each marker seen by each camera, redrawn
once a second.

    examples/mqtt-latest-pose.py [--broker HOST:PORT] [--topic 'lftag/+/detections']
                                 [--messages N]

It reads the messages through mosquitto_sub (Debian: mosquitto-clients), so it needs no
Python MQTT library. --messages N stops after N messages and prints the table once (for
scripts and tests). Each message is one lftagpublish JSON line: the camera is in the topic,
the frame's time and its detections, each with its pose (tvec in metres when the camera
is calibrated, "calibrated": false otherwise).
"""
import argparse
import json
import subprocess
import sys
import time


def table(latest):
    """One line per camera and marker: its latest frame, time and position."""
    lines = [f"{'camera':<10} {'marker':<14} {'frame':>7} {'time s':>9}  tvec (x, y, z)"]
    for (camera, family, marker), (frame, t, pose) in sorted(latest.items()):
        tvec = ", ".join(f"{v:7.3f}" for v in pose["tvec"]) if pose else "no pose"
        unit = " m" if pose and pose.get("calibrated") else ""
        lines.append(f"{camera:<10} {family + ' ' + str(marker):<14} {frame:>7} {t:>9.3f}  ({tvec}){unit}")
    return "\n".join(lines)


def main():
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--broker", default="localhost:1883", help="HOST:PORT of the broker")
    parser.add_argument("--topic", default="lftag/+/detections", help="topic filter ('+': any camera)")
    parser.add_argument("--messages", type=int, default=0, help="stop after this many messages")
    args = parser.parse_args()
    host, _, port = args.broker.rpartition(":") if ":" in args.broker else (args.broker, "", "1883")
    command = ["mosquitto_sub", "-h", host, "-p", port, "-t", args.topic, "-q", "1", "-v"]
    if args.messages:
        command += ["-C", str(args.messages)]
    try:
        sub = subprocess.Popen(command, stdout=subprocess.PIPE, text=True)
    except FileNotFoundError:
        sys.exit("mqtt-latest-pose.py: no mosquitto_sub: install mosquitto-clients")
    latest = {}
    shown = time.monotonic()
    tty = sys.stdout.isatty()
    for line in sub.stdout:
        topic, _, payload = line.rstrip("\n").partition(" ")
        camera = topic.split("/")[1] if topic.count("/") >= 2 else topic
        record = json.loads(payload)
        for d in record["detections"]:
            latest[(camera, d["family"], d["id"])] = (record["frame"], record["time"], d.get("pose"))
        if not args.messages and time.monotonic() - shown >= 1:
            print(("\033[H\033[J" if tty else "") + table(latest), flush=True)
            shown = time.monotonic()
    status = sub.wait()
    if args.messages:
        print(table(latest))
    return status


if __name__ == "__main__":
    sys.exit(main())
