#!/usr/bin/python3
# SPDX-License-Identifier: LGPL-2.1-or-later
"""Annotates a recorded video with lftagdetect: writes the video with the markers
outlined, labelled and given axes, and a JSON Lines file with one object per frame,
keyed by the frame's timestamp, while showing its progress.

    annotate-video.py recording.mp4 --video annotated.webm --jsonl detections.jsonl \\
        [--families 3x3,4x4] [--calibration camera.yml] [--tag-size 0.05]

Each line of the JSON Lines file:

    {"timestamp": 33366666, "time": 0.033367, "frame": 1, "width": 1280, "height": 720,
     "detections": [{"family": "3x3", "id": 6789, "center": [x, y], "corners": [[x, y], ...],
                     "keypoints": [...], "centroids": [...], "pose": {"rvec": [...],
                     "tvec": [...], "calibrated": true, "tag_size": 0.05}, ...}]}

"timestamp" is the presentation time in nanoseconds; "id" is a number when it fits in 53
bits, else a decimal string (as `lftag detect` writes them). The video file's type follows
its extension: .webm and .mkv (VP8), .avi (Motion JPEG). Reads whatever decodebin can.
Needs python3-gi and python3-gst-1.0: run it with Debian's /usr/bin/python3.
"""
import argparse
import json
import os
import sys

import gi

gi.require_version("Gst", "1.0")
from gi.repository import GLib, Gst  # noqa: E402

ENCODERS = {".webm": "vp8enc ! webmmux", ".mkv": "vp8enc ! matroskamux", ".avi": "jpegenc ! avimux"}


def points(value):
    return [list(p) for p in value]


def detection_json(d):
    """An lftag/detection structure as the JSON of `lftag detect`."""
    id_text = d.get_value("id-string")
    return {
        "family": d.get_value("family"),
        "id": int(id_text) if int(id_text) < 2 ** 53 else id_text,
        "center": list(d.get_value("center")),
        "corners": points(d.get_value("corners")),
        "keypoints": points(d.get_value("keypoints")),
        "centroids": points(d.get_value("centroids")),
        "pose": {"rvec": list(d.get_value("rvec")), "tvec": list(d.get_value("tvec")),
                 "calibrated": d.get_value("calibrated"), "tag_size": d.get_value("tag-size")},
        "decode_error": d.get_value("decode-error"),
        "edge_score": d.get_value("edge-score"),
        "reprojection_error": d.get_value("reprojection-error"),
    }


class Annotator:
    def __init__(self, args):
        sink = "fakesink"
        if args.video:
            sink = f"{ENCODERS[os.path.splitext(args.video)[1].lower()]} ! filesink name=out"
        self.pipeline = Gst.parse_launch(
            "filesrc name=in ! decodebin ! videoconvert ! lftagdetect name=detect message=false "
            f"overlay={args.overlay} ! videoconvert ! {sink}")
        # Paths go in as properties, so no character in them needs quoting.
        self.pipeline.get_by_name("in").set_property("location", args.input)
        if args.video:
            self.pipeline.get_by_name("out").set_property("location", args.video)
        detect = self.pipeline.get_by_name("detect")
        detect.set_property("families", args.families)
        if detect.get_property("families") != args.families:  # refused, with a warning saying why
            raise ValueError(f"invalid --families {args.families}")
        if args.calibration:
            detect.set_property("calibration-file", args.calibration)
        if args.tag_size:
            detect.set_property("tag-size", args.tag_size)
        detect.get_static_pad("src").add_probe(Gst.PadProbeType.BUFFER, self.on_buffer)

        self.jsonl = open(args.jsonl, "w") if args.jsonl else None
        self.frames = self.markers = 0
        self.status = 0
        self.loop = GLib.MainLoop()
        self.tty = sys.stderr.isatty()
        self.reported = -1

    def on_buffer(self, pad, info):
        """The streaming thread: one JSON line per analysed frame."""
        buffer = info.get_buffer()
        meta = buffer.get_custom_meta("LFTagMeta")
        if meta is not None:
            s = meta.get_structure()
            detections = [detection_json(d) for d in s.get_value("detections")]
            if self.jsonl:
                record = {"timestamp": buffer.pts, "time": round(buffer.pts / Gst.SECOND, 6), "frame": self.frames,
                          "width": s.get_value("width"), "height": s.get_value("height"), "detections": detections}
                self.jsonl.write(json.dumps(record) + "\n")
            self.markers += len(detections)
        self.frames += 1
        return Gst.PadProbeReturn.OK

    def progress(self, final=False):
        ok, position = self.pipeline.query_position(Gst.Format.TIME)
        known, duration = self.pipeline.query_duration(Gst.Format.TIME)
        percent = int(100 * position / duration) if ok and known and duration > 0 else None
        if final:
            percent = 100
        # On a terminal the line is redrawn; elsewhere (a log) one line per 10 %.
        if not self.tty and not final and (percent is None or percent // 10 == self.reported // 10):
            return True
        self.reported = percent if percent is not None else self.reported
        done = f"{percent:3d} %" if percent is not None else "  ? %"
        line = (f"{done}  {max(position, 0) / Gst.SECOND:7.1f} s  {self.frames} frames  "
                f"{self.markers} markers")
        print(("\r" if self.tty else "") + line, end="\n" if final or not self.tty else "", file=sys.stderr,
              flush=True)
        return True

    def on_message(self, bus, message):
        if message.type == Gst.MessageType.ERROR:
            error, debug = message.parse_error()
            print(f"\nannotate-video: {error.message} ({message.src.get_name()})\n{debug or ''}", file=sys.stderr)
            self.status = 1
            self.loop.quit()
        elif message.type == Gst.MessageType.WARNING:
            warning, _ = message.parse_warning()
            print(f"\nannotate-video: warning: {warning.message}", file=sys.stderr)
        elif message.type == Gst.MessageType.EOS:
            self.loop.quit()

    def run(self):
        bus = self.pipeline.get_bus()
        bus.add_signal_watch()
        bus.connect("message", self.on_message)
        timer = GLib.timeout_add(500, self.progress)
        self.pipeline.set_state(Gst.State.PLAYING)
        self.loop.run()
        GLib.source_remove(timer)
        if self.status == 0:
            self.progress(final=True)
        self.pipeline.set_state(Gst.State.NULL)
        bus.remove_signal_watch()
        if self.jsonl:
            self.jsonl.close()
        return self.status


def main():
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0],
                                     formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument("input", help="a video file decodebin can read")
    parser.add_argument("--video", help="annotated video to write (.webm, .mkv or .avi)")
    parser.add_argument("--jsonl", help="JSON Lines file of detections to write, one line per frame")
    parser.add_argument("--families", default="3x3,4x4", help="families to detect (default 3x3,4x4)")
    parser.add_argument("--calibration", help="OpenCV calibration file of the camera, for metric poses")
    parser.add_argument("--tag-size", type=float, help="outer edge of the markers' border in metres")
    parser.add_argument("--overlay", default="outline+id+axes", help="what to draw (default outline+id+axes)")
    args = parser.parse_args()
    if not args.video and not args.jsonl:
        parser.error("nothing to write: give --video, --jsonl or both")
    if args.video and os.path.splitext(args.video)[1].lower() not in ENCODERS:
        parser.error(f"--video must end in {', '.join(ENCODERS)}")
    if not os.path.isfile(args.input):
        parser.error(f"no such file: {args.input}")
    if args.calibration and not os.path.isfile(args.calibration):
        parser.error(f"no such calibration file: {args.calibration}")

    Gst.init(None)
    try:
        annotator = Annotator(args)
    except (GLib.Error, ValueError) as error:
        sys.exit(f"annotate-video: {error}")
    return annotator.run()


if __name__ == "__main__":
    sys.exit(main())
