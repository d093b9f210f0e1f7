"""Offline compensation: a corrected program for a cell with no wrist
sensor and no real-time interface.  The compensator's own model (the
identified stiffness, its force model, the robot file's inertias, its
servo model and damping: what a user would have) predicts, with the
preview's computation (model/preview.py: the arm's modes, the drives and
their give under load), the joint correction c(t) that keeps the links on
the programmed path; its Cartesian image at the tool point is the
correction written into the program (model/program_correction.py,
model/gcode/writer.py).

The preview's c is meant for a correction sent *without* velocity
feed-forward (it holds a term d'/Kp for the position loop's lag).  A
corrected program is the reference itself, which the controller runs
with feed-forward, so that term is taken out: c_off = c - (dc/dt) / Kp
(to first order, d' ~ c').

The proof (``proof_runs``): the corrected program run on the plant (its
own physics, which the compensator does not share), its surface scanned
against the *programmed* surface (the original program's commanded
envelope): with online compensation off, and with online plain
compensation on top, which then corrects only what the model did not
predict (its wrench input is the measured minus the model's sensor wrench,
the part the program already holds)."""

import copy
import math
import time
from dataclasses import dataclass, replace

import numpy as np

from robstiff_drake.model import kinematics as kin


@dataclass
class Prediction:
    """The predicted correction on the preview's grid: path times u (s),
    the joint references there (N, 6 rad), the offline joint correction
    c_off (N, 6 rad), the tool point's correction (N, 3 mm, base frame),
    the arc length s (N, m), the model's sensor wrench (N, 6), and what it
    took."""

    u_s: np.ndarray
    q_rad: np.ndarray
    c_rad: np.ndarray
    delta_mm: np.ndarray
    s_m: np.ndarray
    sensor_wrench: np.ndarray
    path: object
    t_ref_s: np.ndarray
    q_ref_rad: np.ndarray
    tool_m: np.ndarray
    servo: object
    seconds: float
    c_preview_rad: np.ndarray = None  # the preview's correction (sent without feed-forward)


def predict(sc, robot, *, bar=None, say=None):
    """The Prediction of scenario ``sc``'s program on the compensator's model."""
    from robstiff_drake.diagrams import user_model as user_models
    from robstiff_drake.diagrams.milling_cell import PREVIEW_MARGIN_S, planned_path
    from robstiff_drake.diagrams.scenario_models import (
        COEFFICIENT_GROUPS, identified_parts, model_cutting_setup, model_damping_ratios, model_stiffness
    )
    from robstiff_drake.model.arm_dynamics import ArmInertia
    from robstiff_drake.model.preview import PreviewStream
    from robstiff_drake.model.realtime import DeflectionPredictor
    from robstiff_drake.systems.preview_correction import PreviewModel

    t0 = time.perf_counter()
    tool = robot.tool_point(where="compensate-program")
    if say:
        say(f"planning the program's path (IK every {sc.path.reference_period_ms:g} ms)")
    path, t_ref, q_ref = planned_path(sc, robot, tool)
    if say and sc.model.source == "identified":
        say(f"the compensator's identified model ({identified_parts(sc)})")
    user_models.resolve(sc, robot, q_ref[0])
    T = sc.controller.period_ms / 1e3
    servo = user_models.servo_model(sc)
    groups = [model_cutting_setup(sc, groups=g)[1] for g in COEFFICIENT_GROUPS]
    _, _, workpiece = model_cutting_setup(sc)
    k = model_stiffness(sc, robot)
    kinematics = DeflectionPredictor(robot.dh, k, tool)
    inertia = ArmInertia(robot)
    pm = PreviewModel(path=path, t_ref=t_ref, q_ref=q_ref, group_models=groups, workpiece=workpiece,
                      kinematics=kinematics, inertia=inertia, tool_m=tool)
    stream = PreviewStream(pm, period_s=T, compliance=kinematics.joint_compliance,
                           damping_ratios=model_damping_ratios(sc), servo=servo,
                           motor_inertia_kgm2=inertia.motor_inertia(q_ref[0]), tool_m=tool)
    n = int(math.ceil((path.duration_s + PREVIEW_MARGIN_S) / T)) + 1
    us, cs, ss = [], [], []
    b = bar(n + 2) if bar else None
    for i in range(n + 2):
        out = stream.push(i * T)
        if b is not None and i % 250 == 0:
            b.update(min(250, n + 2 - i))
        if out is not None:
            us.append(out[0])
            cs.append(out[1].sum(axis=0))
            ss.append(out[2].sum(axis=0))
    if b is not None:
        b.close()
    u, c, sensor = np.array(us), np.array(cs), np.array(ss)
    c_off = feedforward_equivalent(c, T, servo.position_gain_per_s)
    q = np.column_stack([np.interp(u, t_ref, q_ref[:, j]) for j in range(6)])
    p0 = kin.tool_position(robot.dh, q, tool)
    p1 = kin.tool_position(robot.dh, q + c_off, tool)
    s = np.array([path.arc_length(x) for x in u])
    return Prediction(u, q, c_off, (p1 - p0) * 1e3, s, sensor, path, np.asarray(t_ref), np.asarray(q_ref), tool,
                      servo, time.perf_counter() - t0, c)


def feedforward_equivalent(c, period_s, position_gain_per_s):
    """The correction that, written into the reference (which the
    controller runs with velocity feed-forward), moves the motors as ``c``
    (N, 6; on a grid of ``period_s``) sent without feed-forward does: the
    servo's response to a reference r with feed-forward is
    omega_v (Kp + s) / (s^2 + omega_v s + omega_v Kp) r, without it
    omega_v Kp / (...) c, so r = Kp / (s + Kp) c: a first-order low-pass
    of corner Kp (rad/s), here its exact discrete form for a held input."""
    a = math.exp(-position_gain_per_s * period_s)
    c = np.asarray(c, dtype=float)
    out = np.empty_like(c)
    y = c[0].copy()
    for k in range(len(c)):
        out[k] = y
        y = a * y + (1.0 - a) * c[k]
    return out


def work_rotation(sc):
    """The work frame's rotation in the base frame (3x3)."""
    a = math.radians(sc.toolpath.work_rotation_deg)
    return np.array([[math.cos(a), -math.sin(a), 0.0], [math.sin(a), math.cos(a), 0.0], [0.0, 0.0, 1.0]])


def move_corrections(sc, program, prediction, *, chord_mm, max_correction_mm):
    """{line: MoveCorrection} of the program's cutting moves (feed moves
    with the spindle on; rapids, and moves with the spindle off, keep their
    ends)."""
    from robstiff_drake.diagrams.toolpath import work_transform, work_transform_mm
    from robstiff_drake.model import program_correction as pc
    from robstiff_drake.model.program_path import program_pieces

    tp = sc.toolpath
    _, _, _, _, sources = program_pieces(program.moves, tp.rapid_mm_per_s / 1e3, work_transform(tp))
    element_of = {id(m): i for i, m in enumerate(sources)}
    maps = pc.element_arc_maps(prediction.path)
    delta_at = pc.correction_along(prediction.s_m, prediction.delta_mm @ work_rotation(sc))  # base -> work frame

    to_work = work_transform_mm(tp)
    R = work_rotation(sc)
    origin = to_work(np.zeros(3))

    def samples_of_move(idx, frac, before, after):
        m = program.moves[idx]
        frac = np.asarray(frac, dtype=float)
        programmed = pc.move_points(m, frac)
        i = element_of.get(id(m))
        if i is None or i not in maps:
            return programmed, np.zeros((len(frac), 3))
        A, S = maps[i]
        L = prediction.path.programmed_elements[i].length
        s = np.interp(frac * L, A, S)
        # the path the controller runs (a corner blended within the zone) where the move next to it is corrected
        # too, the programmed move where it meets one left as programmed
        on_path = np.array([prediction.path.point_at(x) for x in s]) * 1e3
        base = (on_path - origin) @ R  # base frame mm -> work frame mm
        keep = np.zeros(len(frac), dtype=bool)
        if not before:
            keep |= frac * L < A[1] if len(A) > 1 and A[0] == 0.0 else False
        if not after:
            keep |= frac * L > A[-2] if len(A) > 1 else False
        base[keep] = programmed[keep]
        return base, delta_at(s)

    def is_cutting(m):
        return m.kind != "rapid" and m.spindle_on

    return pc.correct_moves(program.moves, samples_of_move, chord_mm=chord_mm, max_correction_mm=max_correction_mm,
                            round_mm=1e-4, is_cutting=is_cutting, label=program.path)


def scanned_against_program(res, program_path):
    """Surface-error statistics (mm) of a run, scanned against the
    programmed path's commanded surface (not the corrected program's)."""
    from robstiff_drake.diagrams.experiment import scanned_surface

    cell = replace(res.cell, path=program_path)
    t, x = res.logs["state"]
    _, stats = scanned_surface(cell, t, x[:, :6])
    return stats


def model_wrench_cell(sc, robot, prediction, *, steady=True):
    """A milling cell whose online compensator hears the measured wrench
    minus the model's (the part the corrected program already holds), at
    the lag the measured one has behind the path (the arm's dead time and
    two sensor samples); ``steady``: heard only where the model's force is
    steady (model/program_correction.steady_mask; elsewhere a residual
    held, going with the model's force: systems/steady_residual.py; at an
    entry the plant's force follows the tool's real motion, later than
    the model's), else everywhere."""
    from robstiff_drake.diagrams.milling_cell import build_milling_cell, planned_path
    from robstiff_drake.model.program_correction import clock_on, steady_mask

    lag = prediction.servo.dead_time_s + 2.0 / sc.sensor.rate_hz
    path, _, _ = planned_path(sc, robot, robot.tool_point(where="the closed loop"))
    u = clock_on(prediction.path, path, prediction.u_s)  # the plan's times on the corrected program's clock
    w = prediction.sensor_wrench
    model = (u + lag, w, steady_mask(u, w[:, :3])) if steady else (u + lag, w)
    return build_milling_cell(sc, robot, compensation=True, model_wrench=model)


def corrected_reference(prediction):
    """(times s, (N, 6) rad): the path's joint references with the full
    (six-axis) offline correction, on the references' own grid."""
    t = prediction.t_ref_s
    c = np.column_stack([np.interp(t, prediction.u_s, prediction.c_rad[:, j]) for j in range(6)])
    return t, prediction.q_ref_rad + c


def reference_text(robot, prediction, run_id, job, model="model", *, period_s):
    """joint_reference.csv: the corrected joint references (controller
    degrees; rows on the controller's cycle ``period_s`` s or coarser), its
    first line the corrected reference's mark (``model``: the compensator's
    model that corrected them, in words), which `robstiff
    compensate --reference` reads (a corrected reference is not streamed with
    online compensation: commands/compensate.py)."""
    from pathlib import Path

    from robstiff_drake.identification.runs.logs import corrected_mark_line, joint_reference_text

    t, q = corrected_reference(prediction)
    mark = corrected_mark_line("robstiff compensate-program", f"{model} of {Path(str(job)).name}")
    return mark + joint_reference_text(robot, t, q, run_id, [
        f"robstiff compensate-program: the joint references of {job}'s program with the offline correction of "
        "the compensator's model (all six axes; controller degrees), for `robstiff compensate --reference "
        "joint_reference.csv --reference-is-corrected`"], period_s=period_s)


def proof_runs(job_sc, robot, corrected_program, prediction, *, modes=("off", "plain"), progress=None, say=None):
    """{"uncompensated": stats, "corrected program": stats, "corrected joint
    reference": stats, "corrected program + online <mode>": stats for the
    other ``modes`` (plain, preview)}: the plant's surface error (mm),
    scanned against the programmed surface."""
    from robstiff_drake.diagrams import user_model as user_models
    from robstiff_drake.diagrams.experiment import run_cut
    from robstiff_drake.diagrams.milling_cell import build_milling_cell
    from robstiff_drake.diagrams.scenario import load_scenario

    out = {}
    if say:
        say("proof: the program as written, on the plant, no compensation")
    res = run_cut(copy.deepcopy(job_sc), robot, compensation=False, progress=progress)
    out["uncompensated"] = _short(res.surface_error_mm)
    sc = load_scenario(job_sc.source, toolpath=corrected_program)
    for mode in modes:
        run_sc = copy.deepcopy(sc)
        if mode == "off":
            if say:
                say("proof: the corrected program, on the plant, no online compensation")
            res = run_cut(run_sc, robot, compensation=False, progress=progress)
            out["corrected program"] = _short(scanned_against_program(res, prediction.path))
            if say:
                say("proof: the corrected joint reference (six axes), on the plant, no online compensation")
            ref_sc = copy.deepcopy(job_sc)
            cell = build_milling_cell(ref_sc, robot, compensation=False, q_reference=corrected_reference(prediction))
            res = run_cut(ref_sc, robot, compensation=False, cell=cell, progress=progress)
            out["corrected joint reference"] = _short(res.surface_error_mm)
        else:
            if say:
                say(f"proof: the corrected program, on the plant, online {mode} compensation " +
                    ("of the model's residual" if mode != "preview" else "(what its scale estimate adds)"))
            run_sc.controller.mode = mode
            user_models.resolve(run_sc, robot, prediction.q_ref_rad[0])
            if mode == "preview":  # the whole measured wrench; it sends only what its scales add to the program's
                cell = build_milling_cell(run_sc, robot, compensation=True, offline_plan=(
                    prediction.path, prediction.t_ref_s, prediction.q_ref_rad))
            else:
                cell = model_wrench_cell(run_sc, robot, prediction)
            res = run_cut(run_sc, robot, compensation=True, cell=cell, progress=progress)
            out[f"corrected program + online {mode}"] = _short(scanned_against_program(res, prediction.path))
    return out


def rapid_targets(sc, robot, program, corrections, prediction, written_moves):
    """The RAPID module's targets (model/rapid_writer.Target): each written
    block's end in the work frame, the orientation of the corrected pose
    there (the full correction's, FK of the corrected joints at that point
    of the path; the programmed tool-down pose for moves left as they are),
    the configuration from the project's IK at that pose; ``written_moves``
    the corrected program's moves as read back (a move left as programmed
    ends where the controller takes it: an axis it does not name stays
    where the corrected cut left it).  InputError (naming the line) for a
    point the IK cannot reach."""
    from robstiff_drake.diagrams.toolpath import work_transform, work_transform_mm
    from robstiff_drake.model import ik
    from robstiff_drake.model import program_correction as pc
    from robstiff_drake.model import rapid_writer as rw
    from robstiff_drake.model.program_path import program_pieces
    from robstiff_drake.errors import InputError

    tp = sc.toolpath
    _, _, _, _, sources = program_pieces(program.moves, tp.rapid_mm_per_s / 1e3, work_transform(tp))
    element_of = {id(m): i for i, m in enumerate(sources)}
    maps = pc.element_arc_maps(prediction.path)
    to_base = work_transform_mm(tp)
    R_w = work_rotation(sc)
    tool = prediction.tool_m
    yaw = prediction.path.yaw
    s_u, keep = prediction.s_m, np.flatnonzero(np.r_[True, np.diff(prediction.s_m) > 1e-12])
    dh = robot.dh
    q_prev = prediction.q_ref_rad[0]
    quat_prev = None
    targets = []

    def pose_at(p_work, m, frac, corrected):
        p_base = to_base(np.asarray(p_work, dtype=float)) / 1e3
        T = ik.tool_down_pose(p_base, yaw)
        i = element_of.get(id(m))
        if corrected and i is not None and i in maps:
            A, S = maps[i]
            s = float(np.interp(frac * prediction.path.programmed_elements[i].length, A, S))
            u = float(np.interp(s, s_u[keep], prediction.u_s[keep]))
            q = np.array([np.interp(u, prediction.u_s, prediction.q_rad[:, j] + prediction.c_rad[:, j])
                          for j in range(6)])
            T[:3, :3] = kin.tool_pose(dh, q, tool)[:3, :3]
        return T

    def target(p_work, m, frac, corrected):
        nonlocal q_prev, quat_prev
        T = pose_at(p_work, m, frac, corrected)
        try:
            q = ik.solve_for(robot, T, tool, q_ref_rad=q_prev)
        except ik.IKError as e:
            raise InputError(f"{program.path}:{m.line}: the corrected point ({p_work[0]:.3f}, {p_work[1]:.3f}, "
                             f"{p_work[2]:.3f}) mm is out of the robot's reach or limits: {e}") from None
        q_prev = q
        F = kin.frames(dh, q)
        conf = rw.configuration(robot.controller_deg(q), ik.wrist_centre(dh, T, tool), F[1, :3, 3],
                                F[2, :3, 3] - F[1, :3, 3], F[1, :3, 2])
        quat_prev = rw.quaternion(R_w.T @ T[:3, :3], quat_prev)
        return quat_prev, conf

    first = program.moves[0]  # the program's start point (the reader's first point with X, Y and Z known)
    quat, conf = target(np.asarray(first.start_mm, dtype=float), first, 0.0, False)
    targets.append(rw.Target("line", np.asarray(first.start_mm, dtype=float), quat, conf, tp.rapid_mm_per_s, True,
                             first.line))
    k = 0
    for m in program.moves:
        corr = corrections.get(m.line)
        speed = tp.rapid_mm_per_s if m.kind == "rapid" else m.feed_mm_per_min / 60.0
        end = written_moves[k].end_mm if k < len(written_moves) else m.end_mm
        pieces = corr.pieces if corr is not None else [pc.Piece(np.asarray(end, dtype=float), m.center_mm, 1.0)]
        k += len(pieces)
        start = None
        prev_frac = 0.0
        for piece in pieces:
            quat, conf = target(piece.end_mm, m, piece.frac, corr is not None)
            if m.kind == "arc":
                mid = 0.5 * (prev_frac + piece.frac)
                via = pc.move_points(m, [mid])[0]
                if corr is not None:  # the piece's circle halfway: the corrected path there
                    a, b, _ = pc.PLANES[m.plane]
                    c = np.asarray(piece.center_mm, dtype=float)
                    pend = np.asarray(piece.end_mm, dtype=float)
                    s0 = start if start is not None else (targets[-1].pos_mm if targets else np.asarray(m.start_mm))
                    r = float(np.hypot(s0[a] - c[0], s0[b] - c[1]))
                    a0 = np.arctan2(s0[b] - c[1], s0[a] - c[0])
                    a1 = np.arctan2(pend[b] - c[1], pend[a] - c[0])
                    sweep = (a1 - a0) % (2 * np.pi) if not m.clockwise else -((a0 - a1) % (2 * np.pi))
                    am = a0 + 0.5 * sweep
                    via = np.array(s0, dtype=float)
                    via[a], via[b] = c[0] + r * np.cos(am), c[1] + r * np.sin(am)
                    via[pc.PLANES[m.plane][2]] = 0.5 * (s0[pc.PLANES[m.plane][2]] + pend[pc.PLANES[m.plane][2]])
                vq, vc = target(via, m, mid, corr is not None)
                targets.append(rw.Target("arc", np.asarray(piece.end_mm, dtype=float), quat, conf, speed, False,
                                         m.line, via, vq, vc))
            else:
                targets.append(rw.Target("line", np.asarray(piece.end_mm, dtype=float), quat, conf, speed,
                                         m.kind == "rapid", m.line))
            start = np.asarray(piece.end_mm, dtype=float)
            prev_frac = piece.frac
    return targets


def rapid_text(sc, robot, stem, targets, header):
    """The RAPID module (text) of ``targets``: the robot file's tool and
    payload, the work object at the job's work offset and rotation."""
    from robstiff_drake.model import rapid_writer as rw

    tool = robot.tool_point(where="compensate-program")
    return rw.module_text(f"{stem}_compensated", targets, tool_mm=tool * 1e3, payload_mass_kg=robot.payload.mass_kg,
                          payload_com_mm=np.asarray(robot.payload.com_m) * 1e3,
                          wobj_mm=sc.toolpath.work_offset_mm, wobj_quat=rw.quaternion(work_rotation(sc)),
                          zone_mm=sc.path.zone_mm, header_lines=header)


def _short(stats):
    return {k: float(stats[k]) for k in ("mean", "rms", "max_abs") if k in stats}
