#!/usr/bin/python3
# SPDX-License-Identifier: LGPL-2.1-or-later
"""Runs lftagtestsrc through lftagdetect and scores every detection against the ground
truth that comes with each frame: the truth (LFTagTruthMeta) and the detections
(LFTagMeta) are read from the same buffer. Optionally writes the annotated video.
The demo (scripts/demo.sh) runs it.

    score-testsrc.py [--families 3x3,4x4,6x6] [--frames 150] [--count 6] [--size 1280x720]
                     [--noise 2] [--motion-blur 0.5] [--output annotated.webm]

The source shows --frames frames of each family in turn, --count markers moving along
smooth paths; the detector looks for every family at once and is told the source's camera,
so its poses are metric. A marker is visible when it is wholly in the frame, and found when
a detection has its family and id and lies where it is (centre within 10 % of its size,
2 px at least); a detection that matches no marker is wrong.
Needs python3-gi and python3-gst-1.0: run it with Debian's /usr/bin/python3.
"""
import argparse
import math
import statistics
import sys

import gi

gi.require_version("Gst", "1.0")
from gi.repository import GLib, Gst  # noqa: E402


def quaternion(rvec):
    angle = math.sqrt(sum(v * v for v in rvec))
    if angle == 0:
        return (1.0, 0.0, 0.0, 0.0)
    s = math.sin(angle / 2) / angle
    return (math.cos(angle / 2), rvec[0] * s, rvec[1] * s, rvec[2] * s)


def rotation_error_deg(a, b):
    """The angle of the rotation between two Rodrigues vectors."""
    dot = abs(sum(x * y for x, y in zip(quaternion(a), quaternion(b))))
    return math.degrees(2 * math.acos(min(1.0, dot)))


class Family:
    def __init__(self, name):
        self.name = name
        self.frames = self.visible = self.found = self.wrong = 0
        self.rotation_errors, self.distance_errors = [], []


class Scorer:
    def __init__(self, args):
        self.families = [Family(name) for name in args.families.split(",")]
        self.frames_per_family = args.frames
        width, height = args.size
        sink = "fakesink"
        if args.output:
            sink = "videoconvert ! vp8enc ! webmmux ! filesink name=out"
        # lftagtestsrc renders with its default camera, fx = fy = width, centred.
        self.pipeline = Gst.parse_launch(
            f"lftagtestsrc name=src num-buffers={args.frames * len(self.families)} count={args.count} "
            f"seed={args.seed} noise={args.noise} motion-blur={args.motion_blur} family={self.families[0].name} ! "
            f"video/x-raw,width={width},height={height} ! "
            f"lftagdetect name=detect families={args.families} fx={width} overlay=outline+id+axes "
            f"messages=none ! {sink}")
        if args.output:
            self.pipeline.get_by_name("out").set_property("location", args.output)
        self.source = self.pipeline.get_by_name("src")
        self.source.get_static_pad("src").add_probe(Gst.PadProbeType.BUFFER, self.next_family)
        self.pipeline.get_by_name("detect").get_static_pad("src").add_probe(Gst.PadProbeType.BUFFER, self.score)
        self.rendered = 0
        self.status = 0

    def next_family(self, pad, info):
        """After the last frame of a family, the source switches to the next one."""
        self.rendered += 1
        if self.rendered % self.frames_per_family == 0 and self.rendered // self.frames_per_family < len(
                self.families):
            Gst.util_set_object_arg(self.source, "family",
                                    self.families[self.rendered // self.frames_per_family].name)
        return Gst.PadProbeReturn.OK

    def score(self, pad, info):
        buffer = info.get_buffer()
        truth = buffer.get_custom_meta("LFTagTruthMeta").get_structure()
        found = buffer.get_custom_meta("LFTagMeta")  # None if the frame could not be analysed
        detections = list(found.get_structure().get_value("detections")) if found else []
        markers = list(truth.get_value("markers"))
        family = next(f for f in self.families if f.name == markers[0].get_value("family"))
        family.frames += 1

        def key(s):
            return s.get_value("family"), s.get_value("id-string")

        def matches(d, m):
            reach = max(2.0, 0.1 * m.get_value("edge-px"))
            return key(d) == key(m) and math.dist(d.get_value("center"), m.get_value("center")) <= reach

        for d in detections:
            if not any(matches(d, m) for m in markers):
                family.wrong += 1
        for m in markers:
            if not m.get_value("fully-visible"):
                continue
            family.visible += 1
            d = next((d for d in detections if matches(d, m)), None)
            if d is None:
                continue
            family.found += 1
            family.rotation_errors.append(rotation_error_deg(list(d.get_value("rvec")), list(m.get_value("rvec"))))
            true_t = list(m.get_value("tvec"))
            family.distance_errors.append(100 * math.dist(d.get_value("tvec"), true_t) / math.hypot(*true_t))
        return Gst.PadProbeReturn.OK

    def run(self):
        bus = self.pipeline.get_bus()
        self.pipeline.set_state(Gst.State.PLAYING)
        message = bus.timed_pop_filtered(Gst.CLOCK_TIME_NONE, Gst.MessageType.EOS | Gst.MessageType.ERROR)
        if message.type == Gst.MessageType.ERROR:
            error, debug = message.parse_error()
            print(f"score-testsrc: {error.message} ({message.src.get_name()})\n{debug or ''}", file=sys.stderr)
            self.status = 1
        self.pipeline.set_state(Gst.State.NULL)
        return self.status

    def report(self):
        def rate(found, visible):
            return f"{100 * found / visible:5.1f} %" if visible else "    - "

        def median(values, unit):
            return f"{statistics.median(values):.3f}{unit}" if values else "-"

        print(f"{'family':8}{'frames':>7}{'visible':>9}{'found':>7}{'rate':>9}{'wrong':>7}"
              f"{'rotation error':>17}{'distance error':>17}")
        for f in self.families:
            print(f"{f.name:8}{f.frames:7d}{f.visible:9d}{f.found:7d}{rate(f.found, f.visible):>9}{f.wrong:7d}"
                  f"{median(f.rotation_errors, ' deg'):>17}{median(f.distance_errors, ' %'):>17}")
        total = [sum(getattr(f, field) for f in self.families) for field in ("frames", "visible", "found", "wrong")]
        print(f"{'all':8}{total[0]:7d}{total[1]:9d}{total[2]:7d}{rate(total[2], total[1]):>9}{total[3]:7d}")
        print("(visible: wholly in the frame; errors: medians over the markers found)")


def size(text):
    try:
        width, height = (int(v) for v in text.lower().split("x"))
    except ValueError:
        raise argparse.ArgumentTypeError(f"'{text}' is not a size such as 1280x720")
    return width, height


def main():
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0],
                                     formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument("--families", default="3x3,4x4,6x6", help="families shown in turn (default 3x3,4x4,6x6)")
    parser.add_argument("--frames", type=int, default=150, help="frames per family (default 150)")
    parser.add_argument("--count", type=int, default=6, help="markers per frame (default 6)")
    parser.add_argument("--size", type=size, default=(1280, 720), help="frame size (default 1280x720)")
    parser.add_argument("--seed", type=int, default=1, help="the source's seed (default 1)")
    parser.add_argument("--noise", type=float, default=2.0, help="the source's pixel noise, grey levels (default 2)")
    parser.add_argument("--motion-blur", type=float, default=0.5,
                        help="the source's shutter, fraction of a frame interval (default 0.5)")
    parser.add_argument("--output", help="annotated video to write (WebM)")
    args = parser.parse_args()
    if args.frames < 1 or not 1 <= args.count <= 64:
        parser.error("--frames must be positive and --count 1 to 64")
    known = [f"{n}x{n}" for n in range(2, 9)]
    if not args.families or any(name not in known for name in args.families.split(",")):
        parser.error(f"--families: a comma-separated list of {', '.join(known)}")

    Gst.init(None)
    try:
        scorer = Scorer(args)
    except GLib.Error as error:
        sys.exit(f"score-testsrc: {error.message}")
    status = scorer.run()
    scorer.report()
    return status


if __name__ == "__main__":
    sys.exit(main())
