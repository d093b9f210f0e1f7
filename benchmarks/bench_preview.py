"""Benchmark: the preview compensator's computation per 4 ms controller
cycle, as `robstiff compensate --mode preview --job` runs it: the table of
the whole job computed before the stream starts (cell/preview_table.py:
the job's planned path, model/preview.PreviewStream over all of it, the
model wrench's filter replica), then per cycle the plain chain's work (the
period's four sensor samples through guard and filter, gravity removal,
the deflection of the measured-minus-model wrench, saturation, delay line,
rate limit) plus the preview's (the controller's clock and the arm's
feedback against the plan, the force scales' Kalman update, the force
departure check, two table lookups), beside the plain chain alone
(model/compensator.Compensator: sensor samples + tick) measured in the
same run on the same cycles.

Target: every cycle's computation <= 500 us (an eighth of the 4 ms
cycle): PASS/FAIL on the preview's 99th percentile and largest cycle in
the thread's CPU time (exit status 1 on FAIL; on a shared machine the wall
clock's tails are the scheduler giving the core to other jobs, which no
code here changes).  Printed beside it: median, p99 and max in CPU time and
on the wall clock, for the preview and the plain chain, their ratio, and
the table's precomputation time.  Quote the load average (`uptime`).
Run: python3 benchmarks/bench_preview.py [--job diagrams/face_and_contour.yaml]
"""

import argparse
import math
import statistics
import sys
import time

import numpy as np

from robstiff_drake.cell.preview_job import build_plan, load_job
from robstiff_drake.cell.preview_table import PreviewDeflection
from robstiff_drake.model.compensator import Compensator
from robstiff_drake.model.filters import lowpass_coefficients
from robstiff_drake.model.payload import PayloadCalibration
from robstiff_drake.model.realtime import DeflectionPredictor
from robstiff_drake.paths import DIAGRAMS_DIR

TARGET_US = 500.0
PERIOD_S = 0.004
RATE_HZ = 1000.0  # a Net F/T streamed at 1 kHz: four sensor samples per cycle


class _Msg:
    def __init__(self, tm_ms):
        self.tm_ms = tm_ms


class _Loop:
    """What PreviewDeflection.update reads of cell/compensate.CompensatorLoop."""

    def __init__(self, comp):
        self.comp, self.faults, self.t_session, self.t_ref, self.q_deg = comp, {}, 0.0, 0.0, None
        self.events = []

    def event(self, text):
        self.events.append(text)


def chain(robot, tool, ba):
    kin = DeflectionPredictor(robot.dh, robot.joint_stiffness_Nm_per_rad, tool)
    cal = PayloadCalibration(mass_kg=0.0, com_mm=[0.0, 0.0, 180.0], force_bias_N=[0.0] * 3,
                             torque_bias_Nm=[0.0] * 3, sensor_mount_rpy_deg=[0.0] * 3)
    return Compensator(predictor=kin, calibration=cal, tool_m=tool, filter_ba=ba, max_jump_N=1000.0,
                       saturation_rad=math.radians(0.5), rate_limit_rad_per_s=math.radians(5.0), delay_steps=0,
                       initial_wrench=[0.0] * 6)


def main():
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--cycles", type=int, default=4000)
    ap.add_argument("--job", default=str(DIAGRAMS_DIR / "face_and_contour.yaml"))
    args = ap.parse_args()

    sc, robot = load_job(args.job, None, period_s=PERIOD_S)
    tool = robot.payload.tool_point_m
    ba = lowpass_coefficients(2.0, RATE_HZ)
    t0 = time.perf_counter()
    plan = build_plan(sc, robot, robot.joint_stiffness_Nm_per_rad, period_s=PERIOD_S, filter_ba=ba, rate_hz=RATE_HZ,
                      delay_steps=0)
    t_plan = time.perf_counter() - t0
    plain, comp = chain(robot, tool, ba), chain(robot, tool, ba)
    preview = comp.model = PreviewDeflection(comp.model, plan, sync_s=0.025, force_bound_N=150.0,
                                             force_bound_fraction=0.5)
    loop = _Loop(comp)
    preview.t_ctrl = k0_s = 2.5  # the benchmark starts into the cut (the plunge's end): the controller's clock there
    G_inv = np.linalg.inv(robot.joint_map.G)
    rng = np.random.default_rng(0)
    k0 = int(round(k0_s / PERIOD_S))
    n = min(args.cycles, len(plan.u) - k0 - 1)
    t_prev, t_plain, c_prev, c_plain = [], [], [], []
    for c in range(n):
        k = k0 + c
        t = k * PERIOD_S
        q_deg = plan.q_plan_deg[k].tolist()
        q = robot.joint_map.to_model(np.radians(q_deg)).tolist()
        # the sensor reads the job's model wrench (as the cut it describes would) and noise
        w_model = plan.replica[k].sum(axis=0)
        samples = [(w_model + rng.normal(size=6) * 10.0).tolist() for _ in range(int(RATE_HZ * PERIOD_S))]
        loop.t_session, loop.t_ref, loop.q_deg = t, t, q_deg
        start, cpu = time.perf_counter(), time.thread_time()
        for w in samples:
            comp.sensor_sample(w)
        preview.update(loop, _Msg(int(round(t * 1e3))))
        corr = comp.tick(q, PERIOD_S)
        preview.sent(np.degrees(G_inv @ np.asarray(corr)).tolist())
        t_prev.append(time.perf_counter() - start)
        c_prev.append(time.thread_time() - cpu)
        start, cpu = time.perf_counter(), time.thread_time()
        for w in samples:
            plain.sensor_sample(w)
        corr = plain.tick(q, PERIOD_S)
        np.degrees(G_inv @ np.asarray(corr)).tolist()
        t_plain.append(time.perf_counter() - start)
        c_plain.append(time.thread_time() - cpu)

    us = 1e6

    def row(name, x):
        return f"  {name:<50} {statistics.median(x) * us:8.1f} {np.percentile(x, 99) * us:8.1f} {max(x) * us:8.1f}"

    print(f"preview table of {args.job}: {len(plan.u)} cycles ({plan.u[-1]:.2f} s of path) computed in {t_plan:.2f} s "
          "before the stream starts")
    print(f"per 4 ms cycle over {n} cycles of the cut (us):          median      p99      max")
    print(row("preview (compensate --mode preview), CPU time", c_prev))
    print(row("plain chain (4 sensor samples + tick), CPU time", c_plain))
    print(row("preview, wall clock (with the scheduler's pauses)", t_prev))
    print(row("plain chain, wall clock", t_plain))
    r = [statistics.median(c_prev) / statistics.median(c_plain), np.percentile(c_prev, 99) / np.percentile(c_plain, 99),
         statistics.median(t_prev) / statistics.median(t_plain)]
    print(f"  ratio preview / plain: CPU median {r[0]:.2f}, CPU p99 {r[1]:.2f}, wall median {r[2]:.2f}")
    if not preview.active or loop.events:
        print(f"  the preview stopped during the benchmark ({loop.events}): FAIL")
        return 1
    p99, top = np.percentile(c_prev, 99) * us, max(c_prev) * us
    ok = p99 <= TARGET_US and top <= TARGET_US
    print(f"  target <= {TARGET_US:.0f} us of computation in every cycle (CPU time: the wall clock's tails on a shared "
          f"machine are other jobs'): p99 {p99:.1f} us, max {top:.1f} us: {'PASS' if ok else 'FAIL'}")
    return 0 if ok else 1


if __name__ == "__main__":
    sys.exit(main())
