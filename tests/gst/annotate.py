#!/usr/bin/env python3
# SPDX-License-Identifier: LGPL-2.1-or-later
"""`lftag annotate` as a user runs it, on short videos of lftagtestsrc whose ground truth
is kept while they are written: the annotated video decodes, the JSON Lines match the
truth, mistakes end with one line, a non-zero status and no file, progress suits the
terminal or the log. Reports each case as TAP.

    annotate.py LFTAG_EXECUTABLE WORK_DIR
"""
import json
import math
import os
import pty
import signal
import subprocess
import sys
import time

import gi

gi.require_version("Gst", "1.0")
from gi.repository import Gst  # noqa: E402
from tap import case, run_cases  # noqa: E402
from videos import decoded  # noqa: E402

lftag, work = sys.argv[1:3]
os.makedirs(work, exist_ok=True)
Gst.init(None)
# Under AddressSanitizer python3 runs with leak detection off (its own leaks are not
# ours); `lftag` is ours, and every run of it below gets it back.
if "LFTAG_TOOL_ASAN_OPTIONS" in os.environ:
    os.environ["ASAN_OPTIONS"] = os.environ["LFTAG_TOOL_ASAN_OPTIONS"]
FRAMES = 45
IDS = (6789, 42, 300)


def path(name):
    return os.path.join(work, name)


def annotate(*args, expect=0, env=None, stderr=subprocess.PIPE):
    # In the work directory, where a stray file would show.
    result = subprocess.run([lftag, "annotate", *args], stdout=subprocess.PIPE, stderr=stderr, text=True,
                            timeout=600, env=dict(os.environ, **(env or {})), cwd=work)
    assert result.returncode == expect, (f"lftag annotate {' '.join(args)} exited {result.returncode}, not {expect}\n"
                                         f"{result.stdout}\n{result.stderr}")
    return result


def remove(*names):
    for name in names:
        for p in (path(name), path(name) + ".part"):
            if os.path.exists(p):
                os.remove(p)


def run_to_eos(pipeline):
    bus = pipeline.get_bus()
    pipeline.set_state(Gst.State.PLAYING)
    message = bus.timed_pop_filtered(600 * Gst.SECOND, Gst.MessageType.EOS | Gst.MessageType.ERROR)
    pipeline.set_state(Gst.State.NULL)
    assert message and message.type == Gst.MessageType.EOS, message.parse_error() if message else "timeout"


TRUTH = {}


def recording():
    """45 frames at 640x480 of three moving 3x3 markers with noise, as VP8 in WebM, and the
    truth of every frame (in order): [(family, id, centre, fully visible, edge in px)]."""
    video = path("input.webm")
    if not TRUTH:
        if os.path.exists(video):
            os.remove(video)
        pipeline = Gst.parse_launch(
            f"lftagtestsrc num-buffers={FRAMES} ids={','.join(map(str, IDS))} noise=1 ! "
            "video/x-raw,width=640,height=480 ! identity name=tap ! videoconvert ! "
            "vp8enc deadline=1 target-bitrate=3000000 ! webmmux ! filesink name=out")
        pipeline.get_by_name("out").set_property("location", video)
        frames = []

        def keep(pad, info):
            truth = info.get_buffer().get_custom_meta("LFTagTruthMeta").get_structure()
            frames.append([(m.get_value("family"), int(m.get_value("id-string")), tuple(m.get_value("center")),
                            m.get_value("fully-visible"), m.get_value("edge-px")) for m in truth.get_value("markers")])
            return Gst.PadProbeReturn.OK

        pipeline.get_by_name("tap").get_static_pad("src").add_probe(Gst.PadProbeType.BUFFER, keep)
        run_to_eos(pipeline)
        TRUTH["frames"] = frames
    return video


def check_jsonl(lines):
    """Every line a frame in order, its detections the truth's markers where they are."""
    frames = TRUTH["frames"]
    assert len(lines) == len(frames), f"{len(lines)} lines for {len(frames)} frames"
    visible = found = 0
    for n, (line, truth) in enumerate(zip(lines, frames)):
        assert line["frame"] == n, line["frame"]
        # WebM keeps timestamps to the millisecond.
        assert abs(line["pts"] - n * Gst.SECOND / 30) <= Gst.MSECOND, (n, line["pts"])
        assert abs(line["time"] - line["pts"] / Gst.SECOND) < 1e-9
        assert (line["width"], line["height"]) == (640, 480)
        assert line["analysed"] is True, (n, line["analysed"])  # annotate analyses every frame
        assert list(line)[:3] == ["frame", "pts", "time"], list(line)

        def matches(d, m):
            family, marker_id, center, _, edge = m
            return (d["family"], d["id"]) == (family, marker_id) and math.dist(d["center"], center) <= max(
                2.0, 0.1 * edge)

        for d in line["detections"]:
            assert any(matches(d, m) for m in truth), f"frame {n}: wrong detection {d['family']} {d['id']} " \
                                                      f"at {d['center']}"
            assert len(d["centroids"]) == 9 and len(d["pose"]["tvec"]) == 3 and "worst_cell" in d
        for m in truth:
            if m[3]:
                visible += 1
                found += any(matches(d, m) for d in line["detections"])
    assert visible > 100 and found >= 0.9 * visible, f"found {found} of {visible} visible markers"
    return found


@case
def annotate_every_container():
    recording()
    for name, codec in (("out.mp4", "video/x-h264"), ("out.mkv", "video/x-h264"), ("out.webm", "video/x-vp8"),
                        ("out.avi", "image/jpeg")):
        remove(name, name + ".jsonl")
        result = annotate(recording(), "--output", path(name), "--jsonl", path(name + ".jsonl"))
        size, frames, codecs = decoded(path(name))
        assert (size, frames) == ((640, 480), FRAMES), (name, size, frames)
        assert codecs and codecs[0] == codec, (name, codecs)
        assert not os.path.exists(path(name) + ".part") and not os.path.exists(path(name + ".jsonl") + ".part")
        check_jsonl([json.loads(line) for line in open(path(name + ".jsonl"))])
        # A log gets no carriage returns or escape sequences; the summary names the markers.
        assert "\r" not in result.stderr and "\033" not in result.stderr, repr(result.stderr)
        assert f"{FRAMES} frames in" in result.stderr, result.stderr
        assert all(f"3x3 {i} (" in result.stderr for i in IDS), result.stderr
        assert result.stdout == "", result.stdout


@case
def jsonl_to_stdout_without_video():
    # No deadline: under the sanitizers a frame can outlast it, and its warning (tested in
    # test_cli) would be the one line on stderr.
    result = annotate(recording(), "--jsonl", "-", "--quiet", "--deadline", "0")
    check_jsonl([json.loads(line) for line in result.stdout.splitlines()])
    assert result.stderr == "", result.stderr
    assert not [name for name in os.listdir(work) if name.endswith(".part")], os.listdir(work)


@case
def options_reach_the_detector():
    # Families the video does not have: nothing found. A camera: metric poses and axes.
    result = annotate(recording(), "--jsonl", "-", "--family", "4X4, 5x5")
    assert all(json.loads(line)["detections"] == [] for line in result.stdout.splitlines())
    assert "no markers found" in result.stderr, result.stderr
    result = annotate(recording(), "--jsonl", "-", "--fx", "640", "--tag-size", "0.05", "-q")
    poses = [d["pose"] for line in result.stdout.splitlines() for d in json.loads(line)["detections"]]
    assert poses and all(p["calibrated"] and p["tag_size"] == 0.05 for p in poses), poses[:1]
    # The ids in use: the others are not reported.
    kept = IDS[0]
    result = annotate(recording(), "--jsonl", "-", "-q", "--ids", f"{kept},1-2")
    found = {d["id"] for line in result.stdout.splitlines() for d in json.loads(line)["detections"]}
    assert found == {kept}, found


@case
def tracking_in_the_json():
    # --tracking: every detection has its track; a marker keeps its track for as long as it
    # is in the lines (a new one only after a line without it), and a predicted marker is
    # never a new track. Without it, no "track".
    result = annotate(recording(), "--jsonl", "-", "--tracking", "--smoothing", "--quiet", "--deadline", "0")
    lines = [json.loads(line) for line in result.stdout.splitlines()]
    check_jsonl(lines)
    tracks, previous, seen_ids = {}, set(), set()
    for line in lines:
        present = set()
        for d in line["detections"]:
            t = d["track"]
            key = (d["family"], d["id"])
            present.add(key)
            assert t["state"] in ("measured", "predicted"), t
            assert t["id"] >= 1 and isinstance(t["id"], int), t
            assert t["first_seen"] <= t["last_seen"] <= line["time"] + 1e-9, (t, line["time"])
            assert abs(t["age"] - (line["time"] - t["first_seen"])) < 1e-6, (t, line["time"])
            assert (t["state"] == "measured") == (abs(t["last_seen"] - line["time"]) < 1e-9), (t, line["time"])
            assert len(t["smoothed_pose"]["rvec"]) == 3 and len(t["smoothed_pose"]["tvec"]) == 3, t
            if key in previous:
                assert tracks[key] == t["id"], (key, tracks[key], t)
            else:
                assert t["state"] == "measured" and t["id"] not in seen_ids, (key, t)
            tracks[key] = t["id"]
            seen_ids.add(t["id"])
        previous = present
    assert len(seen_ids) >= len(IDS), seen_ids
    plain = annotate(recording(), "--jsonl", "-", "--quiet", "--deadline", "0")
    assert all("track" not in d for line in plain.stdout.splitlines() for d in json.loads(line)["detections"])
    for args in (("--smoothing",), ("--lost-after", "1"), ("--full-detection-interval", "5")):
        result = annotate(recording(), "--jsonl", "-", *args, expect=2)
        assert "need --tracking" in result.stderr, result.stderr


@case
def full_detection_interval():
    # --full-detection-interval 5: four frames in five only read the tracked markers where
    # their tracks predict them. Those markers are still measured there (nearly all), and
    # under no id the full search did not find.
    def measured(*args):
        result = annotate(recording(), "--jsonl", "-", "--tracking", "--quiet", "--deadline", "0", *args)
        return [{(d["family"], d["id"]) for d in json.loads(line)["detections"] if d["track"]["state"] == "measured"}
                for line in result.stdout.splitlines()]
    every, sparse = measured(), measured("--full-detection-interval", "5")
    assert len(every) == len(sparse) == FRAMES, (len(every), len(sparse))
    assert set().union(*sparse) <= set().union(*every), (set().union(*sparse), set().union(*every))
    found_every, found_sparse = sum(map(len, every)), sum(map(len, sparse))
    assert found_sparse >= 0.9 * found_every, (found_sparse, found_every)


@case
def principal_point_zero_is_zero():
    # --cx 0 --cy 0 is the top-left pixel, not "not given" (the frame centre): the pose
    # projects each marker's centre through the principal point given.
    def poses(*camera):
        result = annotate(recording(), "--jsonl", "-", "--fx", "640", *camera, "-q")
        return [(d["center"], d["pose"]["tvec"]) for line in result.stdout.splitlines()
                for d in json.loads(line)["detections"]]

    for camera, (cx, cy) in (((), (319.5, 239.5)), (("--cx", "0", "--cy", "0"), (0, 0)),
                             (("--cx", "0"), (0, 239.5))):
        found = poses(*camera)
        assert found, camera
        for center, t in found:
            projected = (640 * t[0] / t[2] + cx, 640 * t[1] / t[2] + cy)
            assert math.dist(projected, center) < 2, (camera, center, projected)


@case
def progress_on_a_terminal():
    remove("tty.webm")
    master, slave = pty.openpty()
    process = subprocess.Popen([lftag, "annotate", recording(), "--output", path("tty.webm")], stdout=subprocess.PIPE,
                               stderr=slave)
    os.close(slave)
    output = b""
    while True:
        try:
            chunk = os.read(master, 4096)
        except OSError:  # the other side closed
            break
        if not chunk:
            break
        output += chunk
    assert process.wait(timeout=600) == 0, output
    os.close(master)
    text = output.decode()
    assert "\r" in text and "fps" in text and "100 %" in text, repr(text)
    assert f"{FRAMES} frames in" in text, repr(text)


@case
def mistakes_end_with_one_line_and_no_file():
    recording()
    not_video = path("not-a-video.webm")
    with open(not_video, "w") as f:
        f.write("this is text\n" * 100)
    cases = [
        ((path("missing.webm"), "--output", path("m.mp4")), 1, "missing.webm"),
        ((not_video, "--output", path("m.mp4")), 1, "cannot decode"),
        ((recording(), "--output", "/nonexistent-dir/m.mp4"), 1, "cannot write '/nonexistent-dir/m.mp4'"),
        ((recording(), "--output", path("m.mp4"), "--jsonl", "/nonexistent-dir/m.jsonl"), 1, "m.jsonl"),
        ((recording(), "--output", path("m.xyz")), 2, ".mp4"),
        ((recording(), "--output", path("m.mp4"), "--family", "9x9"), 2, "9x9"),
        ((recording(), "--output", path("m.mp4"), "--family", "3x3", "--ids", "16384"), 2, "16384"),
        ((recording(), "--output", path("m.mp4"), "--ids", "4-1"), 2, "--ids"),
        ((recording(), "--output", path("m.mp4"), "--overlay", "outline,box"), 2, "box"),
        ((recording(), "--output", path("m.mp4"), "--calibration", path("none.yml")), 2, "none.yml"),
        ((recording(),), 2, "--output"),
    ]
    for args, status, needle in cases:
        result = annotate(*args, expect=status)
        lines = result.stderr.strip().splitlines()
        assert len(lines) == 1 and lines[0].startswith("lftag annotate: ") and needle in lines[0], (args, lines)
        for name in ("m.mp4", "m.mp4.part", "m.xyz", "m.xyz.part", "m.jsonl", "m.jsonl.part"):
            assert not os.path.exists(path(name)), (args, name)


@case
def no_encoder_says_what_to_install():
    # As if gstreamer1.0-plugins-ugly and -libav were not installed: no H.264 encoder.
    env = {"GST_PLUGIN_LOADING_WHITELIST": os.environ["GST_PLUGIN_LOADING_WHITELIST"].replace(
        "gst-plugins-ugly:", "").replace("gst-libav:", ""), "GST_REGISTRY_1_0": path("no-ugly.registry")}
    result = annotate(recording(), "--output", path("m.mp4"), expect=1, env=env)
    lines = result.stderr.strip().splitlines()
    assert len(lines) == 1 and "gstreamer1.0-plugins-ugly" in lines[0] and ".webm" in lines[0], lines
    assert not os.path.exists(path("m.mp4")) and not os.path.exists(path("m.mp4.part"))
    remove("fallback.mkv")
    result = annotate(recording(), "--output", path("fallback.mkv"), env=env)  # .mkv falls back to VP8
    assert decoded(path("fallback.mkv"))[2][0] == "video/x-vp8"


@case
def finds_the_plugin_of_its_build():
    # Run as the README says to run build/src/lftag: under `meson devenv`, which puts the
    # build's gst/ on GST_PLUGIN_PATH (the binary keeps no path of the build tree), with no
    # plugin path of our own and a registry of its own.
    env = {k: v for k, v in os.environ.items() if not k.startswith("GST_PLUGIN")}
    env["GST_REGISTRY_1_0"] = path("plain.registry")
    build = os.path.dirname(os.path.dirname(os.path.abspath(lftag)))
    # meson is a Python program: under the sanitizer build's preloaded runtime LeakSanitizer
    # would report Python's own allocations; the tool loads its runtime itself.
    devenv = {k: v for k, v in env.items() if k != "LD_PRELOAD"}
    result = subprocess.run(["meson", "devenv", "-C", build, lftag, "annotate", recording(), "--jsonl", "-", "-q"],
                            capture_output=True, text=True, env=devenv, timeout=600)
    assert result.returncode == 0, result.stderr
    assert len(result.stdout.splitlines()) == FRAMES
    # Without it, the tool says in one line how to run it, unless a plugin is installed.
    result = subprocess.run([lftag, "annotate", recording(), "--jsonl", "-", "-q"], capture_output=True, text=True,
                            env=env, timeout=600)
    if result.returncode != 0:
        lines = result.stderr.strip().splitlines()
        assert result.returncode == 1 and len(lines) == 1 and "meson devenv" in lines[0], result.stderr


def interrupt_leaves_nothing(sig, status):
    long_video = path("long.webm")
    if not os.path.exists(long_video):
        pipeline = Gst.parse_launch("lftagtestsrc num-buffers=900 count=2 ! video/x-raw,width=320,height=240 ! "
                                    "videoconvert ! vp8enc deadline=1 ! webmmux ! filesink name=out")
        pipeline.get_by_name("out").set_property("location", long_video)
        run_to_eos(pipeline)
    remove("cut.mp4", "cut.jsonl")
    process = subprocess.Popen([lftag, "annotate", long_video, "--output", path("cut.mp4"), "--jsonl",
                                path("cut.jsonl")], stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True)
    deadline = time.monotonic() + 60
    while not os.path.exists(path("cut.jsonl.part")) and time.monotonic() < deadline:
        time.sleep(0.05)
    # Frames written: the signal comes in the middle of the run.
    while os.path.getsize(path("cut.jsonl.part")) == 0 and time.monotonic() < deadline:
        time.sleep(0.05)
    assert process.poll() is None, "the run ended before the signal"
    process.send_signal(sig)
    _, stderr = process.communicate(timeout=60)
    assert process.returncode == status, (process.returncode, stderr)
    assert f"interrupted ({sig.name})" in stderr, stderr
    for name in ("cut.mp4", "cut.mp4.part", "cut.jsonl", "cut.jsonl.part"):
        assert not os.path.exists(path(name)), name


@case
def interrupted_run_leaves_nothing():
    interrupt_leaves_nothing(signal.SIGINT, 130)


@case
def terminated_run_leaves_nothing():
    # What timeout, systemd and docker send: it once left out.mp4.part and out.jsonl.part.
    interrupt_leaves_nothing(signal.SIGTERM, 143)


def damaged_copy(video, name, cut=None, overwrite=None):
    """A copy of `video` cut to the first `cut` of its bytes, or with the bytes from
    overwrite[0] to overwrite[1] (fractions of its size) replaced by a pattern."""
    data = bytearray(open(video, "rb").read())
    if cut is not None:
        data = data[:int(len(data) * cut)]
    if overwrite is not None:
        begin, end = (int(len(data) * f) for f in overwrite)
        data[begin:end] = bytes((i * 37 + 11) & 255 for i in range(end - begin))
    with open(path(name), "wb") as f:
        f.write(data)
    return path(name)


def mjpeg_recording():
    """90 frames of lftagtestsrc at 320x240, 30 fps, as Motion JPEG in AVI: its frames sit
    one after another in the file, so overwriting its middle loses whole frames."""
    video = path("input.avi")
    if not os.path.exists(video):
        pipeline = Gst.parse_launch("lftagtestsrc num-buffers=90 ids=6789 ! video/x-raw,width=320,height=240 ! "
                                    "videoconvert ! jpegenc ! avimux ! filesink name=out")
        pipeline.get_by_name("out").set_property("location", video)
        run_to_eos(pipeline)
    return video


def damage_warnings(stderr):
    return [line for line in stderr.splitlines() if line.startswith("lftag annotate: warning: ")]


@case
def intact_input_has_no_damage():
    # Without the deadline: under the sanitizers on a loaded machine a frame can outlast it,
    # and its warning is not about the input.
    for video in (recording(), mjpeg_recording()):
        result = annotate(video, "--jsonl", path("intact.jsonl"), "--strict", "--deadline", "0")
        assert damage_warnings(result.stderr) == [] and "damaged" not in result.stderr, result.stderr


@case
def truncated_file_is_reported():
    # The WebM header gives 1.5 s; the cut file decodes to about 60 % of it, then ends.
    video = damaged_copy(recording(), "truncated.webm", cut=0.6)
    remove("truncated.jsonl")
    result = annotate(video, "--jsonl", path("truncated.jsonl"))
    lines = [json.loads(line) for line in open(path("truncated.jsonl"))]
    assert 5 < len(lines) < FRAMES, len(lines)
    assert [line["frame"] for line in lines] == list(range(len(lines))), [line["frame"] for line in lines]
    missing = FRAMES - len(lines)
    warnings = damage_warnings(result.stderr)
    assert any("truncated.webm' ends at" in w and f"{missing} frames missing" in w for w in warnings), result.stderr
    assert f"damaged input: {missing} frames missing at the end" in result.stderr, result.stderr
    # --strict: the same files, exit status 3, saying why.
    remove("truncated.jsonl")
    result = annotate(video, "--jsonl", path("truncated.jsonl"), "--strict", expect=3)
    assert len(open(path("truncated.jsonl")).readlines()) == len(lines)
    assert result.stderr.strip().splitlines()[-1].endswith("exit status 3 (--strict)"), result.stderr


@case
def overwritten_middle_keeps_frame_numbers():
    # Without the deadline, so that both runs find the same markers however loaded the machine.
    intact = [json.loads(line) for line in
              annotate(mjpeg_recording(), "--jsonl", "-", "-q", "--deadline", "0").stdout.splitlines()]
    assert [line["frame"] for line in intact] == list(range(90))
    video = damaged_copy(mjpeg_recording(), "overwritten.avi", overwrite=(0.4, 0.5))
    result = annotate(video, "--jsonl", "-", "--deadline", "0")
    lines = [json.loads(line) for line in result.stdout.splitlines()]
    frames = [line["frame"] for line in lines]
    assert 30 < len(lines) < 90, len(lines)
    assert frames == sorted(set(frames)), frames
    # Numbered by timestamp: each frame keeps its number in the intact file, its pts and
    # its marker where it was.
    for line in lines:
        same = intact[line["frame"]]
        assert line["frame"] == round(line["stream_time"] * 30 / Gst.SECOND), line
        assert line["pts"] == same["pts"], (line["frame"], line["pts"], same["pts"])
        assert [d["id"] for d in line["detections"]] == [d["id"] for d in same["detections"]], line["frame"]
    gaps = [b - a - 1 for a, b in zip(frames, frames[1:]) if b - a > 1]
    assert gaps, frames
    warnings = damage_warnings(result.stderr)
    assert sum("frames missing in" in w or "frame missing in" in w for w in warnings) == len(gaps), warnings
    assert f"{len(gaps)} timestamp gap" in result.stderr and f"({sum(gaps)} frames missing)" in result.stderr, \
        result.stderr
    annotate(video, "--jsonl", path("overwritten.jsonl"), "--strict", expect=3)


@case
def missing_decoder_says_what_to_install_first():
    # An H.264 MP4 read as if gstreamer1.0-libav were not installed: no H.264 decoder.
    video = path("h264.mp4")
    if not os.path.exists(video):
        annotate(recording(), "--output", video, "-q")
    env = {"GST_PLUGIN_LOADING_WHITELIST": os.environ["GST_PLUGIN_LOADING_WHITELIST"].replace("gst-libav:", ""),
           "GST_REGISTRY_1_0": path("no-libav.registry")}
    result = annotate(video, "--jsonl", "-", expect=1, env=env)
    lines = result.stderr.strip().splitlines()
    assert len(lines) == 1 and "cannot decode" in lines[0], lines
    assert "gstreamer1.0-libav (avdec_h264)" in lines[0], lines
    assert "video/x-h264" not in lines[0] and "stream-format" not in lines[0], lines  # no raw caps
    # Only decoders that are missing: with libav back, none is suggested and the file decodes.
    assert "vp8dec" not in lines[0], lines


run_cases()
