#!/usr/bin/python3
# SPDX-License-Identifier: LGPL-2.1-or-later
"""Reads lftagdetect's results from Python (PyGObject), both ways:

- the LFTagMeta of every buffer, in a pad probe on the detector's source pad (the
  streaming thread: the place to act on each frame, or to forward results);
- the "lftag" element messages on the bus, in the main loop (the application thread:
  simplest for a user interface; one message per frame with markers).

    read-meta.py                       synthetic markers from lftagtestsrc
    read-meta.py 'filesrc location=in.webm ! decodebin ! videoconvert'

The argument is the pipeline's start; "! lftagdetect name=detect message-detections=true
! fakesink" is appended (message-detections: the messages carry the full detections, as
the meta does; without it they hold the ids and centres only).
Needs python3-gi and python3-gst-1.0 (for GstValueArray as Python lists): run it with
Debian's /usr/bin/python3.
"""
import sys
import threading

import gi

gi.require_version("Gst", "1.0")
from gi.repository import GLib, Gst  # noqa: E402


PRINTING = threading.Lock()  # the probe and the main loop print from different threads


def say(line):
    with PRINTING:
        print(line, flush=True)


def describe(detection):
    """'3x3 6789 at (312.4, 201.7)' from an lftag/detection structure."""
    x, y = detection.get_value("center")
    return f"{detection.get_value('family')} {detection.get_value('id-string')} at ({x:.1f}, {y:.1f})"


def on_buffer(pad, info):
    buffer = info.get_buffer()
    meta = buffer.get_custom_meta("LFTagMeta")
    if meta is not None:  # None: a frame the detector could not analyse
        s = meta.get_structure()
        markers = [describe(d) for d in s.get_value("detections")]
        time = Gst.TIME_ARGS(buffer.pts)
        say(f"meta    {time} {s.get_value('width')}x{s.get_value('height')}: {', '.join(markers) or '-'}")
    return Gst.PadProbeReturn.OK


def on_message(bus, message, state):
    if message.type == Gst.MessageType.ELEMENT and message.has_name("lftag"):
        s = message.get_structure()
        # Timestamps are plain nanoseconds; running-time is what the pipeline clock sees.
        markers = [describe(d) for d in s.get_value("detections")]
        say(f"message {Gst.TIME_ARGS(s.get_value('timestamp'))} (running time "
            f"{Gst.TIME_ARGS(s.get_value('running-time'))}): {', '.join(markers)}")
    elif message.type == Gst.MessageType.ERROR:
        error, debug = message.parse_error()
        print(f"error from {message.src.get_name()}: {error.message}\n{debug or ''}", file=sys.stderr)
        state["status"] = 1
        state["loop"].quit()
    elif message.type == Gst.MessageType.EOS:
        state["loop"].quit()


def main():
    Gst.init(None)
    source = sys.argv[1] if len(sys.argv) > 1 else "lftagtestsrc num-buffers=30 count=3"
    try:
        pipeline = Gst.parse_launch(f"{source} ! lftagdetect name=detect message-detections=true ! fakesink")
    except GLib.Error as error:
        sys.exit(f"cannot build the pipeline: {error.message}")
    pipeline.get_by_name("detect").get_static_pad("src").add_probe(Gst.PadProbeType.BUFFER, on_buffer)

    state = {"loop": GLib.MainLoop(), "status": 0}
    bus = pipeline.get_bus()
    bus.add_signal_watch()
    bus.connect("message", on_message, state)
    pipeline.set_state(Gst.State.PLAYING)
    state["loop"].run()
    pipeline.set_state(Gst.State.NULL)
    bus.remove_signal_watch()
    return state["status"]


if __name__ == "__main__":
    sys.exit(main())
