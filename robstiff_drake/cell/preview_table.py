"""Preview compensation on a real cell (`compensate --mode preview --job
SCENARIO.yaml`): the whole preview computed before any socket opens, so
that each controller cycle does only the force scales' update and a table
lookup.

Before the loop (cell/preview_job.py's ``build_plan``): the job's planned
path (its program, tool and path section, the robot file's IK every
reference period) is the
joint reference; model/preview.PreviewStream runs over the whole path with
the compensator's own numbers (the identified stiffness of --model, the
robot file's inertias, the job's modal damping, the job's servo or
--servo, the job's force model per coefficient group) and gives each
group's correction c_g(u) and the wrench the sensor should read; that
wrench is passed through the measurement chain's filter once, offline
(systems/preview_correction.PreviewCorrection does this per cycle in the
Drake cell: the same filter, input and lag), and the force scales' Kalman
gains are computed along the table (``scale_gains``): the same numbers as
the block's, cycle by cycle (tests/test_preview_table.py).

Per cycle (``PreviewDeflection``, the plain chain's deflection model with
the preview added; model/compensator.Compensator's saturation, delay line,
rate limit and fault ramp are untouched):

    dq = C J^T [W_measured - sum_g s_g R_g(t) - R_inertia(t)]
         - sum_g s_g c_g(t + lead) - c_inertia(t + lead)

with R the filtered model wrench (the table's), s_g the Kalman estimate of
each group's scale (systems/preview_correction's update, numbers and
limits, with the row's precomputed gain), t the session's time (the
reference's; the nearest row), lead the compensator's own delay line.

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
from collections import deque
from dataclasses import dataclass

import numpy as np
from scipy import signal

from robstiff_drake.model.preview import GROUPS, N_FORCE_GROUPS, ServoModel
from robstiff_drake.systems.preview_correction import MIN_GROUP_FORCE_N, SCALE_LIMITS

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
    sensor: np.ndarray  # (N, 4, 6) the model's sensor wrench per part before the filter (model/preview.py's)
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

def scale_gains(replica, period_s):
    """(N, 3, 3) the force scales' Kalman gain at each row (zero where the
    model's group forces are below MIN_GROUP_FORCE_N: no update) and (N, 3,
    3) the regressor Phi (force components x groups) it multiplies: the
    update of systems/preview_correction.PreviewCorrection, the measurement
    sampled at the last tick against the replica then.  The covariance's
    path depends only on the table, not on the measurements, so it is
    computed here, once (a cycle skipped by a fault leaves the later gains
    a little smaller than the filter's: slower, never faster, learning)."""
    n = len(replica)
    eye = np.eye(N_FORCE_GROUPS)
    P = eye * SCALE_SIGMA ** 2
    Q = eye * SCALE_WALK_PER_S ** 2 * period_s
    R = np.eye(3) * NOISE_N ** 2
    K = np.zeros((n, N_FORCE_GROUPS, 3))
    Phi = np.zeros((n, 3, N_FORCE_GROUPS))
    Phi[1:] = np.swapaxes(replica[:-1, :N_FORCE_GROUPS, :3], 1, 2)
    learns = np.max(np.abs(Phi), axis=(1, 2)) > MIN_GROUP_FORCE_N  # the rows the filter updates on
    learns[0] = False
    inv = np.linalg.inv
    for k in np.flatnonzero(learns).tolist():  # (the same products in the same order: the same bits)
        F = Phi[k]
        P = P + Q
        Kk = K[k] = P @ F.T @ inv(F @ P @ F.T + R)
        P = (eye - Kk @ F) @ P
    return K, Phi


class PreviewDeflection:
    """The compensator's deflection model with the preview: ``dq(process
    wrench, q)`` as model/compensator.DeflectionModel's (the plain chain's,
    ``plain``) but for the bracket and the table's correction (module
    docstring); ``update(loop, msg)`` once per controller cycle before the
    chain's tick (the table's row, the checks, the scales); ``sent(corr)``
    after it.  The table's row is the one nearest the played reference's
    time, ``loop.t_ref`` (the session's time but for a stalled clock's stop
    and restart: cell/reference_rate.py; the controller's clock steps by
    whole periods)."""

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
        self.lead_rows = int(round(plan.lead_s / self.T))
        self.K, self.Phi = scale_gains(plan.replica, self.T)
        self.learns = [bool(np.any(k)) for k in self.K]
        self._inertia = plan.replica[:, -1, :3].tolist()  # the payload's inertial force the model expects (N)
        self._q_plan = plan.q_plan_deg.tolist()
        self._v_plan = plan.v_plan_deg_per_s.tolist()
        self.active = True
        self.fallback = None  # (t_s, why) once the preview stopped
        self.s = np.ones(N_FORCE_GROUPS)
        self._w = np.ones(len(GROUPS))
        self.model_w = [0.0] * 6
        self.c_now = [0.0] * 6
        self.tm0 = self.tm_last = None
        self.t_ctrl = 0.0
        self.out_of_step = 0
        self.t_depart = None
        self._corr = deque(maxlen=max(1, int(round(plan.expected_lag_s / self.T))) + 1)
        self.max_offset_s = 0.0  # the largest |arm's time against the plan's| estimated (s)
        self.max_departure_N = 0.0  # the largest |measured - model| force seen while previewing (N)
        self.learned = 0
        self.k = None  # the last cycle's row

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
    def stop(self, loop, why):
        self.active = False
        self.fallback = (loop.t_ref, why)
        loop.event(f"preview: {why}; plain compensation from now on (the correction moves to the plain chain's at "
                   "the rate limit)")

    def update(self, loop, msg):
        if not self.active:
            return
        t = loop.t_ref  # (the reference's played time: the table is the path's, cell/reference_rate.py)
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
        k = min(max(int((t - self.u0) / self.T + 0.5), 0), self.n - 1)
        if self._sync(loop, k):
            return
        if not loop.faults and self.k is not None:
            w = loop.comp.process_wrench  # sampled at the last tick, against the model's then (row self.k)
            if self.learns[k]:
                self._learn(w, k)
            self._depart(loop, w, t)
            if not self.active:
                return
        self.k = k
        self._w[:N_FORCE_GROUPS] = self.s
        self.model_w = (self._w @ self.p.replica[k]).tolist()
        self.c_now = (self._w @ self.p.c[min(k + self.lead_rows, self.n - 1)]).tolist()

    def sent(self, corr_deg):
        """The correction (controller deg) answered this cycle (for the
        timing check: the feedback carries it back after the lag)."""
        self._corr.append(corr_deg)

    def _sync(self, loop, k):
        """Whether the arm is out of step with the plan (and the preview stopped)."""
        v = self._v_plan[k]
        vv = v[0] * v[0] + v[1] * v[1] + v[2] * v[2] + v[3] * v[3] + v[4] * v[4] + v[5] * v[5]
        if vv * self.sync_s ** 2 < MIN_SYNC_MOTION_DEG ** 2 or loop.q_deg is None or len(self._corr) < self._corr.maxlen:
            self.out_of_step = 0
            return False
        c = self._corr[0]
        ev = sum((q - p - cj) * vj for q, p, cj, vj in zip(loop.q_deg, self._q_plan[k], c, v))
        offset = -ev / vv  # s: positive, the arm behind the plan
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

    def _learn(self, w, k):
        """The force scales' update with the row's precomputed gain (``scale_gains``)."""
        g = self._inertia[k - 1]
        y = np.array([w[0] - g[0], w[1] - g[1], w[2] - g[2]])
        s = self.s + self.K[k] @ (y - self.Phi[k] @ self.s)
        self.s = np.minimum(np.maximum(s, SCALE_LIMITS[0]), SCALE_LIMITS[1])
        self.learned += 1

    def _depart(self, loop, w, t):
        """Stop the preview when the measured force stays beyond the bound from the model's."""
        m = self.model_w
        d = math.sqrt((w[0] - m[0]) ** 2 + (w[1] - m[1]) ** 2 + (w[2] - m[2]) ** 2)
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


