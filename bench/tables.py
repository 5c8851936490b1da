#!/usr/bin/python3
# SPDX-License-Identifier: LGPL-2.1-or-later
"""Prints the result tables of docs/BENCHMARKS.md (Markdown) from a results directory, so
that the document is written from the numbers, not retyped.

    tables.py RESULTS_DIR
"""
import csv
import statistics
import sys
from collections import defaultdict
from pathlib import Path

# The LFTag paper's published figures (SPEC section 4), beside ours.
PAPER_RANGE = {"tag36h11": (23.4, 23.9), "tagStandard41h12": (17.5, 21.7), "lftag-3x3": (27.8, 27.8),
               "lftag-4x4": (21.7, 21.7)}
PAPER_ANGLE = {"lftag-3x3": 77.5, "lftag-4x4": 76.0, "tag36h11": 77.5}


def read(results, name):
    path = results / name
    if not path.exists():
        return []
    with open(path, newline="") as f:
        return list(csv.DictReader(f))


def table(header, rows):
    lines = ["| " + " | ".join(header) + " |", "|" + "---|" * len(header)]
    lines += ["| " + " | ".join(str(c) for c in row) + " |" for row in rows]
    return "\n".join(lines)


def paper(figures, family, index=None):
    value = figures.get(family)
    if value is None:
        return ""
    return f"{value[index]:g}" if index is not None else f"{value:g}"


def range_table(results):
    rows = []
    for r in read(results, "range_summary.csv"):
        rows.append([r["system"], f"{int(r['dictionary_size']):,}" if len(r["dictionary_size"]) < 16
                     else f"{float(r['dictionary_size']):.1e}", r["first_missed_m"], r["missed20_m"], r["last_found_m"],
                     r["wrong"], paper(PAPER_RANGE, r["family"], 0), paper(PAPER_RANGE, r["family"], 1)])
    return table(["system", "dictionary", "first missed (m)", "20 % missed (m)", "last found (m)", "wrong ids",
                  "paper: first", "paper: 20 %"], rows)


def angle_table(results):
    rows = [[r["system"], r["first_missed_deg"], r["missed20_deg"], r["last_found_deg"], r["wrong"],
             paper(PAPER_ANGLE, r["family"])] for r in read(results, "angle_summary.csv")]
    return table(["system", "first missed (deg)", "20 % missed (deg)", "last found (deg)", "wrong ids",
                  "paper: first"], rows)


def blur_table(results):
    by_system = defaultdict(dict)
    for r in read(results, "blur_summary.csv"):
        by_system[r["system"]][float(r["blur_angle_deg"])] = float(r["max_fraction_all_found"])
    rows = []
    for system, angles in by_system.items():
        values = [angles[a] for a in sorted(angles)]
        rows.append([system] + [f"{100 * angles.get(a, float('nan')):.0f} %" for a in (0.0, 45.0, 90.0)]
                    + [f"{100 * min(values):.0f} %"])
    return table(["system", "0 deg (vertical)", "45 deg", "90 deg (horizontal)", "worst angle"], rows)


def pose_table(results):
    rows = []
    wanted = {("distance", "2"), ("distance", "10"), ("distance", "15"), ("tilt", "0"), ("tilt", "45"), ("tilt", "75")}
    by_system = defaultdict(dict)
    for r in read(results, "pose_summary.csv"):
        step = r["distance_m"] if r["sweep"] == "distance" else r["tilt_deg"]
        if (r["sweep"], step) in wanted and r["median_rotation_deg"] and r["median_translation_rel"]:
            by_system[r["system"]][(r["sweep"], step)] = (float(r["median_rotation_deg"]),
                                                          100 * float(r["median_translation_rel"]))
    order = [("distance", "2"), ("distance", "10"), ("distance", "15"), ("tilt", "0"), ("tilt", "45"), ("tilt", "75")]
    for system, steps in by_system.items():
        rows.append([system] + [f"{steps[s][0]:.3f} / {steps[s][1]:.3f}" if s in steps else "-" for s in order])
    return table(["system", "2 m", "10 m", "15 m", "3 m, tilt 0", "tilt 45", "tilt 75"], rows)


AMBIGUITY_RULES = [("lftag-3x3", "default"), ("lftag-3x3", "centroids"), ("lftag-3x3", "shapes"),
                   ("lftag-4x4", "default"), ("lftag-4x4", "centroids"), ("lftag-4x4", "shapes"),
                   ("apriltag-36h11-d1", "ippe-corners"), ("apriltag-36h11-d1", "estimate-tag-pose"),
                   ("apriltag-36h11-d2", "ippe-corners"), ("apriltag-36h11-d2", "estimate-tag-pose")]


def ambiguity_table(results, by, column="wrong_pct", condition="clean"):
    """`column` (wrong choices or flips, % of the markers found), tuning / validation, by size or by tilt."""
    other = "tilt_deg" if by == "size_px" else "size_px"
    cells = defaultdict(dict)
    steps = []
    for r in read(results, "ambiguity_summary.csv"):
        if r[other] or not r[by] or r["condition"] != condition:
            continue
        step = f"{float(r[by]):g}"
        if step not in steps:
            steps.append(step)
        cells[(r["system"], r["rule"])][(r["set"], step)] = r
    def cell(key, step):
        parts = []
        for s in ("tuning", "validation"):
            r = cells[key].get((s, step))
            parts.append(f"{float(r[column]):.1f}" if r and r[column] else "-")
        return " / ".join(parts)
    rows = [[f"{k[0]} {k[1]}"] + [cell(k, st) for st in steps] for k in AMBIGUITY_RULES if k in cells]
    unit = " px" if by == "size_px" else " deg"
    return table(["system, rule"] + [st + unit for st in steps], rows)


def ambiguity_size_table(results, condition="clean"):
    return ambiguity_table(results, "size_px", condition=condition)


def ambiguity_tilt_table(results, condition="clean"):
    return ambiguity_table(results, "tilt_deg", condition=condition)


def ambiguity_flips_table(results, condition="clean"):
    return ambiguity_table(results, "size_px", "flips_pct", condition)


def ambiguity_ratio_table(results, condition="clean"):
    """Both sets: the wrong choices (and flips) among the markers found, by the system's ratio."""
    counts = defaultdict(lambda: defaultdict(lambda: [0, 0, 0]))
    bins = []
    for r in read(results, "ambiguity_ratios.csv"):
        if r["condition"] != condition:
            continue
        b = (float(r["ratio_from"]), float(r["ratio_to"]) if r["ratio_to"] else None)
        if b not in bins:
            bins.append(b)
        c = counts[(r["system"], r["rule"])][b]
        c[0] += int(r["found"])
        c[1] += int(r["wrong"])
        c[2] += int(r["flips"])
    bins.sort(key=lambda b: b[0])
    header = ["system, rule"] + [f"{lo:g} to {hi:g}" if hi is not None else f"{lo:g} and over" for lo, hi in bins]
    rows = [[f"{k[0]} {k[1]}"] + [f"{counts[k][b][1]} ({counts[k][b][2]}) of {counts[k][b][0]}" for b in bins]
            for k in AMBIGUITY_RULES if k in counts]
    return table(header, rows)

def fp_table(results):
    totals = defaultdict(lambda: [0, 0, 0])
    for r in read(results, "fp_summary.csv"):
        t = totals[r["system"]]
        t[0] += int(r["frames"])
        t[1] += int(r["false_positives"])
        t[2] += int(r["frames_with_false_positives"])
    return table(["system", "frames", "false positives", "frames with any"],
                 [[s, f"{t[0]:,}", f"{t[1]:,}", f"{t[2]:,}"] for s, t in totals.items()])


def funnel_table(results):
    stages = ["regions", "topology", "area", "geometry", "angle", "collinearity", "residual", "unambiguous", "decoded",
              "second_looks", "second_look_found"]
    sums = defaultdict(float)
    for r in read(results, "fp_counters.csv"):
        sums[(r["system"], r["counter"])] += float(r["value"])
    systems = sorted({s for s, _ in sums if s.startswith("lftag-")})
    return table(["constraint"] + systems, [[stage] + [f"{int(sums[(s, stage)]):,}" for s in systems]
                                           for stage in stages])


def speed_table(results):
    rows = [r for r in read(results, "speed.csv")]
    keys = [("scenes", "1280"), ("video", "1280"), ("scenes", "1920"), ("video", "1920")]
    times = defaultdict(dict)
    for r in rows:
        times[r["system"]][(r["set"], r["width"])] = float(r["median_ms"])
    out = []
    for system, t in times.items():
        out.append([system] + [f"{t[k]:.2f}" if k in t else "-" for k in keys])
    return table(["system (ms per frame, median)", "scenes 720p", "video 720p", "scenes 1080p", "video 1080p"], out)


def stage_table(results):
    stages = ["threshold_ms", "regions_ms", "candidates_ms", "keypoints_ms", "hypotheses_ms", "decode_ms", "pose_ms",
              "second_look_ms", "total_ms"]
    values = defaultdict(dict)
    for r in read(results, "speed_counters.csv"):
        if r["set"] == "scenes" and r["system"] in ("lftag-3x3", "lftag-4x4"):
            values[(r["system"], r["width"])][r["counter"]] = float(r["per_frame"])
    columns = [("lftag-3x3", "1280"), ("lftag-4x4", "1280"), ("lftag-3x3", "1920")]
    label = {"1280": "720p", "1920": "1080p"}
    return table(["stage (mean ms per frame)"] + [f"{s} {label[w]}" for s, w in columns],
                 [[stage.removesuffix("_ms")] + [f"{values[c].get(stage, float('nan')):.3f}" for c in columns]
                  for stage in stages])


def throughput_table(results):
    rows = [[r["size"], r["variant"], r["fps"], r["ms_per_frame"], r["ms_over_identity"]]
            for r in read(results, "throughput.csv")]
    return table(["frame", "element", "frames per second", "ms per frame", "ms over identity"], rows)


def video_rows(results):
    by_system = defaultdict(dict)
    for r in read(results, "video_summary.csv"):
        by_system[r["system"]][(r["bin_kind"], r["bin"])] = r
    return by_system


def recall(text):
    """A recall in percent with one decimal, or two where one would round a miss up to 100."""
    value = float(text)
    return f"{value:.2f} %" if value < 100 and round(value, 1) >= 100 else f"{value:.1f} %"


def video_table(results):
    def number(text, digits):
        return f"{float(text):.{digits}f}" if text else "-"

    rows = []
    for system, bins in video_rows(results).items():
        r = bins.get(("all", "all"))
        if r:
            rows.append([system, f"{int(r['markers']):,}", f"{int(r['found']):,}", recall(r['recall_pct']),
                         r["wrong"], number(r["median_translation_pct"], 3), number(r["p90_translation_pct"], 3),
                         number(r["median_rotation_deg"], 3)])
    return table(["system", "markers", "found", "recall", "wrong", "translation error median (% of distance)",
                  "p90", "rotation error median (deg)"], rows)


def video_bins_table(results):
    by_system = video_rows(results)
    # The bins in the order the file gives them, edges first, then tilts.
    bins = list(dict.fromkeys(k for b in by_system.values() for k in b if k[0] != "all"))
    unit = {"edge_px": "px", "tilt_deg": "deg"}
    rows = []
    for system, b in by_system.items():
        rows.append([system] + [recall(b[k]['recall_pct']) if k in b and b[k]["recall_pct"] else "-"
                                for k in bins])
    counts = next(iter(by_system.values()), {})
    header = [f"{name} {unit.get(kind, kind)} ({int(counts[(kind, name)]['markers']):,})" if (kind, name) in counts
              else f"{name} {unit.get(kind, kind)}" for kind, name in bins]
    return table(["system (recall; markers per bin)"] + header, rows)


def adversarial_table(results):
    def value(r, key, spec):
        # Files of runs before a column existed (docs/results' adversarial.csv predates the
        # deadline's columns) show "-" there.
        return format(float(r[key]), spec) if r.get(key) else "-"

    rows = []
    for r in read(results, "adversarial.csv"):
        found = f"{r['found']}/{r['markers']}" + ("" if r["all_found"] == "1" else " (missed)")
        rows.append([r["config"], r["variant"], value(r, "median_ms", ".1f"), value(r, "mean_ms", ".1f"),
                     value(r, "p99_ms", ".1f"), value(r, "max_ms", ".1f"), value(r, "ratio", ".1f"),
                     value(r, "candidates", ",.0f"), value(r, "examined", ",.0f"),
                     value(r, "skipped_by_budget", ",.0f"), value(r, "past_deadline", ".2f"), found, r["wrong"]])
    return table(["set-up", "frame", "median ms", "mean ms", "p99 ms", "max ms", "x ordinary", "candidates",
                  "examined", "skipped by budget", "frames cut by deadline", "markers found", "other detections"],
                 rows)


FIELD_CONDITIONS = ["plain", "shadow", "motion", "pillbox", "barrel", "low-light", "bayer", "bent", "small-1080p",
                    "crowded", "occlusion", "h264", "h264-1080p"]
FIELD_SETS = ["tuning", "validation"]


def field_rows(results):
    """field_summary.csv by (system, set, condition, subset), systems in file order."""
    rows, systems = {}, []
    for r in read(results, "field_summary.csv"):
        rows[(r["system"], r["set"], r["condition"], r["subset"])] = r
        if r["system"] not in systems:
            systems.append(r["system"])
    conditions = [c for c in FIELD_CONDITIONS + ["all"] if any(k[2] == c for k in rows)]
    return rows, systems, conditions


def tuned_validated(rows, system, condition, subset, cell):
    """One cell per set, "tuning / validation"; "-" where a set has no such markers."""
    values = [cell(rows[k]) if (k := (system, s, condition, subset)) in rows else "-" for s in FIELD_SETS]
    return " / ".join(values)


def field_recall_table(results):
    rows, systems, conditions = field_rows(results)
    def cell(r):
        return f"{float(r['recall_pct']):.1f}"
    header = ["system (recall %, tuning / validation)"]
    for c in conditions:
        counts = [rows[k]["markers"] for s in FIELD_SETS
                  if (k := (systems[0], s, c, "visible")) in rows] if systems else []
        header.append(f"{c} ({' / '.join(counts)})")
    return table(header, [[system] + [tuned_validated(rows, system, c, "visible", cell) for c in conditions]
                          for system in systems])


def field_apart_table(results):
    rows, systems, _ = field_rows(results)
    def cell(r):
        return f"{r['found']}/{r['markers']}"
    return table(["system (found / markers, tuning / validation)", "crowded: cut by the frame edge",
                  "occlusion: occluded"],
                 [[system, tuned_validated(rows, system, "crowded", "cut", cell),
                   tuned_validated(rows, system, "occlusion", "occluded", cell)] for system in systems])


def field_wrong_table(results):
    rows, systems, conditions = field_rows(results)
    def wrong(system, s, c):
        return sum(int(r["wrong"]) for k, r in rows.items() if k[0] == system and k[1] == s and k[2] == c)
    return table(["system (wrong ids, tuning / validation)"] + conditions,
                 [[system] + [f"{wrong(system, 'tuning', c)} / {wrong(system, 'validation', c)}" for c in conditions]
                  for system in systems])


def field_fp_table(results):
    rows, systems = {}, []
    for r in read(results, "field_fp.csv"):
        rows[(r["system"], r["set"], r["condition"])] = r
        if r["system"] not in systems:
            systems.append(r["system"])
    conditions = [c for c in FIELD_CONDITIONS if any(k[2] == c for k in rows)]
    def cell(system, c):
        values = [rows[k]["false_positives"] if (k := (system, s, c)) in rows else "-" for s in FIELD_SETS]
        return " / ".join(values)
    frames = [sum(int(r["frames"]) for k, r in rows.items() if k[0] == systems[0] and k[1] == s) for s in FIELD_SETS]
    return table([f"system (false positives in {frames[0]} / {frames[1]} marker-free frames)"] + conditions,
                 [[system] + [cell(system, c) for c in conditions] for system in systems])


def field_pose_table(results):
    rows, systems, conditions = field_rows(results)
    def cell(r):
        if not r["median_translation_pct"]:
            return "-"
        return f"{float(r['median_translation_pct']):.2f} % {float(r['median_rotation_deg']):.2f}°"
    return table(["system (median translation error, % of distance, and rotation error; tuning / validation)"]
                 + conditions,
                 [[system] + [tuned_validated(rows, system, c, "visible", cell) for c in conditions]
                  for system in systems])


def field_p90_table(results):
    rows, systems, _ = field_rows(results)
    def cell(key, digits):
        return lambda r: f"{float(r[key]):.{digits}f}" if r[key] else "-"
    return table(["system (visible markers of every condition; tuning / validation)", "markers", "found",
                  "median translation (%)", "p90 translation (%)", "median rotation (deg)", "p90 rotation (deg)"],
                 [[system, tuned_validated(rows, system, "all", "visible", lambda r: r["markers"]),
                   tuned_validated(rows, system, "all", "visible", lambda r: r["found"]),
                   tuned_validated(rows, system, "all", "visible", cell("median_translation_pct", 3)),
                   tuned_validated(rows, system, "all", "visible", cell("p90_translation_pct", 3)),
                   tuned_validated(rows, system, "all", "visible", cell("median_rotation_deg", 3)),
                   tuned_validated(rows, system, "all", "visible", cell("p90_rotation_deg", 3))] for system in systems])


def field_both_found_table(results, peer="apriltag-36h11-d1"):
    """Median translation error of each LFTag family and of `peer` on the marker-frames
    both found (the same poses; each system sees its own markers), from field.csv."""
    found = defaultdict(dict)  # (set, condition, clip, frame, marker) -> system -> error
    for r in read(results, "field.csv"):
        if r["subset"] == "visible" and r["found"] == "1" and r["wrong"] == "0":
            found[(r["set"], r["condition"], r["clip"], r["frame"], r["marker"])][r["system"]] = \
                float(r["translation_error_pct"])
    if not found:
        return "(field.csv not in this results directory)"
    systems = sorted({s for v in found.values() for s in v if s.startswith("lftag-")})
    conditions = [c for c in FIELD_CONDITIONS if any(k[1] == c for k in found)]
    def cell(system, condition):
        out = []
        for st in FIELD_SETS:
            pairs = [(v[system], v[peer]) for k, v in found.items()
                     if k[0] == st and k[1] == condition and system in v and peer in v]
            out.append(f"{statistics.median(a for a, _ in pairs):.3f} vs {statistics.median(b for _, b in pairs):.3f}"
                       f" ({len(pairs)})" if pairs else "-")
        return " / ".join(out)
    return table([f"system (median translation error, % of distance, LFTag vs {peer}, on the markers both found "
                  "(how many); tuning / validation)"] + conditions,
                 [[system] + [cell(system, c) for c in conditions] for system in systems])


def field_times_table(results, name="field_times.csv"):
    times, systems = {}, []
    for r in read(results, name):
        if r["set"] == "both":
            times[(r["system"], r["condition"])] = r
            if r["system"] not in systems:
                systems.append(r["system"])
    conditions = [c for c in FIELD_CONDITIONS if any(k[1] == c for k in times)]
    def cell(system, c):
        r = times.get((system, c))
        return (f"{float(r['mean_ms']):.1f} / {float(r['median_ms']):.1f} / {float(r['p99_ms']):.1f}" if r
                else "-")
    return table(["system (ms per frame, one thread: mean / median / p99, both sets)"] + conditions,
                 [[system] + [cell(system, c) for c in conditions] for system in systems])


def field_ratio_table(results):
    """LFTag's frame times over AprilTag 36h11 decimate 2's, measured in the same run."""
    times = {(r["system"], r["condition"]): r for r in read(results, "field_times.csv") if r["set"] == "both"}
    systems = [s for s in dict.fromkeys(k[0] for k in times) if s.startswith("lftag")]
    conditions = [c for c in FIELD_CONDITIONS if any(k[1] == c for k in times)]
    def cell(system, c):
        r, base = times.get((system, c)), times.get(("apriltag-36h11-d2", c))
        if not r or not base:
            return "-"
        return (f"{float(r['mean_ms']) / float(base['mean_ms']):.2f} / "
                f"{float(r['p99_ms']) / float(base['p99_ms']):.2f}")
    return table(["system (mean / p99 over AprilTag d2's, same run)"] + conditions,
                 [[system] + [cell(system, c) for c in conditions] for system in systems])


def tracking_recall_table(results):
    def f(v, fmt="{:.1f}"):
        return fmt.format(float(v)) if v not in ("", None) else "-"
    rows = [[r["system"], r["source"], r["set"], r["markers"], f(r["recall_per_frame_pct"]),
             f(r["recall_tracked_pct"]), r["found_predicted"] or "-", r["predicted_off_target"] or "-",
             f"{r['wrong_per_frame']} / {r['wrong_tracked'] or '-'}",
             f"{f(r['wrong_choice_off_pct'])} / {f(r['wrong_choice_on_pct'])}",
             f"{f(r.get('recall_sparse_pct'))} / {r.get('wrong_sparse') or '-'}"]
            for r in read(results, "tracking_summary.csv") if r["condition"] == "all"]
    return table(["system", "clips", "set", "markers", "recall per frame %", "tracked % (measured + predicted)",
                  "predicted on target", "predicted off target", "wrong ids off / on",
                  "wrong pose choices % off / on", "full search every 10th frame: tracked % / wrong ids"], rows)


def tracking_jitter_table(results):
    rows = [[r["system"], r["source"], r["set"], r["pose"], r["pairs"],
             " / ".join(f"{float(r[k]):.2f}" for k in ("mean_rotation_deg", "p95_rotation_deg", "p99_rotation_deg")),
             " / ".join(f"{float(r[k]):.2f}" for k in ("mean_translation_mm", "p95_translation_mm",
                                                         "p99_translation_mm")),
             " / ".join(f"{float(r[k]):.3f}" for k in ("mean_translation_pct", "p95_translation_pct",
                                                         "p99_translation_pct"))]
            for r in read(results, "tracking_jitter.csv") if r["pairs"] not in ("", "0")]
    return table(["system", "clips", "set", "pose", "frame pairs", "rotation change error deg (mean / p95 / p99)",
                  "translation change error mm", "translation change error % of distance"], rows)


def tracking_times_table(results):
    def f(v):
        return f"{float(v):.2f}" if v else "-"
    rows = [[r["system"], r["source"], r["set"], r["tracking"], r["frames"], f(r["mean_ms"]), f(r["p99_ms"]),
             f(r["mean_over_peer"]), f(r["p99_over_peer"])] for r in read(results, "tracking_times.csv")]
    return table(["system", "clips", "set", "tracking", "frames", "mean ms", "p99 ms", "mean / AprilTag d2's",
                  "p99 / AprilTag d2's"], rows)


def main(results):
    results = Path(results)
    for title, make in [("Range", range_table), ("Grazing angle", angle_table), ("Motion blur", blur_table),
                        ("Pose (median rotation deg / translation % of distance)", pose_table),
                        ("Wrong pose choices by size (% of found; tuning / validation)", ambiguity_size_table),
                        ("Wrong pose choices by tilt (% of found; tuning / validation)", ambiguity_tilt_table),
                        ("Wrong pose choices more than 10 deg off, by size (% of found; tuning / validation)",
                         ambiguity_flips_table),
                        ("Wrong pose choices by ambiguity ratio (both sets)", ambiguity_ratio_table),
                        ("Webcam: wrong pose choices by size", lambda r: ambiguity_size_table(r, "webcam")),
                        ("Webcam: wrong pose choices by tilt", lambda r: ambiguity_tilt_table(r, "webcam")),
                        ("Webcam: flips by size", lambda r: ambiguity_flips_table(r, "webcam")),
                        ("Webcam: wrong pose choices by ambiguity ratio", lambda r: ambiguity_ratio_table(r, "webcam")),
                        ("False positives", fp_table), ("Funnel", funnel_table), ("Speed", speed_table),
                        ("Stages", stage_table), ("Throughput", throughput_table), ("Video", video_table),
                        ("Video recall by projected edge and tilt", video_bins_table),
                        ("Adversarial frames", adversarial_table),
                        ("Field recall (visible markers; tuning / validation)", field_recall_table),
                        ("Field: cut and occluded markers, reported apart", field_apart_table),
                        ("Field wrong ids", field_wrong_table),
                        ("Field false positives: the clips' marker-free twins (blank sheets)", field_fp_table),
                        ("Field pose error by condition", field_pose_table),
                        ("Field pose error, all conditions", field_p90_table),
                        ("Field pose error on the markers both found", field_both_found_table),
                        ("Field frame times", field_times_table),
                        ("Field frame times over AprilTag 36h11 decimate 2's", field_ratio_table),
                        ("Tracking: recall and wrong choices, tracking off / on", tracking_recall_table),
                        ("Tracking: jitter (error of the frame-to-frame pose change)", tracking_jitter_table),
                        ("Tracking: frame times, tracking off / on", tracking_times_table)]:
        print(f"### {title}\n\n{make(results)}\n")


if __name__ == "__main__":
    main(sys.argv[1])
