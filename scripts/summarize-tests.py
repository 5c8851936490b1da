#!/usr/bin/env python3
"""Counts test cases in meson's logs and prints "N passed, N failed".

    summarize-tests.py [--failed N] [LOG_DIR...]     (default: build/meson-logs)

Every GoogleTest case and gst-check case counts once, as does every fuzz target in a
JUnit file written by scripts/fuzz.sh. A test program that failed without reporting a
failing case (a crash, a timeout) counts as one failure; --failed adds N failures of
runs that left no log (a build that failed). Exits non-zero when anything failed or
nothing ran."""
import json
import sys
import xml.etree.ElementTree as ET
from pathlib import Path

args = sys.argv[1:]
failed = 0
if args[:1] == ["--failed"]:
    failed, args = int(args[1]), args[2:]
passed = 0

for logs in [Path(a) for a in args] or [Path("build/meson-logs")]:
    failing_programs = set()
    junit = logs / "testlog.junit.xml"
    if junit.exists():
        for suite in ET.parse(junit).getroot().iter("testsuite"):
            for case in suite.iter("testcase"):
                if case.find("skipped") is not None:
                    continue
                if case.find("failure") is not None or case.find("error") is not None:
                    failed += 1
                    failing_programs.add(suite.get("name", ""))
                else:
                    passed += 1

    results = logs / "testlog.json"
    if results.exists():
        for line in results.read_text().splitlines():
            test = json.loads(line)
            if test.get("result") in ("OK", "SKIP", "EXPECTEDFAIL"):
                continue
            prefix = f"{test.get('project', 'lftag')}.{test['name']}"
            if not any(name == prefix or name.startswith(prefix + ".") for name in failing_programs):
                failed += 1  # failed without naming a case

print(f"{passed} passed, {failed} failed")
sys.exit(1 if failed or passed == 0 else 0)
