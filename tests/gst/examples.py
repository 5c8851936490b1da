#!/usr/bin/env python3
# SPDX-License-Identifier: LGPL-2.1-or-later
"""Runs every example in examples/ (the launch lines, read-meta.c, read-meta.py,
score-testsrc.py) on short synthetic videos and checks what they write.
Reports each case as TAP.

    examples.py SOURCE_ROOT READ_META_EXECUTABLE WORK_DIR
"""
import os
import shutil
import socket
import subprocess
import sys
import time

import gi

gi.require_version("Gst", "1.0")
from gi.repository import Gst  # noqa: E402
from tap import case, run_cases  # noqa: E402
from videos import decoded  # noqa: E402

root, read_meta, work = sys.argv[1:4]
examples = os.path.join(root, "examples")
os.makedirs(work, exist_ok=True)
Gst.init(None)


def path(name):
    return os.path.join(work, name)


def run(*command, env=None, expect=0):
    result = subprocess.run(command, capture_output=True, text=True, timeout=600,
                            env=dict(os.environ, **(env or {})))
    assert result.returncode == expect, (f"{' '.join(command)} exited {result.returncode}, not {expect}\n"
                                         f"{result.stdout}\n{result.stderr}")
    return result


def python(script, *args, expect=0):
    return run(sys.executable, os.path.join(examples, script), *args, expect=expect)


def recording():
    """A recorded video of two 3x3 markers, 6789 and 42: 30 frames at 640x480, VP8."""
    video = path("recording.webm")
    if not os.path.exists(video):
        run("gst-launch-1.0", "-q", "-e", "lftagtestsrc", "num-buffers=30", "ids=6789,42", "!", "videoconvert", "!",
            "vp8enc", "!", "webmmux", "!", "filesink", f"location={video}")
    return video


@case
def launch_line_screen():
    run(os.path.join(examples, "pipelines.sh"), "screen", env={"SINK": "fakesink", "FRAMES": "20"})


@case
def launch_line_testsrc_to_file():
    run(os.path.join(examples, "pipelines.sh"), "testsrc-to-file", path("testsrc.webm"), env={"FRAMES": "20"})
    assert decoded(path("testsrc.webm"))[:2] == ((1280, 720), 20)


@case
def launch_line_file_to_file():
    run(os.path.join(examples, "pipelines.sh"), "file-to-file", recording(), path("annotated.webm"))
    assert decoded(path("annotated.webm"))[:2] == ((640, 480), 30)
    run(os.path.join(examples, "pipelines.sh"), "file-to-file", path("missing.webm"), path("x.webm"), expect=1)


@case
def read_meta_in_c():
    lines = run(read_meta).stdout.splitlines()
    assert len(lines) == 31 and lines[-1] == "30 frames", lines[-3:]
    assert all("3 marker(s): 3x3" in line and line.count("3x3") == 3 for line in lines[:-1]), lines[:3]
    source = f"filesrc location={recording()} ! decodebin ! videoconvert"
    lines = run(read_meta, source).stdout.splitlines()
    assert lines[-1] == "30 frames" and "3x3 6789 at" in lines[0] and "3x3 42 at" in lines[0], lines[:2]
    assert "(uncalibrated)" in lines[0]
    run(read_meta, "no-such-element", expect=1)


@case
def read_meta_in_python():
    lines = python("read-meta.py").stdout.splitlines()
    metas = [line for line in lines if line.startswith("meta ")]
    messages = [line for line in lines if line.startswith("message ")]
    assert len(metas) == 30 and len(messages) == 30, lines[:4]
    # Each frame's message tells what its meta does.
    for meta, message in zip(metas, messages):
        time, markers = meta.split()[1], meta.split(": ", 1)[1]
        assert message.startswith(f"message {time} (running time {time}): {markers}"), (meta, message)
        assert markers.count("3x3") == 3


@case
def score_testsrc():
    result = python("score-testsrc.py", "--families", "3x3,4x4", "--frames", "20", "--count", "3", "--size",
                    "640x480", "--output", path("scored.webm"))
    rows = {line.split()[0]: line.split() for line in result.stdout.splitlines()[1:4]}
    assert set(rows) == {"3x3", "4x4", "all"}, result.stdout
    frames, visible, found, rate, wrong = rows["all"][1], rows["all"][2], rows["all"][3], rows["all"][4], rows["all"][6]
    assert frames == "40" and wrong == "0" and int(visible) >= 100 and float(rate) >= 95, result.stdout
    assert decoded(path("scored.webm"))[:2] == ((640, 480), 40)
    python("score-testsrc.py", "--families", "3x3,10x10", expect=2)


@case
def mqtt_cameras_to_one_broker():
    # Three simulated cameras publish to one mosquitto; the consumer prints each camera's
    # markers with a metric pose. Without the broker (Debian: mosquitto) there is nothing
    # to run.
    broker = shutil.which("mosquitto") or shutil.which("mosquitto", path="/usr/sbin")
    if not broker or not shutil.which("mosquitto_sub"):
        print("# SKIP mqtt_cameras_to_one_broker: mosquitto and mosquitto-clients are not installed")
        return
    with socket.socket() as s:
        s.bind(("127.0.0.1", 0))
        port = s.getsockname()[1]
    with open(path("mosquitto.conf"), "w") as f:
        f.write(f"listener {port} 127.0.0.1\nallow_anonymous true\n")
    process = subprocess.Popen([broker, "-c", path("mosquitto.conf")], stderr=subprocess.DEVNULL)
    try:
        for _ in range(600):  # until it listens, up to a minute
            with socket.socket() as s:
                if s.connect_ex(("127.0.0.1", port)) == 0:
                    break
            time.sleep(0.1)
        address = f"127.0.0.1:{port}"
        consumer = subprocess.Popen([sys.executable, os.path.join(examples, "mqtt-latest-pose.py"), "--broker",
                                     address, "--messages", "60"], stdout=subprocess.PIPE, text=True)
        time.sleep(1)  # subscribed before the cameras start (mosquitto_sub keeps no session)
        run(os.path.join(examples, "mqtt-cameras.sh"), "3", address,
            env={"FRAMES": "20", "WIDTH": "640", "HEIGHT": "480"})
        out, _ = consumer.communicate(timeout=120)
        assert consumer.returncode == 0, out
        rows = [line.split() for line in out.splitlines()[1:]]
        assert sorted({row[0] for row in rows}) == ["cam1", "cam2", "cam3"], out
        assert len(rows) == 6 and all(row[-1] == "m" for row in rows), out  # two markers each, metric
    finally:
        process.terminate()
        process.wait(timeout=60)


run_cases()
