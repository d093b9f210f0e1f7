"""Why online plain compensation on top of the corrected FANUC program cut
worse than the corrected program alone (issue 29), measured: the program
corrected and refined on the compensator's model as `robstiff
compensate-program face_contour_fanuc` writes it, run on the plant (its
own cutting law: docs/results.md "The plant's own cutting physics") with
no online compensation and with plain compensation of the measured wrench
less the model's (systems/steady_residual.py), the residual held where the
model's force is not steady:

  - as it was held before (the last residual passed, at full size, the
    mask closing only once the model's force had moved),
  - with the mask looking ahead only (model/program_correction.STEADY_AHEAD_S),
  - with the held residual going with the model's force only,
  - with both (the code as it is).

Prints the residual the mask's closings capture for several look-aheads
(off the uncompensated run of the corrected program: measured less model),
the residual sent and the tool's height through the contour's end, the
lead-out and the exit, and the floor's error by stretch of the path (the
generating point's arc length, diagrams/offline_refinement.generating_errors).

    python studies/plain_on_top_residual.py     # about 6 minutes on a loaded 2-core machine
"""

import copy
import functools
import sys
import tempfile
from contextlib import contextmanager
from pathlib import Path

import numpy as np

ROOT = Path(__file__).resolve().parents[1]
JOB = ROOT / "diagrams" / "face_contour_fanuc.yaml"
ROUNDS = 2  # compensate-program's --refine-rounds default
MAX_CORRECTION_MM = 1.0  # compensate-program's --max-correction-mm default
CHORD_MM = 0.005
PAYLOAD_N = 397.5  # the payload's weight in the sensor's z (the uncompensated run's reading in the air)


@contextmanager
def hold_as_before():
    """The SteadyResidual of before issue 29: its held residual never scaled."""
    from robstiff_drake.diagrams import milling_cell

    original = milling_cell.SteadyResidual
    milling_cell.SteadyResidual = functools.partial(original, air_force_N=float("inf"))
    try:
        yield
    finally:
        milling_cell.SteadyResidual = original


def residual_table(sc, robot, prediction, ahead_s):
    """(times on the run's clock s, model wrench (N, 6), steady (N,)) as
    diagrams/offline_compensation.model_wrench_cell builds it, the mask
    looking ``ahead_s`` ahead."""
    from robstiff_drake.diagrams.milling_cell import planned_path
    from robstiff_drake.model.program_correction import clock_on, steady_mask

    lag = prediction.servo.dead_time_s + 2.0 / sc.sensor.rate_hz
    path, _, _ = planned_path(sc, robot, robot.tool_point(where="the closed loop"))
    u = clock_on(prediction.path, path, prediction.u_s)
    w = prediction.sensor_wrench
    return u + lag, w, steady_mask(u, w[:, :3], ahead_s=ahead_s)


def main():
    from robstiff_drake.diagrams import offline_compensation as oc
    from robstiff_drake.diagrams import offline_refinement
    from robstiff_drake.diagrams import user_model as user_models
    from robstiff_drake.diagrams.experiment import run_cut
    from robstiff_drake.diagrams.milling_cell import build_milling_cell
    from robstiff_drake.diagrams.offline_refinement import generating_errors
    from robstiff_drake.diagrams.scenario import load_scenario, resolve, scenario_robot
    from robstiff_drake.model import kinematics as kin
    from robstiff_drake.model.gcode.writer import rewrite_corrected
    from robstiff_drake.model.program_correction import STEADY_AHEAD_S

    sc = load_scenario(str(JOB))
    program_file = resolve(sc, sc.toolpath.program)
    program = sc._program
    text = program_file.read_bytes().decode("utf-8-sig")
    robot = scenario_robot(sc, None)
    print("predicting and refining the program on the compensator's model", file=sys.stderr)
    prediction = oc.predict(sc, robot)
    prediction, _ = offline_refinement.refine(sc, robot, program, text, prediction, rounds=ROUNDS, chord_mm=CHORD_MM,
                                              max_correction_mm=MAX_CORRECTION_MM)
    corr = oc.move_corrections(sc, program, prediction, chord_mm=CHORD_MM, max_correction_mm=MAX_CORRECTION_MM)
    runs = {}
    with tempfile.TemporaryDirectory(prefix="robstiff-plain-on-top-") as tmp:
        draft = Path(tmp) / program_file.name
        draft.write_text(rewrite_corrected(text, program.moves, corr)[0])
        job = load_scenario(str(JOB), toolpath=draft)
        print("the corrected program, no online compensation", file=sys.stderr)
        runs["corrected program"] = run_cut(copy.deepcopy(job), robot, compensation=False)
        variants = (("plain on top, held as before", 0.0, True),
                    ("plain on top, mask ahead only", STEADY_AHEAD_S, True),
                    ("plain on top, held residual scaled only", 0.0, False),
                    ("plain on top, both (the code)", STEADY_AHEAD_S, False))
        for label, ahead, before in variants:
            print(label, file=sys.stderr)
            run_sc = copy.deepcopy(job)
            run_sc.controller.mode = "plain"
            user_models.resolve(run_sc, robot, prediction.q_ref_rad[0])
            table = residual_table(run_sc, robot, prediction, ahead)
            if before:
                with hold_as_before():
                    cell = build_milling_cell(run_sc, robot, compensation=True, model_wrench=table)
            else:
                cell = build_milling_cell(run_sc, robot, compensation=True, model_wrench=table)
            runs[label] = run_cut(run_sc, robot, compensation=True, cell=cell)
        # the clocks of the corrected program's path (read while the program is still there)
        tables = {ahead: residual_table(job, robot, prediction, ahead) for ahead in (0.0, 0.1, 0.2, 0.3)}

    off = runs["corrected program"]
    t_meas, measured = off.logs["raw_wrench"]
    print("measured less model (sensor frame, N, the air's taken off) where the mask closes, by look-ahead:")
    for ahead in (0.0, 0.1, 0.2, 0.3):
        t_w, w, steady = tables[ahead]
        model = np.column_stack([np.interp(t_meas, t_w, w[:, j]) for j in range(6)])
        r = measured - model
        m = steady[np.clip(np.searchsorted(t_w, t_meas, side="right") - 1, 0, len(steady) - 1)]
        ends = np.flatnonzero(m[:-1] & ~m[1:])
        print(f"  ahead {ahead:.1f} s: " + "; ".join(
            f"{t_meas[i]:.2f} s ({', '.join(f'{v:+.0f}' for v in r[i, :3] - r[0, :3])}) at "
            f"{np.linalg.norm(model[i, :3]):.0f} N" for i in ends if np.linalg.norm(model[i, :3]) > 5.0))

    print("through the contour's end, lead-out and exit: model force (N), residual sent (N, the payload's weight "
          "taken off) and the tool point's height over the programmed path (mm):")
    t_w, w, _ = tables[STEADY_AHEAD_S]
    show = ("corrected program", "plain on top, held as before", "plain on top, both (the code)")
    print("   t s  model N  " + "  ".join(f"{k[:30]:>30}" for k in show))
    heights = {}
    for k in show:
        t, x = runs[k].logs["state"]
        T6 = kin.frames(robot.dh, x[:, :6])[:, 6]
        heights[k] = (t, (T6[:, 2, 3] + T6[:, 2, :3] @ runs[k].cell.tool_m - prediction.path.positions(t)[:, 2]) * 1e3)
    for ts in np.arange(16.0, 21.01, 0.5):
        f = np.linalg.norm([np.interp(ts, t_w, w[:, j]) for j in range(3)])
        cells = []
        for k in show:
            tr, r = runs[k].logs["raw_wrench"]
            i = min(np.searchsorted(tr, ts), len(tr) - 1)
            sent = r[i, :3] - np.array([0.0, 0.0, PAYLOAD_N])
            t, z = heights[k]
            h = float(np.interp(ts, t, z))
            cells.append(f"{'(measured)' if k == 'corrected program' else ''}"
                         f"({', '.join(f'{v:+.0f}' for v in sent)}) {h:+.3f}")
        print(f"  {ts:4.1f} {f:7.0f}   " + "  ".join(f"{c:>30}" for c in cells))

    print("the floor's error by stretch of the path (mean / largest |e| mm, + = cut more), by the arc length of the "
          "tool where it cut the floor:")
    errors = {k: generating_errors(res, prediction.path) for k, res in runs.items()}
    edges = np.arange(0.0, prediction.s_m.max() + 0.02, 0.02)
    print("   s m   t s  " + "  ".join(f"{k[:20]:>20}" for k in runs))
    for a, b in zip(edges[:-1], edges[1:]):
        row = []
        for s, e in errors.values():
            sel = (s >= a) & (s < b)
            row.append(f"{e[sel].mean():+.3f} / {np.abs(e[sel]).max():.3f}" if sel.any() else "")
        if any(row):
            u = float(np.interp(a, prediction.s_m, prediction.u_s))
            print(f"  {a:.2f} {u:5.1f}  " + "  ".join(f"{c:>20}" for c in row))
    print("surface error on the plant, scanned against the programmed surface (mm):")
    for k, res in runs.items():
        st = oc.scanned_against_program(res, prediction.path)
        print(f"  {k:<42} mean {st['mean']:+.3f}  rms {st['rms']:.3f}  max {st['max_abs']:.3f}")


if __name__ == "__main__":
    main()
