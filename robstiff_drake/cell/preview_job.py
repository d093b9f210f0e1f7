"""`compensate --mode preview --job SCENARIO.yaml`'s inputs: the job read
and checked (its robot, its controller period), its planned path (the
joint reference), the preview's table computed from it before any socket
opens (cell/preview_table.py), and a --reference given too checked
against it.  One line and exit status 2 (InputError) for anything wrong.
"""

import math
import time

import numpy as np

from robstiff_drake.cell.preview_table import PreviewPlan, replica_table
from robstiff_drake.errors import InputError
from robstiff_drake.model.preview import PreviewStream, ServoModel

# How far past the path's end the table runs (s): the run-out and the lead (diagrams/milling_cell.py's).
TABLE_MARGIN_S = 0.5
# --reference, when given with --job, must agree with the job's planned path within this (deg, every row).
REFERENCE_AGREEMENT_DEG = 1e-3


def job_servo(sc, servo_option):
    """The preview's servo model: --servo (DELAY_MS, KP, BW_HZ, FF[, KI_HZ])
    when given (a step test on this controller), else the job's."""
    if servo_option is not None:
        s = list(servo_option)
        return ServoModel(s[0] / 1e3, s[1], s[2], s[4] if len(s) > 4 else 7.5)
    from robstiff_drake.diagrams.user_model import servo_model

    return servo_model(sc)


def load_job(job, robot_yaml, *, period_s):
    """(scenario, robot) of --job; InputError (one line) for a job of
    another robot or another controller period."""
    from robstiff_drake.diagrams.scenario import load_scenario, scenario_robot

    sc = load_scenario(job)
    try:
        robot = scenario_robot(sc, robot_yaml)
    except InputError as e:
        raise InputError(f"--job {job}: {e}") from None
    if abs(sc.controller.period_ms / 1e3 - period_s) > 1e-9:
        raise InputError(f"--job {job}: controller.period_ms {sc.controller.period_ms:g} is not --period-ms "
                         f"{period_s * 1e3:g} (the preview's table is on the controller's cycle)")
    return sc, robot


def build_plan(sc, robot, k_Nm_per_rad, *, period_s, filter_ba, rate_hz, delay_steps, servo_option=None,
               say=None, bar=None):
    """The job's PreviewPlan (before any socket opens).  ``say``: a
    function for progress lines; ``bar``: a function (total) -> progress
    bar (shown when the table takes more than a second)."""
    from robstiff_drake.diagrams.milling_cell import planned_path
    from robstiff_drake.diagrams.scenario_models import COEFFICIENT_GROUPS, model_cutting_setup, model_damping_ratios
    from robstiff_drake.model.arm_dynamics import ArmInertia
    from robstiff_drake.model.realtime import DeflectionPredictor
    from robstiff_drake.systems.preview_correction import PreviewModel

    t0 = time.perf_counter()
    tool = robot.payload.tool_point_m
    T = float(period_s)
    if say:
        say(f"planning the job's path ({sc.source}: IK every {sc.path.reference_period_ms:g} ms)")
    path, t_ref, q_ref = planned_path(sc, robot, tool)
    servo = job_servo(sc, servo_option)
    groups = [model_cutting_setup(sc, groups=g)[1] for g in COEFFICIENT_GROUPS]
    _, _, workpiece = model_cutting_setup(sc)
    kin = DeflectionPredictor(robot.dh, k_Nm_per_rad, tool)
    inertia = ArmInertia(robot)
    pm = PreviewModel(path=path, t_ref=t_ref, q_ref=q_ref, group_models=groups, workpiece=workpiece,
                      kinematics=kin, inertia=inertia, tool_m=tool)
    stream = PreviewStream(pm, period_s=T, compliance=kin.joint_compliance, damping_ratios=model_damping_ratios(sc),
                           servo=servo, motor_inertia_kgm2=inertia.motor_inertia(q_ref[0]), tool_m=tool)
    n = int(math.ceil((path.duration_s + TABLE_MARGIN_S) / T)) + 1
    us, cs, ss = [], [], []
    with bar(n + 2) if bar else _NoBar() as b:
        for k in range(n + 2):
            out = stream.push(k * T)
            b.update(1)
            if out is not None:
                us.append(out[0])
                cs.append(out[1])
                ss.append(out[2])
    u, c, s = np.array(us), np.array(cs), np.array(ss)
    # the controller acts on an answer after its transport delay (the job's controller.delay_steps, as sim-cell
    # does) and the next cycle, then the servo's dead time: the feedback (and the arm's wrench) is that far behind
    # the streamed reference; the wrench also two sensor samples (sensor, guard), as in the Drake cell
    expected = (1 + int(sc.controller.delay_steps)) * T + servo.dead_time_s
    lag = expected + 2.0 / rate_hz
    replica = replica_table(u, s, filter_ba, rate_hz, lag)
    q_deg = robot.controller_deg(np.asarray(q_ref, dtype=float))
    t_ref = np.asarray(t_ref, dtype=float)
    at = np.clip(u - expected, t_ref[0], t_ref[-1])
    q_plan = np.column_stack([np.interp(at, t_ref, q_deg[:, j]) for j in range(6)])
    v_ref = np.gradient(q_deg, t_ref, axis=0) if len(t_ref) > 1 else np.zeros_like(q_deg)
    v_plan = np.column_stack([np.interp(at, t_ref, v_ref[:, j]) for j in range(6)])
    return PreviewPlan(u=u, c=c, replica=replica, sensor=s, q_plan_deg=q_plan, v_plan_deg_per_s=v_plan, t_ref_s=t_ref,
                       q_ref_deg=q_deg, period_s=T, lead_s=int(delay_steps) * T, lag_s=lag, expected_lag_s=expected,
                       servo=servo, seconds=time.perf_counter() - t0)


class _NoBar:
    def __enter__(self):
        return self

    def __exit__(self, *exc):
        return False

    def update(self, n):
        pass


def reference_disagreement(plan, t_s, q_ctrl_deg):
    """None, or why the joint reference (t_s, (N, 6) controller deg) is not
    the job's planned path: the largest difference at its rows, or another
    duration."""
    t = np.asarray(t_s, dtype=float)
    if abs(t[-1] - plan.t_ref_s[-1]) > plan.period_s + 1e-9:
        return f"it lasts {t[-1]:.3f} s, the job's path {plan.t_ref_s[-1]:.3f} s"
    job = np.column_stack([np.interp(t, plan.t_ref_s, plan.q_ref_deg[:, j]) for j in range(6)])
    d = np.abs(np.asarray(q_ctrl_deg, dtype=float) - job)
    i, j = np.unravel_index(int(np.argmax(d)), d.shape)
    if d[i, j] > REFERENCE_AGREEMENT_DEG:
        return (f"q{j + 1} differs by {d[i, j]:.4g} deg at t = {t[i]:.3f} s (at most {REFERENCE_AGREEMENT_DEG:g} "
                "deg)")
    return None


def job_reference(sc, robot, k_Nm_per_rad, *, job, reference, read_reference, period_s, filter_ba, rate_hz,
                  delay_steps, servo):
    """(PreviewPlan, reference times s, reference (N, 6) controller rad):
    the job's planned path, checked as a --reference file is
    (cell/safety.check_reference), and its table, with a line before and
    after and a bar when it takes more than a second.  With --reference
    too (``read_reference()`` waits for it and reads it, after the table):
    that file, refused (one line) unless it is the job's path."""
    import sys

    from robstiff_drake.cell.safety import check_reference
    from robstiff_drake.progress import info, progress

    def say(text):
        info(f"robstiff: compensate: {text}", file=sys.stderr)

    def bar(total):
        return progress(total, None, "preview table", unit="cycle", delay=1.0, leave=False)

    plan = build_plan(sc, robot, k_Nm_per_rad, period_s=period_s, filter_ba=filter_ba, rate_hz=rate_hz,
                      delay_steps=delay_steps, servo_option=servo, say=say, bar=bar)
    check_reference(f"--job {job} (its planned path)", robot, plan.t_ref_s, plan.q_ref_deg, period_s)
    say(f"preview table of {job}: {len(plan.u)} cycles ({plan.u[-1]:.2f} s) computed in {plan.seconds:.2f} s")
    if reference is None:
        return plan, plan.t_ref_s, np.radians(plan.q_ref_deg)
    t_ref, q_ref = read_reference()
    why = reference_disagreement(plan, t_ref, np.degrees(q_ref))
    if why:
        raise InputError(f"--reference {reference}: not the planned path of --job {job}: {why}; drop --reference "
                         "(the job's path is streamed) or write it from the job (robstiff simulate JOB --out RUN)")
    return plan, t_ref, q_ref

