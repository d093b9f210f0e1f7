"""Benchmark: how fast a bad command line is refused, against `robstiff
--help` measured in the same run (the reference: argument parsing only).

A mistyped file name or a bad argument should come back as fast as --help
(issue 23: a missing campaign took 1.5 s, Drake imported first).  Each
command runs as its own process (the console script), ``REPEATS`` times;
the median wall time is the figure, printed with its ratio to two
references measured in the same run: `robstiff --help` (argument parsing
only) and a Python process that imports numpy (the floor of any check that
reads a number array, io.py's output checks for one).  Target: every case
within 2x the numpy reference (no scipy, no Drake before the error).
Prints PASS/FAIL per case; exit status 1 when a target is missed.  Which
modules were imported is held by tests/test_fast_errors.py (no pydrake in
sys.modules when the error comes), not by a time.
Run: python3 benchmarks/bench_bad_input.py
"""

import shutil
import statistics
import subprocess
import sys
import tempfile
import time
from pathlib import Path

REPEATS = 5
TARGET_RATIO = 2.0  # of the numpy reference
NUMPY_REFERENCE = "python -c 'import numpy' (reference)"
CASES = [
    ("a missing campaign (identify missing.csv)", ["identify", "missing.csv"]),
    ("a missing scenario (simulate no_such)", ["simulate", "no_such"]),
    ("a bad period list (sweep block.yaml --period-ms 4,x)", ["sweep", "block.yaml", "--period-ms", "4,x"]),
    ("a missing run folder (diagnose-run nope)", ["diagnose-run", "nope"]),
    ("a bad replay name (simulate block.yaml --replay r.png)", ["simulate", "block.yaml", "--replay", "r.png", "--out", "o"]),
    ("an argument out of range (kg-study --grid 30)", ["kg-study", "--grid", "30"]),
]


def robstiff():
    exe = shutil.which("robstiff") or str(Path(sys.executable).parent / "robstiff")
    return [exe] if Path(exe).exists() else [sys.executable, "-m", "robstiff_drake"]


def timed(argv, cwd, expect, command=None):
    times = []
    for _ in range(REPEATS):
        t0 = time.perf_counter()
        proc = subprocess.run((command or robstiff()) + argv, cwd=cwd, capture_output=True, text=True)
        times.append(time.perf_counter() - t0)
        if proc.returncode != expect:
            raise SystemExit(f"{argv}: exit status {proc.returncode}, expected {expect}: {proc.stderr.strip()}")
    return statistics.median(times)


def main():
    import os

    print(f"load average: {os.getloadavg()[0]:.2f}")
    failed = 0
    with tempfile.TemporaryDirectory() as cwd:
        # the block test's scenario by its path (as every version of the command takes it)
        shutil.copy(Path(__file__).resolve().parents[1] / "diagrams" / "block_milling.yaml", Path(cwd) / "block.yaml")
        print(f"robstiff: {' '.join(robstiff())}")
        ref = timed(["--help"], cwd, 0)
        python = [str(Path(robstiff()[0]).parent / "python")] if robstiff()[0] != sys.executable else [sys.executable]
        floor = timed(["-c", "import numpy"], cwd, 0, command=python)
        print(f"{'robstiff --help (reference)':62s} {ref * 1e3:7.0f} ms")
        print(f"{NUMPY_REFERENCE:62s} {floor * 1e3:7.0f} ms")
        for what, argv in CASES:
            t = timed(argv, cwd, 2)
            ok = t <= TARGET_RATIO * floor
            failed += not ok
            print(f"{what:62s} {t * 1e3:7.0f} ms  {t / ref:4.1f}x --help  {t / floor:4.1f}x numpy  "
                  f"{'PASS' if ok else 'FAIL'} (target <= {TARGET_RATIO:g}x numpy)")
    return 1 if failed else 0


if __name__ == "__main__":
    sys.exit(main())
