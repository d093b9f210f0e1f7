"""Preview compensation on a real cell (`compensate --mode preview --job
SCENARIO.yaml`): the whole preview computed before any socket opens, so
that each controller cycle does only the force scales' update and a table
lookup.

Before the loop (``build_plan``): the job's planned path (its program,
tool and path section, the robot file's IK every reference period) is the
joint reference; model/preview.PreviewStream runs over the whole path with
the compensator's own numbers (the identified stiffness of --model, the
robot file's inertias, the job's modal damping, the job's servo or
--servo, the job's force model per coefficient group) and gives each
group's correction c_g(u) and the wrench the sensor should read; that
wrench is passed through the measurement chain's filter once, offline
(systems/preview_correction.PreviewCorrection does this per cycle in the
Drake cell: the same filter, input and lag, so the same numbers).

Per cycle (``PreviewDeflection``, the plain chain's deflection model with
the preview added; model/compensator.Compensator's saturation, delay line,
rate limit and fault ramp are untouched):

    dq = C J^T [W_measured - sum_g s_g R_g(t) - R_inertia(t)]
         - sum_g s_g c_g(t + lead) - c_inertia(t + lead)

with R the filtered model wrench (the table's), s_g the Kalman estimate of
each group's scale (systems/preview_correction's update, numbers and
limits), t the session's time (the reference's), lead the compensator's
own delay line.

Preview faults fall back to plain compensation for the rest of the run
(the correction moves from the preview's to the plain chain's at the rate
limit; one log line says why): the table ends; the controller's clock and
the table's time part by more than ``sync_s``; the arm's feedback says it
is more than ``sync_s`` behind or ahead of where the plan puts it
(``SYNC_CYCLES`` cycles in a row); the measured force departs from the
model's by more than ``force_bound`` for ``DEPART_S``.  Plain compensation
needs no plan, so it stays valid whatever went out of step.

Units: times s, angles rad inside (the model's joints), the controller's
degrees for the feedback; wrenches N and N*m in the sensor frame.
"""

import math
import time
from collections import deque
from dataclasses import dataclass

import numpy as np
from scipy import signal

from robstiff_drake.errors import InputError
from robstiff_drake.model.preview import GROUPS, N_FORCE_GROUPS, PreviewStream, ServoModel
from robstiff_drake.systems.preview_correction import MIN_GROUP_FORCE_N, SCALE_LIMITS

# How far past the path's end the table runs (s): the run-out and the lead (diagrams/milling_cell.py's).
TABLE_MARGIN_S = 0.5
# --reference, when given with --job, must agree with the job's planned path within this (deg, every row).
REFERENCE_AGREEMENT_DEG = 1e-3
SYNC_CYCLES = 5  # cycles in a row the arm must be out of step with the plan before the preview stops
# ASSUMPTION: the feedback resolves a position along the path of this much (deg); below it (the plan at rest or
# crawling) the arm's time along the plan is not estimated.
MIN_SYNC_MOTION_DEG = 0.005
DEPART_S = 0.1  # the measured force beyond the bound for this long (s) stops the preview
SCALE_SIGMA = 0.25  # the prior's standard deviation of each group's scale (systems/preview_correction's default)
NOISE_N = 3.0  # of the filtered force against the model's (N)
SCALE_WALK_PER_S = 0.01


@dataclass
class PreviewPlan:
    """Everything the per-cycle work reads, computed before the loop.
    ``u`` (N,) s on the controller period's grid; ``c`` (N, 4, 6) rad the
    correction's parts (three force groups, the path's inertia);
    ``replica`` (N, 4, 6) the model's sensor wrench per part through the
    force filter, lagged as the measurement is; ``q_plan_deg`` and
    ``v_plan_deg_per_s`` (N, 6): the plan in the controller's degrees at
    ``u - expected_lag_s`` (where the feedback should be) and its speed."""

    u: np.ndarray
    c: np.ndarray
    replica: np.ndarray
    q_plan_deg: np.ndarray
    v_plan_deg_per_s: np.ndarray
    t_ref_s: np.ndarray  # the reference's rows (s) and angles (controller deg): what is streamed
    q_ref_deg: np.ndarray
    period_s: float
    lead_s: float
    lag_s: float  # the measured wrench behind the model's at the same path time
    expected_lag_s: float  # the feedback behind the streamed reference (transport and the servo's dead time)
    servo: ServoModel
    seconds: float  # the precomputation's wall time


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
    from robstiff_drake.diagrams.scenario import COEFFICIENT_GROUPS, model_cutting_setup, model_damping_ratios
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
    return PreviewPlan(u=u, c=c, replica=replica, q_plan_deg=q_plan, v_plan_deg_per_s=v_plan, t_ref_s=t_ref,
                       q_ref_deg=q_deg, period_s=T, lead_s=int(delay_steps) * T, lag_s=lag, expected_lag_s=expected,
                       servo=servo, seconds=time.perf_counter() - t0)


class _NoBar:
    def __enter__(self):
        return self

    def __exit__(self, *exc):
        return False

    def update(self, n):
        pass


def replica_table(u, sensor, filter_ba, rate_hz, lag_s):
    """(N, 4, 6): the model's sensor wrench per part (``sensor`` (N, 4, 6) on
    the grid ``u``) at the sensor's rate, delayed by ``lag_s`` (held at the
    ends), through the force filter ``filter_ba`` from rest, sampled at each
    u: systems/preview_correction.PreviewCorrection's replica, offline."""
    h = 1.0 / rate_hz
    n_dense = int(math.ceil(u[-1] / h)) + 1
    t = np.arange(n_dense) * h - lag_s
    flat = sensor.reshape(len(u), -1)
    x = np.column_stack([np.interp(t, u, flat[:, i]) for i in range(flat.shape[1])])
    b, a = filter_ba
    y = signal.lfilter(b, a, x, axis=0)
    idx = np.clip(np.rint(u / h).astype(int), 0, n_dense - 1)
    return y[idx].reshape(sensor.shape)


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


class PreviewDeflection:
    """The compensator's deflection model with the preview: ``dq(process
    wrench, q)`` as model/compensator.DeflectionModel's (the plain chain's,
    ``plain``) but for the bracket and the table's correction (module
    docstring); ``update(loop, msg)`` once per controller cycle before the
    chain's tick (the table's time, the checks, the scales)."""

    def __init__(self, plain, plan, *, sync_s, force_bound_N, force_bound_fraction):
        self.plain = plain
        self.p = plan
        self.sync_s = float(sync_s)
        self.bound_N = float(force_bound_N)
        self.bound_frac = float(force_bound_fraction)
        self.T = plan.period_s
        self.n = len(plan.u)
        self.u0 = float(plan.u[0])
        self.end_s = float(plan.u[-1]) - plan.lead_s
        self.active = True
        self.fallback = None  # (t_s, why) once the preview stopped
        self.s = np.ones(N_FORCE_GROUPS)
        self.P = np.eye(N_FORCE_GROUPS) * SCALE_SIGMA ** 2
        self._Q = np.eye(N_FORCE_GROUPS) * SCALE_WALK_PER_S ** 2 * self.T
        self._R = np.eye(3) * NOISE_N ** 2
        self._w = np.ones(len(GROUPS))
        self.model_w = np.zeros(6)
        self.c_now = np.zeros(6)
        self._Y_last = None
        self.tm0 = self.tm_last = None
        self.t_ctrl = 0.0
        self.out_of_step = 0
        self.t_depart = None
        self._corr = deque(maxlen=max(1, int(round(plan.expected_lag_s / self.T))) + 1)
        self.max_offset_s = 0.0  # the largest |arm's time against the plan's| estimated (s)
        self.max_departure_N = 0.0  # the largest |measured - model| force seen while previewing (N)
        self.learned = 0

    # -- what the chain calls -------------------------------------------------------------------------------------
    def dq(self, process_wrench, q):
        if not self.active:
            return self.plain.dq(process_wrench, q)
        bracket = [w - m for w, m in zip(process_wrench, self.model_w)]
        fb = self.plain.dq(bracket, q)
        return [f - c for f, c in zip(fb, self.c_now)]

    def tool_wrench(self, process_wrench, q):
        return self.plain.tool_wrench(process_wrench, q)

    # -- once per cycle -------------------------------------------------------------------------------------------
    def _row(self, table, t):
        x = (t - self.u0) / self.T
        i = int(x)
        if i >= self.n - 1:
            return table[-1]
        if x <= 0.0:
            return table[0]
        a = x - i
        return table[i] + a * (table[i + 1] - table[i])

    def stop(self, loop, why):
        self.active = False
        self.fallback = (loop.t_session, why)
        loop.event(f"preview: {why}; plain compensation from now on (the correction moves to the plain chain's at "
                   "the rate limit)")

    def update(self, loop, msg):
        if not self.active:
            return
        t = loop.t_session
        if t > self.end_s:
            return self.stop(loop, f"the job's table ended (t = {t:.3f} s, table to {self.end_s:.3f} s)")
        tm = msg.tm_ms
        if self.tm0 is None:
            self.tm0 = self.tm_last = tm
        else:
            d = (tm - self.tm_last) % 2**32
            self.t_ctrl += (d - 2**32 if d >= 2**31 else d) * 1e-3
            self.tm_last = tm
            if tm != self.tm0 and abs(self.t_ctrl - t) > self.sync_s:
                return self.stop(loop, f"the controller's clock ({self.t_ctrl:.3f} s since the first message) and "
                                       f"the table's time ({t:.3f} s) differ by more than {self.sync_s * 1e3:g} ms")
        if self._sync(loop, t):
            return
        Y = self._row(self.p.replica, t)
        if not loop.faults:
            self._learn(loop.comp.process_wrench)
            self._depart(loop, loop.comp.process_wrench, t)
            if not self.active:
                return
        self._Y_last = Y
        self._w[:N_FORCE_GROUPS] = self.s
        self.model_w = (self._w @ Y).tolist()
        self.c_now = (self._w @ self._row(self.p.c, t + self.p.lead_s)).tolist()

    def sent(self, corr_deg):
        """The correction (controller deg) answered this cycle (for the
        timing check: the feedback carries it back after the lag)."""
        self._corr.append(corr_deg)

    def _sync(self, loop, t):
        """Whether the arm is out of step with the plan (and the preview stopped)."""
        v = self._row(self.p.v_plan_deg_per_s, t)
        vv = float(v @ v)
        if vv * self.sync_s ** 2 < MIN_SYNC_MOTION_DEG ** 2 or loop.q_deg is None or len(self._corr) < self._corr.maxlen:
            self.out_of_step = 0
            return False
        e = np.asarray(loop.q_deg) - self._row(self.p.q_plan_deg, t) - np.asarray(self._corr[0])
        offset = -float(e @ v) / vv  # s: positive, the arm behind the plan
        self.max_offset_s = max(self.max_offset_s, abs(offset))
        if abs(offset) <= self.sync_s:
            self.out_of_step = 0
            return False
        self.out_of_step += 1
        if self.out_of_step < SYNC_CYCLES:
            return False
        self.stop(loop, f"the arm is {abs(offset) * 1e3:.0f} ms {'behind' if offset > 0 else 'ahead of'} the plan "
                        f"(feedback against the job's path for {SYNC_CYCLES} cycles; at most {self.sync_s * 1e3:g} ms)")
        return True

    def _learn(self, w):
        """The force scales' Kalman update (systems/preview_correction's),
        the measurement sampled at the last tick against the replica then."""
        Y = self._Y_last
        if Y is None:
            return
        Phi = Y[:N_FORCE_GROUPS, :3].T
        if np.max(np.abs(Phi)) <= MIN_GROUP_FORCE_N:
            return
        y = np.asarray(w[:3]) - Y[-1, :3]
        P = self.P + self._Q
        S = Phi @ P @ Phi.T + self._R
        K = P @ Phi.T @ np.linalg.inv(S)
        self.s = np.clip(self.s + K @ (y - Phi @ self.s), *SCALE_LIMITS)
        self.P = (np.eye(N_FORCE_GROUPS) - K @ Phi) @ P
        self.learned += 1

    def _depart(self, loop, w, t):
        """Stop the preview when the measured force stays beyond the bound from the model's."""
        m = self.model_w
        d = math.sqrt(sum((a - b) ** 2 for a, b in zip(w[:3], m[:3])))
        self.max_departure_N = max(self.max_departure_N, d)
        bound = self.bound_N + self.bound_frac * math.sqrt(m[0] ** 2 + m[1] ** 2 + m[2] ** 2)
        if d <= bound:
            self.t_depart = None
            return
        if self.t_depart is None:
            self.t_depart = t
        elif t - self.t_depart >= DEPART_S:
            self.stop(loop, f"the measured force departs from the job's model by {d:.0f} N (more than {bound:.0f} N "
                            f"for {DEPART_S * 1e3:.0f} ms): not the cut the job describes")

    def summary(self):
        return {"active_at_end": self.active,
                "fallback": None if self.fallback is None else {"t_s": self.fallback[0], "why": self.fallback[1]},
                "force_scales": [float(v) for v in self.s], "scale_updates": self.learned,
                "max_plan_offset_ms": self.max_offset_s * 1e3, "max_force_departure_N": self.max_departure_N,
                "table_rows": self.n, "lead_s": self.p.lead_s, "lag_s": self.p.lag_s,
                "expected_feedback_lag_s": self.p.expected_lag_s, "precompute_s": self.p.seconds}


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
