# SPDX-License-Identifier: LGPL-2.1-or-later
"""Video files as the Python tests read them back."""
import gi

gi.require_version("Gst", "1.0")
from gi.repository import Gst  # noqa: E402


def decoded(video):
    """Width, height and number of frames of a video file, decoded, and its video caps
    before decoding (the codec)."""
    pipeline = Gst.parse_launch("filesrc name=in ! parsebin name=parse ! decodebin ! videoconvert ! "
                                "appsink name=out sync=false")
    pipeline.get_by_name("in").set_property("location", video)
    codecs = []

    def on_pad(element, pad):
        caps = pad.get_current_caps() or pad.query_caps(None)
        codecs.append(caps.get_structure(0).get_name())

    pipeline.get_by_name("parse").connect("pad-added", on_pad)
    sink = pipeline.get_by_name("out")
    pipeline.set_state(Gst.State.PLAYING)
    frames, size = 0, None
    while (sample := sink.emit("try-pull-sample", 60 * Gst.SECOND)) is not None:
        s = sample.get_caps().get_structure(0)
        size = (s.get_value("width"), s.get_value("height"))
        frames += 1
    pipeline.set_state(Gst.State.NULL)
    return size, frames, codecs
