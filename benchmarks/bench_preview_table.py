"""Benchmark: how long `robstiff compensate --mode preview --job` computes
before the stream can start (cell/preview_job.build_plan: the job's path by
IK every reference period, then the preview's table), for
face_and_contour and for a job of many lines (a finishing pass written as
a CAM post writes it: short G1 chords of a wavy surface, zig-zag rows,
made here in a temporary folder).

Printed for each job: the table's time with the IK solved (an empty disk
cache) and with the IK read from the disk cache (the job run again), the
vectorised IK alone (model/ik_path), and, the reference in the same run,
the table with the sample-by-sample IK it replaced
(model/path.PlannedPath.joint_references: model/ik.solve_for warm-started
from the previous sample, no disk cache): the ratio and the largest
difference between the two plans' joint references (deg).  Targets: face_and_contour's
table <= 5 s, the 10,000-line job's <= 60 s (both with the IK solved).
Quote the load average (`uptime`): the machine is shared.
Run: python3 benchmarks/bench_preview_table.py [--lines 10000] [--long-reference]
"""

import argparse
import math
import os
import sys
import tempfile
import time
from pathlib import Path

import numpy as np

from robstiff_drake.paths import DIAGRAMS_DIR

PERIOD_S = 0.004
RATE_HZ = 1000.0


def long_program(n_lines):
    """A Fanuc-style program of about ``n_lines`` lines: zig-zag rows over the
    120 x 80 mm plate of face_and_contour, each row 0.5 mm chords of a wave
    (the surface a CAM finishing pass follows), 0.5 mm deep, F1200."""
    rows = max(1, (n_lines - 12) // 241)
    lines = ["%", "O0300 (MANY-LINE FINISHING PASS)", "N10 G21 G17 G90 G40 G49 G80 G94", "G54", "S3600 M3",
             "G0 X0. Y10. Z50.", "G1 Z-0.5 F1200."]
    xs = np.arange(0.0, 120.0 + 1e-9, 0.5)
    for r in range(rows):
        y0 = 10.0 + 60.0 * r / max(rows - 1, 1)
        row = xs if r % 2 == 0 else xs[::-1]
        for x in row:
            lines.append(f"X{x:.3f} Y{y0 + 2.0 * math.sin(x / 10.0):.4f}")
    lines += ["G0 Z20.", "M5", "M30", "%"]
    return "\n".join(lines) + "\n"


def long_job(folder, n_lines):
    text = (DIAGRAMS_DIR / "face_and_contour.yaml").read_text()
    prog = Path(folder) / "many_lines.nc"
    prog.write_text(long_program(n_lines))
    job = Path(folder) / "many_lines.yaml"
    job.write_text(text.replace("program: face_and_contour.nc", f"program: {prog}"))
    return job, sum(1 for _ in prog.open())


def table_time(job, cache, sample_by_sample=False):
    """(s, PreviewPlan) of build_plan on ``job`` with the disk cache in
    ``cache``; ``sample_by_sample``: with the IK as it was before
    (model/path.PlannedPath.joint_references, no disk cache)."""
    from robstiff_drake.cell.preview_job import build_plan, load_job
    from robstiff_drake.diagrams import milling_cell, reference_cache
    from robstiff_drake.model.filters import lowpass_coefficients

    os.environ["ROBSTIFF_CACHE_DIR"] = cache
    milling_cell._REFERENCES.clear()  # the process's own cache: each run as a new process sees it
    sc, robot = load_job(str(job), None, period_s=PERIOD_S)
    fast = reference_cache.joint_references
    if sample_by_sample:
        reference_cache.joint_references = lambda path, robot, tool, dt, q_start=None: path.joint_references(
            robot, tool, dt, q_start)
    try:
        t0 = time.perf_counter()
        plan = build_plan(sc, robot, robot.joint_stiffness_Nm_per_rad, period_s=PERIOD_S,
                          filter_ba=lowpass_coefficients(2.0, RATE_HZ), rate_hz=RATE_HZ, delay_steps=0)
        return time.perf_counter() - t0, plan
    finally:
        reference_cache.joint_references = fast


def ik_time(job):
    """(s, samples) of the vectorised IK alone along the job's path."""
    from robstiff_drake.cell.preview_job import load_job
    from robstiff_drake.diagrams.milling_cell import scenario_path
    from robstiff_drake.model import ik_path

    sc, robot = load_job(str(job), None, period_s=PERIOD_S)
    path, tool, dt = scenario_path(sc), robot.payload.tool_point_m, sc.path.reference_period_ms / 1e3
    t0 = time.perf_counter()
    _, q_fast = ik_path.joint_references(path, robot, tool, dt)
    return time.perf_counter() - t0, len(q_fast)


def main():
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--lines", type=int, default=10000, help="the long job's program lines (0: face_and_contour only)")
    ap.add_argument("--long-reference", action="store_true",
                    help="the sample-by-sample reference on the long job too (minutes; face_and_contour's always)")
    args = ap.parse_args()
    print(f"load average {' / '.join(f'{v:.2f}' for v in os.getloadavg())} at the start")
    ok = True
    with tempfile.TemporaryDirectory() as tmp:
        jobs = [(DIAGRAMS_DIR / "face_and_contour.yaml", 5.0, "face_and_contour")]
        if args.lines:
            job, n = long_job(tmp, args.lines)
            jobs.append((job, 60.0, f"a {n}-line job"))
        for job, target, name in jobs:
            cache = tempfile.mkdtemp(dir=tmp)
            cold, plan = table_time(job, cache)
            warm, _ = table_time(job, cache)
            t_fast, n = ik_time(job)
            from robstiff_drake.cell.preview_table import scale_gains

            t0 = time.perf_counter()
            scale_gains(plan.replica, PERIOD_S)
            t_gains = time.perf_counter() - t0
            good = cold <= target
            ok &= good
            print(f"{name}: {len(plan.u)} cycles ({plan.u[-1]:.1f} s of path), {n} IK samples")
            print(f"  preview table, IK solved: {cold:7.2f} s   IK from the disk cache: {warm:7.2f} s   "
                  f"target <= {target:g} s: {'PASS' if good else 'FAIL'}")
            print(f"  then the force scales' gains along it (cell/preview_table.scale_gains, also before the "
                  f"stream): {t_gains:5.2f} s")
            line = f"  the vectorised IK alone: {t_fast:7.2f} s"
            if job == jobs[0][0] or args.long_reference:
                before, old = table_time(job, cache, sample_by_sample=True)
                diff = np.max(np.abs(old.q_ref_deg - plan.q_ref_deg))
                line += (f"   the table with the sample-by-sample IK (before, the reference): {before:7.2f} s   "
                         f"ratio {before / cold:4.1f}x   plans differ by at most {diff:.1e} deg")
            print(line)
    print(f"load average {' / '.join(f'{v:.2f}' for v in os.getloadavg())} at the end")
    return 0 if ok else 1


if __name__ == "__main__":
    sys.exit(main())
