#!/usr/bin/python3
# SPDX-License-Identifier: LGPL-2.1-or-later
"""meson test 'bench:misses': bench/misses.py accounts for every miss of a field run.

    test_misses.py LFTAG_BENCH LFTAG WORK_DIR

Runs the field experiment's acceptance plan on its motion clips for LFTag 4x4, saving
the frames it missed markers in, then misses.py on them, and fails unless misses.py
names a stage for every missed marker (its tally sums to the misses of field.csv, and
there are some: the plan's motion clips hold markers blurred past reading).
"""
import csv
import re
import subprocess
import sys
from pathlib import Path

bench, lftag, work = sys.argv[1], sys.argv[2], Path(sys.argv[3])
results, frames = work / "results", work / "misses"
subprocess.run([bench, "field", "--acceptance", "--conditions", "motion", "--systems", "lftag-4x4", "--threads", "2",
                "--out", str(results), "--save-misses", str(frames)], check=True, stdout=subprocess.DEVNULL)
with open(results / "field.csv", newline="") as f:
    missed = sum(1 for r in csv.DictReader(f) if r["subset"] == "visible" and r["found"] == "0")
out = subprocess.run([sys.executable, str(Path(__file__).with_name("misses.py")), str(results), str(frames),
                      "lftag-4x4", "--lftag", lftag], check=True, capture_output=True, text=True).stdout
print(out)
lines = out.splitlines()
header = lines.index(f"{missed} misses of lftag-4x4:")
tally = [int(re.match(r"\s*(\d+)\s", line).group(1)) for line in lines[header + 1:]]
per_miss = [line for line in lines[:header] if re.search(r": (outline read|candidate|border proposal): |: never proposed$", line)]
if missed == 0 or sum(tally) != missed or len(per_miss) != missed:
    sys.exit(f"test_misses: {missed} misses in field.csv, {len(per_miss)} lines and a tally of {sum(tally)}")
print(f"test_misses: every one of {missed} misses placed")
