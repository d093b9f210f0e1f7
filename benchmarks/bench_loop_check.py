"""Benchmark: `robstiff compensate`'s loop check (cell/loop_guard.py over
model/loop_check.py) at the block test's start pose on the IRB 6400, with
compensate's defaults (4 ms period, 1 kHz sensor, no extra delay, a
2nd-order low-pass) at the new default cutoff (2 Hz: one verdict) and at
the old one (10 Hz: refused, with the search for the largest stable
cutoff), beside one spectral radius of the loop model (its unit of work)
measured in the same run.

Prints, per cutoff, the spectral radius per period in air and cutting at
the check's 2 % damping margin and at the assumed 5 %, the verdict, the
largest stable cutoff, and the check's wall time (median of the repeats)
with its ratio to one radius.  Target: the check under 1 s (the time
compensate spends before it opens a socket).  Exit status 1 when missed.

    python benchmarks/bench_loop_check.py [--repeats 5]

The machine is shared (2 cores): the load average is printed with the
figures.
"""

import argparse
import os
import statistics
import sys
import time

import numpy as np

from robstiff_drake.cell.loop_guard import LoopGuard, feed_direction
from robstiff_drake.diagrams.milling_cell import planned_path
from robstiff_drake.diagrams.scenario import load_scenario
from robstiff_drake.errors import InputError
from robstiff_drake.identification.threads import single_blas_thread
from robstiff_drake.model import loop_check
from robstiff_drake.model.filters import lowpass_coefficients
from robstiff_drake.model.robot import load_robot
from robstiff_drake.paths import DIAGRAMS_DIR

TARGET_S = 1.0
RATE_HZ, PERIOD_S = 1000.0, 0.004  # compensate's defaults


def main():
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--repeats", type=int, default=5)
    args = ap.parse_args()
    robot = load_robot()
    tool = robot.payload.tool_point_m
    sc = load_scenario(DIAGRAMS_DIR / "block_milling.yaml")
    _, _, q_ref = planned_path(sc, robot, tool)
    q0_deg = np.degrees(robot.joint_map.to_controller(q_ref[0]))
    feed = feed_direction(robot, tool, q_ref)
    print(f"IRB 6400, the block test's start {np.round(q0_deg, 2).tolist()} deg, feed {np.round(feed, 3).tolist()}; "
          f"period {PERIOD_S * 1e3:g} ms, sensor {RATE_HZ:g} Hz, delay 0 + {loop_check.TRANSPORT_DELAY_STEPS} "
          f"(transport); load average {os.getloadavg()[0]:.2f}")
    # the unit: one spectral radius of the loop model at this pose
    setup = loop_check.LoopSetup(robot=robot, q_rad=q_ref[0], k_Nm_per_rad=robot.joint_stiffness_Nm_per_rad,
                                 servo=LoopGuard(robot=robot, k_Nm_per_rad=robot.joint_stiffness_Nm_per_rad,
                                                 servo=None, sensor_rate_hz=RATE_HZ, period_s=PERIOD_S,
                                                 delay_steps=0, filter_kind="lowpass", filter_ba=None, cutoff_hz=2.0,
                                                 filter_order=2, allow_unstable=False).servo,
                                 sensor_rate_hz=RATE_HZ, period_s=PERIOD_S, delay_steps=0)
    ba = lowpass_coefficients(2.0, RATE_HZ, 2)
    setup.radius(ba, np.zeros((3, 3)))  # (the arm's matrices cached, as in a check)
    unit = []
    with single_blas_thread():
        for _ in range(args.repeats):
            t0 = time.perf_counter()
            setup.radius(ba, np.zeros((3, 3)))
            unit.append(time.perf_counter() - t0)
    unit_s = statistics.median(unit)
    print(f"one spectral radius (the loop model's period map and its eigenvalues): {unit_s * 1e3:.1f} ms")
    worst = 0.0
    for cutoff in (2.0, 10.0):
        times, result = [], None
        for _ in range(args.repeats):
            guard = LoopGuard(robot=robot, k_Nm_per_rad=robot.joint_stiffness_Nm_per_rad, servo=None,
                              sensor_rate_hz=RATE_HZ, period_s=PERIOD_S, delay_steps=0, filter_kind="lowpass",
                              filter_ba=lowpass_coefficients(cutoff, RATE_HZ, 2), cutoff_hz=cutoff, filter_order=2,
                              allow_unstable=False)
            t0 = time.perf_counter()
            try:
                guard.at(q0_deg, "the block test's start", feed)
            except InputError:
                pass
            times.append(time.perf_counter() - t0)
            result = guard.result
        t = statistics.median(times)
        worst = max(worst, t)
        r, ra = result["spectral_radius"], result["spectral_radius_assumed_damping"]
        verdict = "REFUSED" if result["unstable_modes"] else "passes"
        best = result["largest_stable_cutoff_hz"]
        print(f"--cutoff-hz {cutoff:g}: radius at 2 % air {r['air']:.5f}, cutting {r['cutting']:.5f} (at 5 %: "
              f"{ra['air']:.5f}, {ra['cutting']:.5f}); {verdict}"
              + (f"; largest stable cutoff {best:g} Hz" if best is not None else "")
              + f"; check {t:.3f} s (median of {args.repeats}; {t / unit_s:.0f} radii)")
    ok = worst < TARGET_S
    print(f"{'PASS' if ok else 'FAIL'}: the slowest check {worst:.3f} s against the target {TARGET_S:g} s "
          f"(load average {os.getloadavg()[0]:.2f})")
    return 0 if ok else 1


if __name__ == "__main__":
    sys.exit(main())
