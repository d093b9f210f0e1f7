"""Benchmark: the cost per controller cycle of the bound on the correction's
tool motion (cell/correction_bound.bounded: the model's wish and the
correction checked, the Jacobian from the chain's memo or the bound's own
cache), against the compensator's own tick (model/compensator.Compensator:
gravity removal, prediction, saturation, rate limit) measured in the same
run, at the tests' IRB 6400 start pose.

Cases: the arm standing (the Jacobian cached), the arm moving 0.05 deg a
cycle on every joint (a cache refresh every 6th cycle, the chain's memo
hit when the tick ran at the same pose), and the bound's fault (the shrink
and its check).  Target: the bound under a third of the tick's time and
under 10 us a cycle (the fault's path: under the tick's time and 20 us: it
runs only while the correction ramps down).  Prints the medians (us), the ratios and PASS/FAIL;
exit status 1 when a target is missed.
First it prints what the per-joint clamp (0.5 deg) allows at the tool
there: each joint's alone and the worst of all signs together (the figures
docs/real_cell.md and cell/correction_bound.py quote).
Run: python3 benchmarks/correction_bound_cost.py
"""

import itertools

import math
import os
import statistics
import sys
import time
from types import SimpleNamespace

import numpy as np

sys.path.insert(0, os.path.join(os.path.dirname(__file__), "..", "tests"))
import cell_helpers as h  # noqa: E402

from robstiff_drake.cell.correction_bound import CorrectionBound, bounded  # noqa: E402
from robstiff_drake.model.robot import load_robot  # noqa: E402

Q0 = [0.0, 7.008, 29.517, 0.0, 53.476, 0.0]
CYCLES = 20000
REPEATS = 5
TARGET_RATIO, TARGET_US = 1.0 / 3.0, 10.0
FAULT_RATIO, FAULT_US = 1.0, 20.0
T = 0.004


def _median_us(fn, n):
    runs = []
    for _ in range(REPEATS):
        t0 = time.perf_counter()
        for i in range(n):
            fn(i)
        runs.append((time.perf_counter() - t0) / n * 1e6)
    return statistics.median(runs)


def main():
    robot = load_robot()
    w = (np.asarray(h.hold_wrench(robot, np.radians(Q0))(0.0)) + [300.0, -200.0, 0, 0, 0, 0]).tolist()
    comp = h.hold_compensator(robot, w)
    q0 = robot.joint_map.to_model(np.radians(Q0)).tolist()
    step = math.radians(0.05)
    poses = [[v + step * (i % 400) for v in q0] for i in range(400)]  # (moving: a new pose every cycle)
    bound = CorrectionBound(comp.model._pred, 5.0, 0.5)
    loop = SimpleNamespace(bound=bound, q=q0, comp=comp, faults={}, _corr_sent=[0.001] * 6,
                           s=SimpleNamespace(rate_limit_rad_per_s=math.radians(5.0)), fault_on=lambda *a: None,
                           fault_off=lambda *a: None)
    for _ in range(50):
        comp.tick(q0, T, True)
    J = comp.model._pred.jacobian(q0)
    clamp = math.radians(0.5)
    alone = [float(np.linalg.norm(J[:3, j]) * clamp * 1e3) for j in range(6)]
    worst = max(float(np.linalg.norm(J[:3] @ (np.array(s) * clamp))) * 1e3
                for s in itertools.product((-1.0, 1.0), repeat=6))
    print(f"the 0.5 deg clamp at the tool, IRB 6400 at {Q0} deg: each joint alone "
          f"{', '.join(f'{v:.1f}' for v in alone)} mm; all joints, the worst signs, {worst:.1f} mm")

    def tick_standing(i):
        comp.tick(q0, T, True)

    def both_standing(i):
        bounded(loop, comp.tick(q0, T, True), T, True, 25)

    def tick_moving(i):
        comp.tick(poses[i % 400], T, True)

    def both_moving(i):
        loop.q = poses[i % 400]
        bounded(loop, comp.tick(loop.q, T, True), T, True, 25)

    def fault(i):
        loop.q = q0
        loop.faults["bound"] = 0.0
        loop._corr_sent = [0.001] * 6
        bounded(loop, comp.tick(q0, T, True), T, True, 25)

    rows = []
    t_stand = _median_us(tick_standing, CYCLES)
    rows.append(("standing", t_stand, _median_us(both_standing, CYCLES) - t_stand))
    t_move = _median_us(tick_moving, CYCLES)
    rows.append(("moving 0.05 deg/cycle", t_move, _median_us(both_moving, CYCLES) - t_move))
    rows.append(("the bound's fault", t_stand, _median_us(fault, CYCLES) - t_stand))
    ok = True
    print(f"{'case':<24} {'tick us (reference)':>20} {'bound us':>10} {'ratio':>7}")
    for k, (name, ref, extra) in enumerate(rows):
        us, ratio = (FAULT_US, FAULT_RATIO) if k == 2 else (TARGET_US, TARGET_RATIO)
        good = extra <= us and extra / ref <= ratio
        ok &= good
        print(f"{name:<24} {ref:>20.2f} {extra:>10.2f} {extra / ref:>7.3f}  {'PASS' if good else 'FAIL'}")
    return 0 if ok else 1


if __name__ == "__main__":
    raise SystemExit(main())
