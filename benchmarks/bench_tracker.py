"""Benchmark: `robstiff diagnose` on a 12,000-row laser-tracker campaign
(absolute positions) made by Drake's perturbed plant (tests/tracker_world.py:
an IRB 6400 with joint offsets, link length and twist errors, sag through
compliant joints, a drifting tracker, 0.03 mm noise), beside the reference
of the same run: reading the file and registering it on the nominal arm
(the declared model, what every diagnosis starts with).

The diagnosis: the identifiable set by the Jacobian's rank, the search over
the effects in two linearised passes, the final Gauss-Newton, the held-out
errors by Gauss-Newton in 5 grouped folds before and after, the
non-parametric residual map nested in the folds.

Target: 12,000 rows in at most 30 s on this 2-core machine (shared with
other jobs: the load average is printed with the figures).  Prints the
median of ``--repeats`` runs, the reference, their ratio, the held-out 3D
error before/after, and PASS/FAIL (exit status 1 on FAIL).
Run: python3 benchmarks/bench_tracker.py
"""

import argparse
import os
import statistics
import sys
import tempfile
import time
from pathlib import Path

from robstiff_drake.identification.tracker import diagnosis as td
from robstiff_drake.identification.tracker.campaign import read_tracker_campaign
from robstiff_drake.io import Warnings
from robstiff_drake.model.robot import load_robot

sys.path.insert(0, str(Path(__file__).resolve().parents[1] / "tests"))
import tracker_world as tw  # noqa: E402

TARGET_S = 30.0
ROWS = 12000


def median_s(fn, repeats):
    samples = []
    for _ in range(repeats):
        t0 = time.perf_counter()
        out = fn()
        samples.append(time.perf_counter() - t0)
    return statistics.median(samples), out


def main():
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--repeats", type=int, default=3)
    ap.add_argument("--rows", type=int, default=ROWS)
    args = ap.parse_args()
    robot = load_robot("irb6400")
    world = tw.make_tracker_campaign(robot, 7, n=args.rows, noise_mm=0.03)
    with tempfile.TemporaryDirectory() as tmp:
        path = Path(tmp) / "tracker.csv"
        path.write_text(world.csv_text)

        def reference():
            camp = read_tracker_campaign(path, robot)
            return td._prepare(robot, camp, None, Warnings(quiet=True))

        def diagnosis():
            return td.diagnose_tracker(robot, read_tracker_campaign(path, robot), noise_mm=0.03)

        t_ref, _ = median_s(reference, args.repeats)
        t_diag, d = median_s(diagnosis, args.repeats)
    e = d.report["error_3d_mm"]
    load = os.getloadavg()
    print(f"{args.rows} rows (Drake plant: geometry, sag, drift; planted {', '.join(world.true['effects'])})")
    print(f"diagnose {t_diag:7.2f} s   read + register {t_ref:6.2f} s   ratio {t_diag / t_ref:5.1f}")
    print(f"held-out 3D error mean {e['before']['mean']:.4f} -> {e['after']['mean']:.4f} mm, max "
          f"{e['before']['max']:.4f} -> {e['after']['max']:.4f} mm; effects found: "
          f"{', '.join(d.report['selected_effects'])}")
    print(f"load average during the run: {load[0]:.2f} {load[1]:.2f} {load[2]:.2f} (2 cores)")
    ok = t_diag <= TARGET_S
    print(f"target <= {TARGET_S:g} s: {'PASS' if ok else 'FAIL'}")
    return 0 if ok else 1


if __name__ == "__main__":
    sys.exit(main())
