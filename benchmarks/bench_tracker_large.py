"""Benchmark: `robstiff diagnose` and `robstiff identify` on a large
laser-tracker campaign (default 100,000 rows, tests/tracker_world.py's
Drake plant of a perturbed IRB 6400), each as a separate process with its
standard error going to a file (no terminal: the progress is log lines),
beside the reference of the same run: a process that reads the file and
registers it on the nominal arm (what every diagnosis starts with).

Prints per command: wall time, CPU time (user + system: less moved by
the other jobs on this shared machine than the wall time), peak resident
memory, the progress lines it wrote, and the ratios to the reference.
Targets: each command within 60 s of CPU and 1 GB (reported before these
changes on this machine: diagnose 288 s and 1.9 GB, identify 500 s and
1.7 GB) -- on a loaded machine judge by the CPU time and the ratio; exit
status 1 when a target is missed.  (About 4 minutes in all on a quiet
machine: --rows 20000 for a quick look.)

    python benchmarks/bench_tracker_large.py
    python benchmarks/bench_tracker_large.py --rows 20000
"""

import argparse
import os
import subprocess
import sys
import tempfile
import time
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]
TARGET_S, TARGET_MB = 60.0, 1024.0

REFERENCE = """
import sys
from robstiff_drake.identification.tracker import diagnosis as td
from robstiff_drake.identification.tracker.campaign import read_tracker_campaign
from robstiff_drake.io import Warnings
from robstiff_drake.model.robot import load_robot
robot = load_robot("irb6400")
td._prepare(robot, read_tracker_campaign(sys.argv[1], robot), None, Warnings(quiet=True))
"""


def run(cmd, log):
    """(wall s, CPU s, peak MB, exit status) of a child process."""
    t0 = time.perf_counter()
    with open(log, "w") as err:
        proc = subprocess.Popen(cmd, cwd=ROOT, stdout=subprocess.DEVNULL, stderr=err)
        _, status, ru = os.wait4(proc.pid, 0)
    wall = time.perf_counter() - t0
    return wall, ru.ru_utime + ru.ru_stime, ru.ru_maxrss / 1024.0, os.waitstatus_to_exitcode(status)


def main(argv=None):
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--rows", type=int, default=100000)
    ap.add_argument("--commands", default="diagnose,identify")
    args = ap.parse_args(argv)
    sys.path.insert(0, str(ROOT / "tests"))
    import tracker_world as tw
    from robstiff_drake.model.robot import load_robot

    with tempfile.TemporaryDirectory() as tmp:
        data = Path(tmp) / "tracker.csv"
        data.write_text(tw.make_tracker_campaign(load_robot("irb6400"), 7, n=args.rows, noise_mm=0.03).csv_text)
        ref = run([sys.executable, "-c", REFERENCE, str(data)], Path(tmp) / "ref.err")
        print(f"{args.rows} rows; reference (read + register): wall {ref[0]:.1f} s, CPU {ref[1]:.1f} s, "
              f"peak {ref[2]:.0f} MB")
        ok = True
        for name in args.commands.split(","):
            log = Path(tmp) / f"{name}.err"
            wall, cpu, mb, code = run([sys.executable, "-m", "robstiff_drake", name, str(data), "--robot", "irb6400",
                                       "--json", str(Path(tmp) / f"{name}.json")], log)
            lines = [ln for ln in log.read_text().splitlines() if "tracker diagnosis:" in ln]
            print(f"{name}: exit {code}; wall {wall:.1f} s ({wall / ref[0]:.1f} x the reference), CPU {cpu:.1f} s "
                  f"({cpu / ref[1]:.1f} x), peak {mb:.0f} MB ({mb / ref[2]:.1f} x); {len(lines)} progress lines"
                  + (f", the last: {lines[-1]}" if lines else ""))
            ok = ok and code == 0 and cpu <= TARGET_S and mb <= TARGET_MB
    load = os.getloadavg()
    print(f"load average {load[0]:.2f} {load[1]:.2f} {load[2]:.2f} (2 cores)")
    print(f"{'PASS' if ok else 'FAIL'}: targets CPU <= {TARGET_S:g} s and peak <= {TARGET_MB:g} MB per command")
    return 0 if ok else 1


if __name__ == "__main__":
    sys.exit(main())
