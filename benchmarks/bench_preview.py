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

Target: every cycle <= 500 us (an eighth of the 4 ms cycle): PASS/FAIL on
the preview's 99th percentile (exit status 1 on FAIL); the median, the
largest cycle and the ratio to the plain chain are printed beside it, and
the table's precomputation time.  The largest cycle on a shared machine
is the scheduler's (quote the load average, `uptime`, beside the figures).
Run: python3 benchmarks/bench_preview.py [--job diagrams/face_and_contour.yaml]
"""

import argparse
import math
import statistics
import sys
import time

import numpy as np

from robstiff_drake.cell.preview_table import PreviewDeflection, build_plan, load_job
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
        self.comp, self.faults, self.t_session, self.q_deg = comp, {}, 0.0, None
        self.events = []

    def event(self, text):
        self.events.append(text)


def chain(robot, tool, ba):
    kin = DeflectionPredictor(robot.dh, robot.joint_stiffness_Nm_per_rad, tool)
    cal = PayloadCalibration(mass_kg=40.0, com_mm=[0.0, 0.0, 180.0], force_bias_N=[0.0] * 3,
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
    t_prev, t_plain = [], []
    for c in range(n):
        k = k0 + c
        t = k * PERIOD_S
        q_deg = plan.q_plan_deg[k].tolist()
        q = robot.joint_map.to_model(np.radians(q_deg)).tolist()
        samples = [(rng.normal(size=6) * 10.0).tolist() for _ in range(int(RATE_HZ * PERIOD_S))]
        loop.t_session, loop.q_deg = t, q_deg
        start = time.perf_counter()
        for w in samples:
            comp.sensor_sample(w)
        preview.update(loop, _Msg(int(round(t * 1e3))))
        corr = comp.tick(q, PERIOD_S)
        preview.sent(np.degrees(G_inv @ np.asarray(corr)).tolist())
        t_prev.append(time.perf_counter() - start)
        start = time.perf_counter()
        for w in samples:
            plain.sensor_sample(w)
        corr = plain.tick(q, PERIOD_S)
        np.degrees(G_inv @ np.asarray(corr)).tolist()
        t_plain.append(time.perf_counter() - start)

    us = 1e6
    mp, mr = statistics.median(t_prev) * us, statistics.median(t_plain) * us
    p99p, p99r = np.percentile(t_prev, 99) * us, np.percentile(t_plain, 99) * us
    print(f"preview table of {args.job}: {len(plan.u)} cycles ({plan.u[-1]:.2f} s of path) computed in {t_plan:.2f} s "
          "before the stream starts")
    print(f"per 4 ms cycle over {n} cycles of the cut (us):        median      p99      max")
    print(f"  preview (compensate --mode preview)              {mp:8.1f} {p99p:8.1f} {max(t_prev) * us:8.1f}")
    print(f"  plain chain (4 sensor samples + tick), reference {mr:8.1f} {p99r:8.1f} {max(t_plain) * us:8.1f}")
    print(f"  ratio preview / plain: median {mp / mr:.2f}, p99 {p99p / p99r:.2f}")
    if not preview.active or loop.events:
        print(f"  the preview stopped during the benchmark ({loop.events}): FAIL")
        return 1
    ok = p99p <= TARGET_US
    over = sum(1 for x in t_prev if x * us > TARGET_US)
    print(f"  target <= {TARGET_US:.0f} us per cycle: p99 {p99p:.1f} us, {over} of {n} cycles over (on a shared "
          f"machine: the scheduler's preemptions): {'PASS' if ok else 'FAIL'}")
    return 0 if ok else 1


if __name__ == "__main__":
    sys.exit(main())
