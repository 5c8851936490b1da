# SPDX-License-Identifier: LGPL-2.1-or-later
"""The cases of a Python test, run in order and reported as TAP.

    from tap import case, run

    @case
    def something_holds():
        assert ...

    run_cases()
"""
import sys
import traceback

_CASES = []


def case(function):
    _CASES.append(function)
    return function


def run_cases():
    """Runs every case (a failure does not stop the next), then exits 1 if any failed."""
    print(f"1..{len(_CASES)}", flush=True)
    failed = 0
    for number, function in enumerate(_CASES, 1):
        try:
            function()
            print(f"ok {number} - {function.__name__}", flush=True)
        except Exception:  # noqa: BLE001 - every failure is reported, then the next case runs
            failed += 1
            print(f"not ok {number} - {function.__name__}", flush=True)
            for line in traceback.format_exc().splitlines():
                print("# " + line, flush=True)
            # Also on stderr: meson's --print-errorlogs shows a TAP test's stderr, not its stdout.
            print(f"{function.__name__} failed:\n{traceback.format_exc()}", file=sys.stderr, flush=True)
    raise SystemExit(1 if failed else 0)
