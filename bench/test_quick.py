#!/usr/bin/python3
# SPDX-License-Identifier: LGPL-2.1-or-later
"""meson test 'bench:quick': the benchmark suite end to end on LFTag 3x3 and two peers.

    test_quick.py LFTAG_BENCH PLOT_PY WORK_DIR

Runs every experiment in quick mode, then the plots and the tables, and fails when the program fails
(its "check" experiment fails when a system misses its own markers at 2 m, gets their ids,
centres or poses wrong), when a result file is missing or malformed, or when a peer is
not found at the range sweep's first distance. It asserts nothing about speed.
"""
import csv
import json
import shutil
import subprocess
import sys
from pathlib import Path

SYSTEMS = ["lftag-3x3", "apriltag-36h11-d2", "aruco-36h11"]
# The tracking experiment runs LFTag's systems and its peer, AprilTag 36h11 decimate 2, only.
TRACKING_SYSTEMS = ["lftag-3x3", "apriltag-36h11-d2"]
# Every file an experiment writes, with columns it must have; `rows`: at least one row
# per system (files such as fp_detections.csv may rightly be empty).
EXPECTED = {
    "check.csv": (["system", "id", "found", "rotation_error_deg"], True),
    "range.csv": (["system", "distance_m", "markers", "found", "wrong"], True),
    "range_summary.csv": (["system", "dictionary_size", "first_missed_m", "missed20_m"], True),
    "angle.csv": (["system", "angle_deg", "found"], True),
    "angle_summary.csv": (["system", "first_missed_deg"], True),
    "blur.csv": (["system", "blur_angle_deg", "blur_fraction", "found"], True),
    "blur_summary.csv": (["system", "blur_angle_deg", "max_fraction_all_found", "never_missed"], True),
    "pose.csv": (["system", "sweep", "rotation_error_deg", "translation_error_m"], True),
    "pose_summary.csv": (["system", "sweep", "median_rotation_deg", "median_translation_m"], True),
    "ambiguity.csv": (["system", "rule", "condition", "set", "size_px", "tilt_deg", "found", "rotation_error_deg",
                       "alternative_rotation_error_deg", "ambiguity_ratio", "wrong_choice"], True),
    "ambiguity_summary.csv": (["system", "rule", "condition", "set", "size_px", "tilt_deg", "markers", "found", "wrong", "wrong_pct",
                               "flips", "flips_pct"], True),
    "ambiguity_ratios.csv": (["system", "rule", "condition", "set", "ratio_from", "ratio_to", "found", "wrong", "flips"], True),
    "fp_summary.csv": (["system", "width", "height", "frames", "false_positives"], True),
    "fp_detections.csv": (["system", "frame", "id"], False),
    "fp_counters.csv": (["system", "counter", "value"], False),
    "speed.csv": (["set", "width", "height", "system", "median_ms"], True),
    "speed_ratios.csv": (["system", "reference", "ratio"], True),
    "speed_counters.csv": (["system", "counter", "per_frame"], False),
    "video.csv": (["system", "clip", "frame", "edge_px", "tilt_deg", "found", "wrong", "translation_error_pct",
                   "rotation_error_deg"], True),
    "video_summary.csv": (["system", "bin_kind", "bin", "markers", "found", "recall_pct", "wrong",
                           "median_translation_pct", "p90_translation_pct", "median_rotation_deg"], True),
    "video_clips.csv": (["clip", "video", "defocus_sigma_px", "noise_sigma", "light_gradient"], False),
    "video_counters.csv": (["system", "counter", "value"], False),
    "field.csv": (["system", "set", "condition", "clip", "frame", "marker", "id", "subset", "edge_px", "found", "wrong",
                   "translation_error_pct", "rotation_error_deg", "blur_px", "bend_radius_m", "occluded_pct"], True),
    "field_summary.csv": (["system", "set", "condition", "subset", "frames", "markers", "found", "recall_pct", "wrong",
                           "median_translation_pct", "p90_translation_pct", "median_rotation_deg", "p90_rotation_deg"],
                          True),
    "field_times.csv": (["system", "set", "condition", "frames", "samples", "mean_ms", "median_ms", "p99_ms"], True),
    "field_wrong.csv": (["system", "set", "condition", "clip", "frame", "id", "nearest_id", "distance_edges"], False),
    "field_fp.csv": (["system", "set", "condition", "frames", "false_positives", "frames_with_false_positives"], True),
    "field_clips.csv": (["set", "condition", "clip", "background", "codec", "kbps", "shadow_level", "pillbox_radius_px",
                         "k1", "black", "white", "gamma"], False),
    "tracking_summary.csv": (["system", "source", "set", "condition", "markers", "found_per_frame",
                              "recall_per_frame_pct", "found_measured", "found_predicted", "recall_tracked_pct",
                              "wrong_per_frame", "wrong_tracked", "wrong_choice_off_pct", "wrong_choice_on_pct",
                              "recall_sparse_pct", "wrong_sparse"],
                             TRACKING_SYSTEMS),
    "tracking_jitter.csv": (["system", "source", "set", "pose", "pairs", "mean_rotation_deg", "p99_rotation_deg",
                             "mean_translation_mm", "p99_translation_pct"], TRACKING_SYSTEMS),
    "tracking_times.csv": (["system", "source", "set", "tracking", "frames", "mean_ms", "p99_ms", "mean_over_peer",
                            "p99_over_peer"], TRACKING_SYSTEMS),
    "adversarial.csv": (["config", "variant", "median_ms", "ratio", "candidates", "skipped_by_budget", "found",
                         "all_found", "mean_ms", "p99_ms", "max_ms", "past_deadline", "skipped_by_deadline"], False),
}
FIELD_CONDITIONS = ["plain", "shadow", "motion", "pillbox", "barrel", "low-light", "bayer", "bent", "small-1080p",
                    "crowded", "occlusion", "h264", "h264-1080p"]
PLOTS = ["range_vs_dictionary.png", "range_rate.png", "blur_polar.png", "pose_error.png", "speed.png",
         "video_recall.png"]


def fail(message):
    print("FAIL: " + message)
    sys.exit(1)


def main(bench, plot, work):
    work = Path(work)
    shutil.rmtree(work, ignore_errors=True)
    run = subprocess.run([bench, "--quick", "--systems", ",".join(SYSTEMS), "--out", str(work)])
    if run.returncode != 0:
        fail(f"lftag-bench exited with {run.returncode}")

    for name, (columns, rows_per_system) in EXPECTED.items():
        path = work / name
        if not path.exists():
            fail(f"{name} was not written")
        with open(path, newline="") as f:
            reader = csv.DictReader(f)
            rows = list(reader)
            header = reader.fieldnames or []
        missing = [c for c in columns if c not in header]
        if missing:
            fail(f"{name} lacks columns {missing}")
        if rows_per_system:
            systems = SYSTEMS if rows_per_system is True else rows_per_system
            absent = [s for s in systems if not any(r["system"] == s for r in rows)]
            if absent:
                fail(f"{name} has no rows for {absent}")

    with open(work / "range_summary.csv", newline="") as f:
        for r in csv.DictReader(f):
            if r["first_missed_m"] != "" and float(r["first_missed_m"]) <= 2.0:
                fail(f"{r['system']} missed a marker at the first range step (2 m)")

    # The video frames are hard but not that hard: a system finding nothing there means the
    # markers were not composited into the frames (or not where the truth says).
    with open(work / "video_summary.csv", newline="") as f:
        for r in csv.DictReader(f):
            if r["bin_kind"] == "all" and int(r["found"]) == 0:
                fail(f"{r['system']} found none of the markers composited into video")

    # Adversarial frames: the budget may skip tiles, never the real markers in front of them.
    with open(work / "adversarial.csv", newline="") as f:
        for r in csv.DictReader(f):
            if r["all_found"] != "1":
                fail(f"adversarial: {r['config']} {r['variant']}: {r['found']} of {r['markers']} real markers found")

    # The field experiment: both sets in every row and every condition in both; H.264 only
    # when GStreamer's elements are there (the program says so when they are not).
    with open(work / "field_summary.csv", newline="") as f:
        field = list(csv.DictReader(f))
    if {r["set"] for r in field} != {"tuning", "validation"}:
        fail("field_summary.csv: rows must carry the set, tuning or validation, and both must be there")
    with open(work / "field_times.csv", newline="") as f:
        if not {r["set"] for r in csv.DictReader(f)} <= {"tuning", "validation", "both"}:
            fail("field_times.csv: a row without its set")
    with open(work / "field_clips.csv", newline="") as f:
        codecs = {r["codec"] for r in csv.DictReader(f)}
    conditions = set(FIELD_CONDITIONS) if "h264" in codecs else set(FIELD_CONDITIONS) - {"h264", "h264-1080p"}
    for s in SYSTEMS:
        for field_set in ("tuning", "validation"):
            present = {r["condition"] for r in field if r["system"] == s and r["set"] == field_set}
            if not conditions <= present:
                fail(f"field: {s} {field_set} lacks conditions {sorted(conditions - present)}")
        # Plain frames hold nothing unusual: a system finding none of them means the
        # markers are not where the truth says.
        plain = [r for r in field if r["system"] == s and r["condition"] == "plain" and r["subset"] == "visible"]
        if not plain or sum(int(r["found"]) for r in plain) == 0:
            fail(f"field: {s} found none of the plain markers")

    meta = json.loads((work / "meta.json").read_text())
    if meta["mode"] != "quick" or not set(SYSTEMS) <= set(meta["systems"]):
        fail("meta.json does not describe the run")
    if not all(e["passed"] for e in meta["experiments"].values()):
        fail("an experiment reported failure")

    run = subprocess.run([sys.executable, plot, str(work)])
    if run.returncode != 0:
        fail(f"plot.py exited with {run.returncode}")
    for name in PLOTS:
        if not (work / name).exists() or (work / name).stat().st_size == 0:
            fail(f"plot {name} was not written")
    # The tables of docs/BENCHMARKS.md, from the same files (tables.py sits beside plot.py).
    tables = Path(plot).with_name("tables.py")
    run = subprocess.run([sys.executable, str(tables), str(work)], capture_output=True, text=True)
    if run.returncode != 0:
        fail(f"tables.py exited with {run.returncode}: {run.stderr}")
    for section in ("Range", "Grazing angle", "Motion blur", "False positives", "Funnel", "Speed", "Stages",
                    "Video", "Video recall by projected edge and tilt"):
        heading = f"### {section}"
        body = run.stdout.split(heading, 1)[1].split("###", 1)[0] if heading in run.stdout else ""
        if SYSTEMS[0] not in body and section not in ("Funnel", "Stages"):
            fail(f"tables.py: no {section} table with {SYSTEMS[0]} in it")
        if "| " not in body:
            fail(f"tables.py: no {section} table")
    for section in ("Field recall", "Field wrong ids", "Field false positives", "Field frame times"):
        body = run.stdout.split(f"### {section}", 1)[1].split("###", 1)[0] if f"### {section}" in run.stdout else ""
        if SYSTEMS[0] not in body or "| " not in body:
            fail(f"tables.py: no {section} table with {SYSTEMS[0]} in it")
    if "### Adversarial frames" not in run.stdout or "white-4-10px" not in run.stdout:
        fail("tables.py: no Adversarial frames table")

    # The field experiment gives each set its own ids: the dictionaries smaller than its two
    # sets' 60 ids (AprilTag 16h5: 30, LFTag 2x2: 16) are split in halves.
    small = work / "small-dictionaries"
    run = subprocess.run([bench, "field", "--quick", "--conditions", "plain", "--systems",
                          "apriltag-16h5-d2,lftag-2x2", "--out", str(small)])
    if run.returncode != 0:
        fail(f"lftag-bench field with the smallest dictionaries exited with {run.returncode}")
    with open(small / "field_summary.csv", newline="") as f:
        sets = {(r["system"], r["set"]) for r in csv.DictReader(f)}
    for system in ("apriltag-16h5-d2", "lftag-2x2"):
        if {(system, "tuning"), (system, "validation")} - sets:
            fail(f"field: {system} lacks a set")
    print("bench quick run: all results, plots and tables written")


if __name__ == "__main__":
    if len(sys.argv) != 4:
        print(__doc__, file=sys.stderr)
        sys.exit(2)
    main(*sys.argv[1:])
