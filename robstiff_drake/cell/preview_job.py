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


def reference_disagreement(t_plan_s, q_plan_deg, period_s, t_s, q_ctrl_deg):
    """None, or why the joint reference (t_s, (N, 6) controller deg) is not
    the job's planned path (``t_plan_s``, ``q_plan_deg`` controller deg): the
    largest difference at its rows, or another duration."""
    t = np.asarray(t_s, dtype=float)
    if abs(t[-1] - t_plan_s[-1]) > period_s + 1e-9:
        return f"it lasts {t[-1]:.3f} s, the job's path {t_plan_s[-1]:.3f} s"
    job = np.column_stack([np.interp(t, t_plan_s, q_plan_deg[:, j]) for j in range(6)])
    d = np.abs(np.asarray(q_ctrl_deg, dtype=float) - job)
    i, j = np.unravel_index(int(np.argmax(d)), d.shape)
    if d[i, j] > REFERENCE_AGREEMENT_DEG:
        return (f"q{j + 1} differs by {d[i, j]:.4g} deg at t = {t[i]:.3f} s (at most {REFERENCE_AGREEMENT_DEG:g} "
                "deg)")
    return None


def table_file(sc, robot, k_Nm_per_rad, t_plan_s=None, q_plan_rad=None, *, period_s, filter_ba, rate_hz,
               delay_steps, servo):
    """The disk cache's file of this job's table with these numbers
    (cell/preview_cache.py; None: no writable cache folder); ``t_plan_s``,
    ``q_plan_rad``: the planned path when at hand."""
    from robstiff_drake.cell import preview_cache

    if t_plan_s is None:
        from robstiff_drake.diagrams.milling_cell import planned_path

        _, t_plan_s, q_plan_rad = planned_path(sc, robot, robot.payload.tool_point_m)
    return preview_cache.file_for(preview_cache.key(sc, robot, k_Nm_per_rad, t_plan_s, q_plan_rad, period_s=period_s,
                                                    filter_ba=filter_ba, rate_hz=rate_hz, delay_steps=delay_steps,
                                                    servo_option=servo))


def job_reference(sc, robot, k_Nm_per_rad, *, job, reference, read_reference, period_s, filter_ba, rate_hz,
                  delay_steps, servo):
    """(PreviewPlan or None, its cache file, reference times s, reference
    (N, 6) controller rad): the job's planned path (the IK, kept on disk:
    diagrams/reference_cache.py), checked as a --reference file is
    (cell/safety.check_reference), and its table when the disk cache holds
    it (cell/preview_cache.py; None: ``BackgroundTable`` computes it while
    the loop runs).  With --reference too (``read_reference()`` waits for it
    and reads it): that file, refused (one line) unless it is the job's path."""
    import sys

    from robstiff_drake.cell import preview_cache
    from robstiff_drake.cell.safety import check_reference
    from robstiff_drake.diagrams.milling_cell import planned_path
    from robstiff_drake.progress import info

    def say(text):
        info(f"robstiff: compensate: {text}", file=sys.stderr)

    _, t_plan, q_plan = planned_path(sc, robot, robot.payload.tool_point_m)
    t_plan = np.asarray(t_plan, dtype=float)
    q_deg = robot.controller_deg(np.asarray(q_plan, dtype=float))
    check_reference(f"--job {job} (its planned path)", robot, t_plan, q_deg, period_s,
                    finer_fix="set the job's path.reference_period_ms to {period_ms} (its IK's step)")
    file = table_file(sc, robot, k_Nm_per_rad, t_plan, q_plan, period_s=period_s, filter_ba=filter_ba,
                      rate_hz=rate_hz, delay_steps=delay_steps, servo=servo)
    plan = preview_cache.load(file)
    if plan is not None:
        say(f"preview table of {job}: {len(plan.u)} cycles ({plan.u[-1]:.2f} s), from the disk cache ({file.name})")
    else:
        say(f"preview table of {job}: not in the disk cache; computed in another process while the loop runs "
            "(plain compensation until it is ready)")
    if reference is None:
        return plan, file, t_plan, np.radians(q_deg)
    t_ref, q_ref = read_reference()
    why = reference_disagreement(t_plan, q_deg, period_s, t_ref, np.degrees(q_ref))
    if why:
        raise InputError(f"--reference {reference}: not the planned path of --job {job}: {why}; drop --reference "
                         "(the job's path is streamed) or write it from the job (robstiff simulate JOB --out RUN)")
    return plan, file, t_ref, q_ref


class BackgroundTable:
    """The job's table computed in a process of its own
    (cell/preview_cache.py's build, started at once: while compensate waits
    for the controller's first message and then answers it), read back and
    made the loop's PreviewDeflection (``make_preview(plan)``) in a thread
    below the loop's priority.  The loop polls ``done`` (an attribute) and
    then takes ``preview`` (None: ``error`` says why); it never waits."""

    def __init__(self, spec_json, file):
        import subprocess
        import threading

        from robstiff_drake.cell import preview_cache

        self.done = False
        self.preview = None
        self.error = None
        self.seconds = float("nan")
        self.taken_at_s = None  # the session's time (s) the loop took it at
        self._file, self._make = file, None
        self._t0 = time.monotonic()
        self._proc = subprocess.Popen(preview_cache.build_command(), stdin=subprocess.PIPE,
                                      stdout=subprocess.DEVNULL, stderr=subprocess.PIPE, text=True)
        self._thread = threading.Thread(target=self._run, args=(spec_json,), name="robstiff-preview", daemon=True)

    def then(self, make_preview):
        """Make the PreviewDeflection with ``make_preview(plan)`` once the
        table is built (the process runs from the constructor on)."""
        self._make = make_preview
        self._thread.start()
        return self

    def _run(self, spec_json):
        from robstiff_drake.cell import preview_cache
        from robstiff_drake.cell.start_gate import below_the_loop

        try:
            _, err = self._proc.communicate(spec_json)
            below_the_loop()  # (the loop's start may have made this thread real-time meanwhile)
            if self._proc.returncode != 0:
                lines = [ln for ln in err.splitlines() if ln.strip()]
                self.error = lines[-1].removeprefix("robstiff: error: ") if lines else \
                    f"its process ended with status {self._proc.returncode}"
                return
            plan = preview_cache.load(self._file)
            if plan is None:
                self.error = f"its file {self._file} could not be read back"
                return
            self.preview = self._make(plan)
        except Exception as e:  # (the preview is an addition: plain compensation stands without it)
            self.error = f"{type(e).__name__}: {e}"
        finally:
            self.seconds = time.monotonic() - self._t0
            self.done = True

    def stop(self):
        """At the run's end: the build's process ended if it still runs."""
        if self._proc.poll() is None:
            self._proc.kill()
        if self._thread.is_alive():
            self._thread.join(30)
        elif self._make is None:
            self._proc.communicate()  # (never taken: its pipes closed)

    def note(self):
        """What became of the table (for the summary and the last lines)."""
        if self.taken_at_s is not None and self.preview is not None:
            return (f"computed in another process in {self.seconds:.2f} s; plain compensation until t = "
                    f"{self.taken_at_s:.3f} s, previewing from then")
        if self.done and self.preview is None:
            return f"could not be computed ({self.error}): plain compensation throughout"
        return "not ready before the run ended: plain compensation throughout"
