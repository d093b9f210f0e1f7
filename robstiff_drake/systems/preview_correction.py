"""Preview compensation as a Drake block: the correction the planned path
will need through the arm's dynamics (model/preview.py, computed ahead),
scaled by the cutting-force model's per-group scale as measured during the
cut, plus the static deflection of what the model still misses:

    dq = -sum_g s_g c_g(t + lead) - c_inertia(t + lead)
         + C J^T [W_measured - filter(sum_g s_g W_g + W_inertia)]

c_g are the correction's parts of the force model's coefficient groups
(tangential, radial, axial) and of the path's inertia, ``lead`` is when a
correction computed now reaches the robot controller's input (the
compensator's delay line and half a period of hold), W_g the model's
wrench per group as the wrist sensor would read it, passed through an
exact replica of the measurement chain (the force filter at the sensor
rate, fed as late as the sensor, the guard and the arm's own lag behind
its reference deliver it).  s_g: a Kalman estimate of each group's scale
(prior 1 +- the model's stated uncertainty) from the filtered measured
force against the replica's groups, updated every period while the cut
is loaded: a force model off by 20 % is corrected once the cut has been
felt, so the corners and exits after it are previewed at the right size.

On top of a program already corrected offline for the same model
(``offline=True``: diagrams/offline_compensation.py, the program written
with the model's correction at scale 1 and the path's inertia), the
feed-forward the program holds is not sent again: only what the scale
estimate adds to it,

    dq = -sum_g (s_g - 1) c_g(t + lead)
         + C J^T [W_measured - filter(sum_g s_g W_g + W_inertia)]

with the table computed on the plan the program was corrected for (the
programmed path, where the corrected program puts the tool): with an exact
model the measured wrench is the replica's, the scales stay at one, and
the correction is zero.  There the scales learn only where the model's
force is steady (STEADY_WINDOW_S), and its bracket (measured less the
scaled model) is heard only there too: at a cut's entry the measured force
rises later than the model's (its engagement's timing, not its
coefficients), and a scale learned there, or the bracket heard there,
would take back part of the program's correction.

The arithmetic of the bracket's deflection is model/compensator.
DeflectionModel's, shared with the plain chain."""

import numpy as np
from robstiff_drake.systems.leaf_system import LeafSystem
from scipy import signal
from scipy.interpolate import CubicSpline

from robstiff_drake.model.preview import GROUPS, N_FORCE_GROUPS

MIN_GROUP_FORCE_N = 10.0  # the scales learn only while the model's filtered group forces reach this
# on top of a program corrected offline, the scales learn, and the bracket (measured less the scaled model) is
# heard, only where the model's force is steady: over the last STEADY_WINDOW_S (checked every 50 ms) its change
# stays within STEADY_FRACTION of it.  At an entry the model's engagement timing, not its coefficients, is what
# differs from the cut's: measured on face_and_contour with the plant's chip turning with the tool's real motion,
# the measured force reached the model's ~0.5 s after the model's had at the plate's edge (with a 50 ms window
# and the bracket always heard: +0.157/0.288 mm mean/max on the unrefined corrected program; 0.6 s for both:
# +0.062/0.101; without online compensation +0.022/0.066)
STEADY_WINDOW_S = 0.6
STEADY_FRACTION = 0.1
SCALE_LIMITS = (0.3, 2.0)  # a scale beyond these is not a coefficient error but another process


class PreviewModel:
    """The compensator's knowledge for model/preview.PreviewStream: the
    planned path and its joint references, the force model per coefficient
    group (MillingForceModel each), the workpiece, its kinematics
    (DeflectionPredictor) and inertia (model/arm_dynamics.ArmInertia)."""

    def __init__(self, *, path, t_ref, q_ref, group_models, workpiece, kinematics, inertia, tool_m):
        self.path = path
        self._t = np.asarray(t_ref, dtype=float)
        self._q = np.asarray(q_ref, dtype=float)
        self._spline = CubicSpline(self._t, self._q, axis=0)
        self.groups = list(group_models)
        self.wp = workpiece
        self.kin = kinematics
        self.inertia = inertia
        self.payload = inertia.payload
        self._tool = np.asarray(tool_m, dtype=float)

    def q(self, u):
        """The joint reference at path time u: a C2 cubic spline through the
        IK samples (a preview period shorter than theirs needs smooth second
        differences), held at the ends."""
        return self._spline(min(max(u, self._t[0]), self._t[-1]))

    def force_groups(self, u):
        p, d = self.path.position(u), self.path.feed_direction(u)
        feed = self.path.programmed_speed(u)
        return np.array([m.average_wrench(p, d, self.wp, feed) for m in self.groups])

    def jacobian(self, q):
        return np.array(self.kin.jacobian_rows(q)).T

    def flange_rotation(self, q):
        return self.kin.pose(q)[:9]

    def mass(self, q):
        return self.inertia.mass_matrix(q)

    def payload_com_jacobian(self, q):
        """(3, 6): from the tool point's Jacobian, z_j x (p_c - o_j) =
        z_j x (p_t - o_j) + z_j x (p_c - p_t), p_c - p_t = R6 (c - tool)."""
        J = np.array(self.kin.jacobian_rows(q)).T
        R = np.asarray(self.kin.pose(q)[:9]).reshape(3, 3)
        d = R @ (self.payload[1] - self._tool)
        Jw = J[3:]
        return J[:3] + np.array([Jw[1] * d[2] - Jw[2] * d[1], Jw[2] * d[0] - Jw[0] * d[2], Jw[0] * d[1] - Jw[1] * d[0]])


class PreviewCorrection(LeafSystem):
    """Inputs ``process_wrench`` (6, sensor frame: measured, filtered,
    gravity-free, sampled at the last tick) and ``q`` (6, rad); output
    ``dq`` (6, rad): the deflection the correction cancels (the chain's
    saturation, delay and rate limit follow).  ``table``: (u, c (N, 4, 6),
    sensor (N, 4, 6)) from model/preview.preview_table; ``deflection``: the
    compensator's DeflectionModel; ``lag_s``: the measured wrench's lag
    behind the model's at the same path time (the arm's dead time behind its
    reference and two sensor samples); ``scale_sigma``: the prior's
    standard deviation of each group's scale; ``noise_N``: of the filtered
    force against the model's; ``offline``: the reference is a program
    already corrected for the table's model at scale 1 (module docstring),
    so the feed-forward sent is only each force group's part times its
    scale less one (the inertia's part none)."""

    def __init__(self, *, table, deflection, filter_ba, rate_hz, period_s, lead_s, lag_s, scale_sigma=0.25,
                 noise_N=3.0, scale_walk_per_s=0.01, learn=True, offline=False):
        super().__init__()
        self._u, self._c, self._s = (np.asarray(a, dtype=float) for a in table)
        self._model = deflection
        self._h = 1.0 / rate_hz
        self._n_sub = max(1, int(round(period_s * rate_hz)))
        self._lead = float(lead_s)
        self._lag = float(lag_s)
        A, B, C, D = signal.tf2ss(*filter_ba)
        self._A, self._B, self._C, self._D = A, B[:, 0], (C[0] if A.shape[0] else np.zeros(0)), float(np.squeeze(D))
        self._nf = A.shape[0]
        self._ng = len(GROUPS)
        self._learn = bool(learn)
        self._offline = bool(offline)
        self._P0 = np.eye(N_FORCE_GROUPS) * scale_sigma ** 2
        self._R = np.eye(3) * noise_N ** 2
        self._Q = np.eye(N_FORCE_GROUPS) * scale_walk_per_s ** 2 * period_s
        nx = self._nf * self._ng * 6
        self._nx = nx
        # replica states, then the scales (3), their covariance (9) and the tick time
        x0 = np.concatenate([np.zeros(nx), np.ones(N_FORCE_GROUPS), self._P0.ravel(), [0.0]])
        self._state = self.DeclareDiscreteState(x0)
        self._w = self.DeclareVectorInputPort("process_wrench", 6)
        self._q = self.DeclareVectorInputPort("q", 6)
        self.DeclarePeriodicDiscreteUpdateEvent(period_s, 0.0, self._update)
        deps = {self._w.ticket(), self._q.ticket(), self.discrete_state_ticket(self._state)}
        self.DeclareVectorOutputPort("dq", 6, self._calc, prerequisites_of_calc=deps)
        self.DeclareVectorOutputPort("scales", N_FORCE_GROUPS, self._calc_scales,
                                     prerequisites_of_calc={self.discrete_state_ticket(self._state)})

    # -- the precomputed preview, at a path time ---------------------------------------------------------------------
    def _at(self, table, u):
        """Linear interpolation of a (N, 4, 6) table at path time u (held at the ends)."""
        uu = self._u
        if u <= uu[0]:
            return table[0]
        if u >= uu[-1]:
            return table[-1]
        i = int(np.searchsorted(uu, u, side="right")) - 1
        a = (u - uu[i]) / (uu[i + 1] - uu[i])
        return (1.0 - a) * table[i] + a * table[i + 1]

    def _split(self, x):
        nx = self._nx
        X = x[:nx].reshape(self._nf, self._ng * 6) if self._nf else np.zeros((0, self._ng * 6))
        s = x[nx:nx + N_FORCE_GROUPS]
        P = x[nx + N_FORCE_GROUPS:nx + N_FORCE_GROUPS + 9].reshape(3, 3)
        return X, s, P, x[-1]

    def _replica(self, X, t):
        """The replica's output (4, 6) at tick time t for its state X."""
        u = self._at(self._s, t - self._lag).ravel()
        y = (self._C @ X if self._nf else 0.0) + self._D * u
        return np.asarray(y).reshape(self._ng, 6)

    def _steady(self, t):
        """Whether the model's force (all groups, before the filter) at the
        path time the measurement at tick ``t`` belongs to has changed by
        less than STEADY_FRACTION of itself over STEADY_WINDOW_S (checked
        every 50 ms of it)."""
        now = self._at(self._s, t - self._lag)[:N_FORCE_GROUPS, :3].sum(axis=0)
        for back in np.arange(STEADY_WINDOW_S, 0.0, -0.05):
            then = self._at(self._s, t - self._lag - back)[:N_FORCE_GROUPS, :3].sum(axis=0)
            if float(np.linalg.norm(now - then)) > STEADY_FRACTION * float(np.linalg.norm(now)):
                return False
        return True

    def _update(self, context, discrete_state):
        x = context.get_discrete_state(self._state).value()
        X, s, P, t_last = self._split(x)
        t = context.get_time()
        if self._learn and t > 0:
            Y = self._replica(X, t_last)  # what the measurement sampled at the last tick is compared with
            Phi = Y[:N_FORCE_GROUPS, :3].T  # (3 force components, 3 groups)
            if np.max(np.abs(Phi)) > MIN_GROUP_FORCE_N and (not self._offline or self._steady(t_last)):
                y = self._w.Eval(context)[:3] - Y[-1, :3]
                P = P + self._Q
                S = Phi @ P @ Phi.T + self._R
                K = P @ Phi.T @ np.linalg.inv(S)
                s = np.clip(s + K @ (y - Phi @ s), *SCALE_LIMITS)
                P = (np.eye(N_FORCE_GROUPS) - K @ Phi) @ P
        for j in range(self._n_sub, 0, -1):
            u = self._at(self._s, t - j * self._h - self._lag).ravel()
            if self._nf:
                X = self._A @ X + np.outer(self._B, u)
        discrete_state.set_value(self._state, np.concatenate([X.ravel(), s, P.ravel(), [t]]))

    def _calc(self, context, output):
        x = context.get_discrete_state(self._state).value()
        X, s, _, t = self._split(x)
        weights = np.r_[s, 1.0]
        model = weights @ self._replica(X, t)
        q = self._q.Eval(context)
        bracket = self._w.Eval(context) - model
        if self._offline and not self._steady(t):  # at an entry the difference is timing
            bracket = np.zeros(6)
        dq_fb = np.asarray(self._model.dq(bracket, q), dtype=float)
        ff = np.r_[s - 1.0, 0.0] if self._offline else weights  # what the reference does not already hold
        c = ff @ self._at(self._c, context.get_time() + self._lead)
        output.SetFromVector(dq_fb - c)

    def _calc_scales(self, context, output):
        output.SetFromVector(self._split(context.get_discrete_state(self._state).value())[1])
