#!/usr/bin/python3
# SPDX-License-Identifier: LGPL-2.1-or-later
"""Turns lftag-bench results (CSV files in one directory) into PNG plots there.

    plot.py RESULTS_DIR

Plots whatever the directory holds results for; experiments that were not run are skipped.
"""
import csv
import math
import sys
from pathlib import Path

import matplotlib

matplotlib.use("Agg")  # files only, no display
import matplotlib.pyplot as plt  # noqa: E402
import numpy as np  # noqa: E402

# The LFTag paper's detection range table (first missed, metres), to draw next to ours:
# (label, dictionary size, first missed).
PAPER_RANGE = [
    ("AprilTag 16h5 d1", 30, 30.1),
    ("AprilTag 25h9 d1", 35, 25.4),
    ("AprilTag 36h11 d1", 587, 23.4),
    ("AprilTag 41h12 d1", 2115, 17.5),
    ("AprilTag 16h5 d2", 30, 19.0),
    ("AprilTag 25h9 d2", 35, 19.7),
    ("AprilTag 36h11 d2", 587, 19.7),
    ("AprilTag 41h12 d2", 2115, 14.1),
    ("TopoTag 3x3", 128, 13.3),
    ("TopoTag 4x4", 16384, 10.6),
    ("TopoTag 5x5", 8388608, 8.39),
    ("LFTag 3x3", 16384, 27.8),
    ("LFTag 4x4", 268435456, 21.7),
]
PAPER_BLUR_LIMIT = 0.15  # the paper swept blur lengths up to 15 % of the marker edge


def read(results, name):
    path = results / name
    if not path.exists():
        return None
    with open(path, newline="") as f:
        return list(csv.DictReader(f))


def number(text):
    return float(text) if text not in ("", None) else math.nan


def by_system(rows):
    groups = {}
    for r in rows:
        groups.setdefault(r["system"], []).append(r)
    return groups


def colours(names):
    cmap = plt.get_cmap("tab20")
    return {n: cmap(i % 20) for i, n in enumerate(sorted(names))}


def plot_range(results):
    summary = read(results, "range_summary.csv")
    if not summary:
        return None
    fig, ax = plt.subplots(figsize=(8, 5.5))
    colour = colours(r["system"] for r in summary)
    for r in summary:
        x, y = number(r["dictionary_size"]), number(r["first_missed_m"])
        if math.isnan(y):
            continue
        ax.scatter(x, y, color=colour[r["system"]], s=40, zorder=3)
        ax.annotate(r["system"], (x, y), textcoords="offset points", xytext=(5, 3), fontsize=7)
    for label, size, distance in PAPER_RANGE:
        ax.scatter(size, distance, facecolors="none", edgecolors="grey", s=40, zorder=2)
        ax.annotate("paper: " + label, (size, distance), textcoords="offset points", xytext=(5, -9),
                    fontsize=6, color="grey")
    ax.set_xscale("log")
    ax.set_xlabel("dictionary size (markers)")
    ax.set_ylabel("first missed distance (m)")
    ax.set_title("Range: 1 m marker, 640x480, fx = 320 (filled: this run; open: the LFTag paper)")
    ax.grid(True, which="both", alpha=0.3)
    return save(fig, results / "range_vs_dictionary.png")


def plot_range_rate(results):
    rows = read(results, "range.csv")
    if not rows:
        return None
    fig, ax = plt.subplots(figsize=(8, 5))
    groups = by_system(rows)
    colour = colours(groups)
    for name, rs in groups.items():
        d = [number(r["distance_m"]) for r in rs]
        rate = [number(r["found"]) / number(r["markers"]) for r in rs]
        ax.plot(d, rate, color=colour[name], label=name, lw=1.2)
    ax.set_xlabel("distance (m)")
    ax.set_ylabel("markers found (fraction)")
    ax.set_ylim(-0.02, 1.02)
    ax.set_title("Detection rate against distance (1 m marker, fx = 320)")
    ax.grid(True, alpha=0.3)
    ax.legend(fontsize=7)
    return save(fig, results / "range_rate.png")


def plot_blur(results):
    summary = read(results, "blur_summary.csv")
    if not summary:
        return None
    fig = plt.figure(figsize=(7, 7))
    ax = fig.add_subplot(projection="polar")
    # 0 degrees (vertical blur) at the top, 90 (horizontal) to the right, as the paper.
    ax.set_theta_zero_location("N")
    ax.set_theta_direction(-1)
    ax.set_thetamin(0)
    ax.set_thetamax(90)
    groups = by_system(summary)
    colour = colours(groups)
    top = PAPER_BLUR_LIMIT
    for name, rs in groups.items():
        rs = sorted(rs, key=lambda r: number(r["blur_angle_deg"]))
        theta = np.radians([number(r["blur_angle_deg"]) for r in rs])
        radius = np.array([100 * number(r["max_fraction_all_found"]) for r in rs])
        ax.plot(theta, radius, "-", color=colour[name], label=name, lw=1.2)
        never = np.array([r["never_missed"] == "1" for r in rs])
        ax.plot(theta[~never], radius[~never], "o", color=colour[name], ms=4)
        ax.plot(theta[never], radius[never], "^", color=colour[name], ms=6, mfc="none")
        top = max(top, np.nanmax(radius) / 100 if len(radius) else 0)
    limit = np.radians(np.linspace(0, 90, 50))
    ax.plot(limit, np.full_like(limit, 100 * PAPER_BLUR_LIMIT), "k--", lw=0.8, label="paper's sweep limit (15 %)")
    ax.set_rmax(100 * top * 1.05)
    ax.set_title("Largest motion blur with every marker found\n(% of marker edge; angle 0 = vertical, "
                 "90 = horizontal; triangles: never missed)", fontsize=9)
    ax.legend(fontsize=7, loc="lower left", bbox_to_anchor=(-0.15, -0.15))
    return save(fig, results / "blur_polar.png")


def plot_pose(results):
    summary = read(results, "pose_summary.csv")
    if not summary:
        return None
    fig, axes = plt.subplots(2, 2, figsize=(11, 8))
    groups = by_system(summary)
    colour = colours(groups)
    for name, rs in groups.items():
        for col, sweep, key, label in ((0, "distance", "distance_m", "distance (m)"),
                                       (1, "tilt", "tilt_deg", "tilt (degrees)")):
            part = sorted((r for r in rs if r["sweep"] == sweep), key=lambda r: number(r[key]))
            x = [number(r[key]) for r in part]
            axes[0][col].plot(x, [number(r["median_rotation_deg"]) for r in part], "-o", ms=3,
                              color=colour[name], label=name)
            axes[1][col].plot(x, [100 * number(r["median_translation_rel"]) for r in part], "-o", ms=3,
                              color=colour[name], label=name)
            axes[1][col].set_xlabel(label)
    axes[0][0].set_ylabel("median rotation error (degrees)")
    axes[1][0].set_ylabel("median translation error (% of distance)")
    axes[0][0].set_title("against distance (facing the camera)")
    axes[0][1].set_title("against tilt (at a fixed distance)")
    for ax in axes.flat:
        ax.set_yscale("log")
        ax.grid(True, which="both", alpha=0.3)
    axes[0][1].legend(fontsize=7)
    fig.suptitle("Pose error against ground truth (1 m marker, 640x480, fx = 320)")
    return save(fig, results / "pose_error.png")


def plot_speed(results):
    rows = read(results, "speed.csv")
    if not rows:
        return None
    sets = sorted({(r["set"], int(r["width"]), int(r["height"])) for r in rows}, key=lambda s: (s[0], s[1]))
    fig, axes = plt.subplots(1, len(sets), figsize=(4.5 * len(sets), 6), sharey=True)
    axes = np.atleast_1d(axes)
    for ax, (name, w, h) in zip(axes, sets):
        part = [r for r in rows if (r["set"], int(r["width"]), int(r["height"])) == (name, w, h)]
        labels = [r["system"] for r in part]
        median = [number(r["median_ms"]) for r in part]
        ax.barh(labels, median, color=["tab:blue" if r["kind"] == "detector" else "tab:grey" for r in part])
        ax.set_xscale("log")
        ax.set_title(f"{name} {w}x{h}", fontsize=9)
        ax.set_xlabel("median ms per frame (one thread)")
        ax.grid(True, axis="x", which="both", alpha=0.3)
    axes[0].invert_yaxis()
    fig.suptitle("Time per frame (grey: OpenCV reference operations on the same frames)")
    return save(fig, results / "speed.png")


def plot_video(results):
    summary = read(results, "video_summary.csv")
    if not summary:
        return None
    fig, axes = plt.subplots(1, 2, figsize=(11, 4.5), sharey=True)
    groups = by_system(summary)
    colour = colours(groups)
    for ax, kind, label in ((axes[0], "edge_px", "projected tag edge (px)"), (axes[1], "tilt_deg", "tilt (degrees)")):
        bins = list(dict.fromkeys(r["bin"] for r in summary if r["bin_kind"] == kind))
        for name, rs in groups.items():
            recall = {r["bin"]: number(r["recall_pct"]) for r in rs if r["bin_kind"] == kind}
            ax.plot(range(len(bins)), [recall.get(b, math.nan) for b in bins], "-o", ms=4, color=colour[name],
                    label=name)
        ax.set_xticks(range(len(bins)))
        ax.set_xticklabels(bins)
        ax.set_xlabel(label)
        ax.grid(True, alpha=0.3)
    lowest = min((number(r["recall_pct"]) for r in summary if r["recall_pct"]), default=0)
    axes[0].set_ylim(max(0, lowest - 5), 101)
    axes[0].set_ylabel("markers found (%)")
    axes[1].legend(fontsize=7)
    fig.suptitle("Markers composited into real video (1280x720, shake, defocus, light, noise, JPEG 60)")
    return save(fig, results / "video_recall.png")


def save(fig, path):
    fig.tight_layout()
    fig.savefig(path, dpi=110)
    plt.close(fig)
    return path


def main(argv):
    if len(argv) != 2:
        print(__doc__, file=sys.stderr)
        return 2
    results = Path(argv[1])
    if not results.is_dir():
        print(f"plot.py: no results directory {results}", file=sys.stderr)
        return 1
    for plot in (plot_range, plot_range_rate, plot_blur, plot_pose, plot_speed, plot_video):
        path = plot(results)
        if path:
            print(path)
    return 0


if __name__ == "__main__":
    sys.exit(main(sys.argv))
