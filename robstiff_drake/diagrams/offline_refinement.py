"""The corrected program refined on the compensator's model: predict,
correct, run the corrected program on the model's twin of the cell, correct
again where the floor it leaves is off.

Why (measured on face_and_contour, docs/offline_compensation.md): the
preview's correction written into a 3-axis program puts the tool point where
the model wants it on average, but the program runs through the controller's
own IK with the tool held vertical, so the correction's wrist share is moved
onto the main axes, whose modes it then rings (the six-axis joint reference
does not); and a face mill's floor is the lowest the cutter reached over each
point (model/floor_generation.py), so those dips, and the dips the cut's own
transients leave (the plunge, the cutter leaving the plate), are stamped over
the cutter's width.  The tool point's mean position is then right and the
floor is not.  Each round here runs the corrected program on the twin
(``model_twin``: the identified stiffness, damping, servo and linear force
model as the plant; the cutting force recomputed on the corrected path, so
a correction that changes the force is re-predicted), finds where
along the path the tool cut each point of the floor (its generating place,
with the tool's actual tilt), and raises the program there by the floor's
error (lowers it where the floor is left high): a fixed-point iteration on
the floor, with the program's own interpolation and the controller's lag in
the loop.  Only the vertical (floor) coordinate is refined; the lateral
correction stays the preview's (a wall would need the flank's generating
point, which this job's scan does not measure)."""

import tempfile
from dataclasses import replace
from pathlib import Path

import numpy as np

from robstiff_drake.model import kinematics as kin


def generating_errors(res, program_path):
    """(arc lengths m, errors mm): for every point of the run's scan (the
    scenario's scan lines along the programmed path ``program_path``, its
    offsets, resolution and edge margin) where the programmed pass cuts the
    material, the floor's error there (commanded - machined, mm) and the arc
    length along ``program_path`` of the tool when it cut it."""
    from robstiff_drake.diagrams.experiment import inside_margin, material_top
    from robstiff_drake.model.floor_generation import lowest_faces

    cell = res.cell
    scan = cell.scenario.scan
    t, x = res.logs["state"]
    T6 = kin.frames(cell.robot.dh, x[:, :6])[:, 6]
    p_act = T6[:, :3, 3] + T6[:, :3, :3] @ cell.tool_m
    n_act = -T6[:, :3, 2]
    R = cell.force_model.cutter.radius_m
    p_cmd = program_path.positions(t)
    up = np.tile([0.0, 0.0, 1.0], (len(t), 1))
    _, pts, tg = program_path.sample_xy(scan.resolution_mm / 1e3)
    normal = np.column_stack([-tg[:, 1], tg[:, 0]])
    samples, errors = [], []
    for off_mm in scan.offsets_mm or [0.0]:
        xs = pts[:, 0] + off_mm / 1e3 * normal[:, 0]
        ys = pts[:, 1] + off_mm / 1e3 * normal[:, 1]
        top = material_top(cell.workpiece, xs, ys)
        h_cmd, _ = lowest_faces(xs, ys, p_cmd, up, R)
        h_act, who = lowest_faces(xs, ys, p_act, n_act, R)
        face = (np.isfinite(top) & (h_cmd < top - 1e-9) & (who >= 0)
                & inside_margin(cell.workpiece, xs, ys, scan.edge_margin_mm / 1e3))
        samples.append(who[face])
        errors.append((h_cmd[face] - h_act[face]) * 1e3)
    samples, errors = np.concatenate(samples), np.concatenate(errors)
    s_of = {}
    for i in np.unique(samples):
        s_of[i] = program_path.project(p_act[i], program_path.arc_length(t[i]), max_step_m=0.01, iterations=8)
    return np.array([s_of[i] for i in samples]), errors


def model_twin(sc, robot):
    """The compensator's model of the cell as a scenario
    (diagrams/feed_plan.twin_scenario) with the model's own cutting law,
    the linear one the coefficients were identified with: the plant's
    richer law (chip exponent, runout, wear: model/plant_cutting.py) is
    what a user does not have."""
    from robstiff_drake.diagrams.feed_plan import twin_scenario

    tw = twin_scenario(sc, robot, 1.0)
    tw.cutting.plant_law = "linear"
    return tw


def twin_run(sc, robot, prediction, program_file=None, *, progress=None):
    """The program ``program_file`` (None: the job's own) run on the
    compensator's model of the cell (``model_twin``), no online
    compensation."""
    from robstiff_drake.diagrams import user_model as user_models
    from robstiff_drake.diagrams.experiment import run_cut
    from robstiff_drake.diagrams.scenario import load_scenario

    sc2 = load_scenario(sc.source, toolpath=program_file) if program_file is not None else sc
    user_models.resolve(sc2, robot, prediction.q_ref_rad[0])
    return run_cut(model_twin(sc2, robot), robot, compensation=False, progress=progress)


def predicted_errors(sc, robot, prediction, corrected_program, *, progress=None, say=None, after=None):
    """The predicted surface error (mm: mean, max_abs, ...) on the
    compensator's model, before (the program as written) and after (the
    corrected program): each run on the model's twin of the cell
    (model_twin: the identified stiffness, its
    damping, servo, linear force model and sensor bias as the plant), scanned
    against the programmed surface.  ``after``: the corrected program's
    stats when already known (the refinement's last round)"""
    from robstiff_drake.diagrams.offline_compensation import _short, scanned_against_program

    if say:
        say("the compensator's model (its twin of the cell): the program as written" +
            (" and the corrected one" if after is None else ""))
    before = twin_run(sc, robot, prediction, progress=progress).surface_error_mm
    if after is None:
        res = twin_run(sc, robot, prediction, corrected_program, progress=progress)
        after = _short(scanned_against_program(res, prediction.path))
    return _short(before), after


def best_round(history):
    """The index in ``history`` (twin surface-error stats mm per round) of
    the round to write: the smallest largest |error|, then the smallest
    |mean|.  The fixed-point iteration need not converge (on a job whose
    floor the cut's own vibration stamps, a round can undo the one before:
    0.035 mm then 0.306 mm), so its last round is not always its best."""
    return min(range(len(history)), key=lambda k: (history[k]["max_abs"], abs(history[k]["mean"]), -k))


def refine(sc, robot, program, text, prediction, *, rounds, chord_mm, max_correction_mm, progress=None, say=None):
    """(the refined Prediction, [twin surface-error stats mm per round]):
    ``rounds`` rounds of the floor's fixed-point iteration (module
    docstring) on the corrected program of ``program`` (its ``text``); the
    stats list has rounds + 1 entries, one per program tried (the first the
    preview's correction as written).  The Prediction returned is that of
    the best round (``best_round``: the last when the rounds improve, as
    on face_contour_fanuc; on face_and_contour round 2 undoes a little of
    round 1, 0.027 -> 0.030 mm on the twin, and round 1 is written), whose
    stats are ``history[best_round(history)]``.
    CorrectionError when a refined correction exceeds ``max_correction_mm``."""
    from robstiff_drake.diagrams.offline_compensation import move_corrections, scanned_against_program, _short
    from robstiff_drake.model.floor_generation import floor_raise_mm
    from robstiff_drake.model.gcode.writer import rewrite_corrected

    history, tried = [], []
    with tempfile.TemporaryDirectory(prefix="robstiff-refine-") as tmp:
        draft = Path(tmp) / Path(str(program.path)).name
        for k in range(rounds + 1):
            corr = move_corrections(sc, program, prediction, chord_mm=chord_mm, max_correction_mm=max_correction_mm)
            draft.write_text(rewrite_corrected(text, program.moves, corr)[0])
            if say:
                say(f"the corrected program on the compensator's model, round {k + 1} of {rounds + 1}")
            res = twin_run(sc, robot, prediction, draft, progress=progress)
            history.append(_short(scanned_against_program(res, prediction.path)))
            tried.append(prediction)
            if k == rounds:
                break
            s_gen, err = generating_errors(res, prediction.path)
            delta = prediction.delta_mm.copy()
            delta[:, 2] += floor_raise_mm(prediction.s_m, s_gen, err)
            prediction = replace(prediction, delta_mm=delta)
    return tried[best_round(history)], history
