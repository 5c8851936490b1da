#!/usr/bin/env python3
# SPDX-License-Identifier: LGPL-2.1-or-later
"""Reads LFTagTruthMeta and lftagdetect's LFTagMeta and region-of-interest metas from Python
(PyGObject), as gst/lftag-meta.h and docs/gstreamer.md say one can, after videoconvert and videoscale.
Reports each case as TAP."""

import gi

gi.require_version("Gst", "1.0")
gi.require_version("GstVideo", "1.0")
from gi.repository import GLib, Gst, GstVideo  # noqa: E402
from tap import case, run_cases  # noqa: E402

Gst.init(None)


def frames(launch, count):
    pipeline = Gst.parse_launch(launch + " ! appsink name=sink sync=false")
    sink = pipeline.get_by_name("sink")
    pipeline.set_state(Gst.State.PLAYING)
    buffers = []
    for _ in range(count):
        sample = sink.emit("try-pull-sample", 60 * Gst.SECOND)
        assert sample is not None, "no frame from " + launch
        buffers.append(sample.get_buffer())
    pipeline.set_state(Gst.State.NULL)
    return buffers


def truth(buffer):
    meta = buffer.get_custom_meta("LFTagTruthMeta")
    assert meta is not None, "no LFTagTruthMeta"
    return meta.get_structure()


@case
def truth_after_convert_and_scale():
    buffers = frames("lftagtestsrc num-buffers=2 ids=6789,42 ! video/x-raw,width=640,height=480 ! "
                     "videoconvert ! videoscale ! video/x-raw,format=I420,width=320,height=240", 2)
    for buffer in buffers:
        s = truth(buffer)
        assert (s.get_value("width"), s.get_value("height")) == (640, 480)
        assert s.get_value("fx") == 640.0 and list(s.get_value("distortion")) == []
        markers = list(s.get_value("markers"))
        assert [m.get_name() for m in markers] == ["lftag/truth"] * 2
        assert [m.get_value("id") for m in markers] == [6789, 42]
        assert [m.get_value("id-string") for m in markers] == ["6789", "42"]
        for m in markers:
            assert m.get_value("family") == "3x3"
            keypoints = [list(p) for p in m.get_value("keypoints")]
            assert len(keypoints) == 4 and all(len(p) == 2 and all(isinstance(v, float) for v in p)
                                               for p in keypoints)
            assert len(list(m.get_value("centroids"))) == 9
            assert len(list(m.get_value("corners"))) == 4
            assert len(list(m.get_value("center"))) == 2
            assert len(list(m.get_value("rvec"))) == 3 and list(m.get_value("tvec"))[2] > 0
            assert isinstance(m.get_value("fully-visible"), bool)
            assert m.get_value("edge-px") > 0 and m.get_value("tag-size") == 0.1


@case
def ids_beyond_64_bits():
    buffer = frames("lftagtestsrc num-buffers=1 family=8x8 ids=1267650600228229401496703205377", 1)[0]
    marker = list(truth(buffer).get_value("markers"))[0]
    assert not marker.has_field("id")
    assert marker.get_value("id-string") == "1267650600228229401496703205377"
    assert int(marker.get_value("id-string")) == 2 ** 100 + 1


@case
def truth_is_not_detection():
    buffer = frames("lftagtestsrc num-buffers=1", 1)[0]
    assert buffer.get_custom_meta("LFTagMeta") is None


@case
def detections_and_regions():
    buffer = frames("lftagtestsrc num-buffers=1 ids=6789,42 ! lftagdetect ! videoconvert ! "
                    "video/x-raw,format=NV12", 1)[0]
    meta = buffer.get_custom_meta("LFTagMeta")
    assert meta is not None, "no LFTagMeta"
    s = meta.get_structure()
    assert (s.get_value("width"), s.get_value("height")) == (640, 480)
    assert s.get_value("analysed") is True
    detections = list(s.get_value("detections"))
    assert sorted(d.get_value("id") for d in detections) == [42, 6789]
    for number, d in enumerate(detections):
        assert d.get_name() == "lftag/detection" and d.get_value("family") == "3x3"
        assert d.get_value("id-string") == str(d.get_value("id"))
        corners = [list(p) for p in d.get_value("corners")]
        assert len(corners) == 4 and len(list(d.get_value("keypoints"))) == 4
        assert len(list(d.get_value("centroids"))) == 9 and len(list(d.get_value("rvec"))) == 3
        assert list(d.get_value("tvec"))[2] > 0 and d.get_value("calibrated") is False
        # Its region: videoconvert keeps the box.
        roi = GstVideo.buffer_get_video_region_of_interest_meta_id(buffer, number)
        assert roi is not None and GLib.quark_to_string(roi.roi_type) == "lftag"
        assert all(roi.x - 1 <= x <= roi.x + roi.w and roi.y - 1 <= y <= roi.y + roi.h for x, y in corners)


@case
def region_params():
    buffer = frames("lftagtestsrc num-buffers=1 ids=6789 ! lftagdetect", 1)[0]
    roi = GstVideo.buffer_get_video_region_of_interest_meta_id(buffer, 0)
    param = roi.get_param("lftag")
    assert param is not None and param.get_value("id") == 6789 and param.get_value("id-string") == "6789"


run_cases()
