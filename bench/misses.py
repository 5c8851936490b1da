#!/usr/bin/python3
# SPDX-License-Identifier: LGPL-2.1-or-later
"""Where the detector stopped on each marker a field run missed.

    misses.py RESULTS_DIR MISSES_DIR SYSTEM [--lftag PATH] [--set tuning|validation]

RESULTS_DIR and MISSES_DIR are the `--out` and `--save-misses` directories of one
`lftag-bench field` run that included SYSTEM (an LFTag system: lftag-3x3, lftag-4x4, ...).
Each saved frame is detected again with `lftag detect --why` (no deadline, the clip's
focal length), and each visible marker the run missed is matched with what the trace
shows at its place (within half its edge of its centre): the outline read that got
furthest, else the topological candidate that got furthest, else the border proposal,
else nothing. Prints one line per miss and then how many misses stopped at each stage:
the figures docs/BENCHMARKS.md quotes as "stop at the border proposal", "at an alignment
that does not converge", and so on.
"""
import argparse
import csv
import json
import math
import subprocess
import sys
from collections import Counter
from pathlib import Path

# Stage names (lftag/trace.hpp) in the order a detection passes them: a trace entry that
# got further is the one that says where the marker was lost.
ORDER = ["budget", "deadline", "area", "geometry", "angle", "collinearity", "border", "alignment", "structure",
         "contrast", "baselines", "resolution", "decoding", "margin", "ink", "marker", "unexpected", "pose",
         "duplicate", "detected"]


def furthest(entries, key):
    entries = [e for e in entries if e.get(key) in ORDER]
    return max(entries, key=lambda e: ORDER.index(e[key]), default=None)


def centre(outline):
    return (sum(p[0] for p in outline) / len(outline), sum(p[1] for p in outline) / len(outline))


def main():
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("results")
    parser.add_argument("misses")
    parser.add_argument("system")
    parser.add_argument("--lftag", default=str(Path(__file__).resolve().parent.parent / "build" / "src" / "lftag"))
    parser.add_argument("--set", choices=["tuning", "validation"])
    args = parser.parse_args()
    if not args.system.startswith("lftag-"):
        sys.exit(f"misses.py: {args.system} is not an LFTag system (lftag-3x3, lftag-4x4, ...)")
    family = args.system.split("-")[1]
    results, misses = Path(args.results), Path(args.misses)

    focal = {}
    with open(results / "field_clips.csv", newline="") as f:
        for clip in csv.DictReader(f):
            focal[(clip["set"], clip["condition"], clip["clip"])] = clip["fx"]
    with open(results / "field.csv", newline="") as f:
        missed = [r for r in csv.DictReader(f)
                  if r["system"] == args.system and r["subset"] == "visible" and r["found"] == "0"
                  and (args.set is None or r["set"] == args.set)]

    traces = {}
    tally = Counter()
    for r in missed:
        frame = misses / f"{args.system}-field-{r['set']}-{r['condition']}-clip{r['clip']}-frame{r['frame']}.png"
        if not frame.exists():
            sys.exit(f"misses.py: {frame} is missing (was the run made with --save-misses {misses}?)")
        if frame not in traces:
            command = [args.lftag, "detect", "--why", "--deadline", "0", "--family", family,
                       "--fx", focal[(r["set"], r["condition"], r["clip"])], str(frame)]
            out = subprocess.run(command, check=True, capture_output=True, text=True).stdout
            traces[frame] = json.loads(out.splitlines()[0])
        trace = traces[frame]
        x, y, edge = float(r["x"]), float(r["y"]), float(r["edge_px"])

        def near(point):
            return math.hypot(point[0] - x, point[1] - y) < edge / 2

        read = furthest([o for o in trace["outline_reads"] if near(centre(o["outline"]))], "stage")
        candidate = furthest([c for c in trace["candidates"] if near(c["center"])], "stage")
        proposal = furthest([b for b in trace["borders"] if near(centre(b["outline"]))], "stage")
        if read:
            where = "outline read: " + read["stage"]
        elif candidate:
            where = "candidate: " + candidate["stage"]
        elif proposal:
            where = "border proposal: " + proposal["stage"]
        else:
            where = "never proposed"
        tally[where] += 1
        blur = f", blur {float(r['blur_px']):.1f} px" if r.get("blur_px") else ""
        print(f"{r['set']} {r['condition']} clip {r['clip']} frame {r['frame']} marker {r['marker']} "
              f"({float(r['edge_px']):.0f} px, tilt {float(r['tilt_deg']):.0f} deg{blur}): {where}")
    print(f"{len(missed)} misses of {args.system}:")
    for where, count in tally.most_common():
        print(f"  {count:4d}  {where}")


if __name__ == "__main__":
    main()
