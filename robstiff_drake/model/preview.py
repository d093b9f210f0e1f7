"""Preview compensation (beyond the paper): the correction for what the arm
*will* do, from the planned path, the cutting-force model and a model of
the arm's dynamics, so that the correction anticipates the arm's response
instead of chasing the static deflection.  Plain numpy; no Drake, and
nothing of the plant's own code: the compensator's own models only.

The arm about the planned path, linearised (joint space, link side), the
form of the plant's joints (model/joint_dynamics.py) with the compensator's
own numbers:

    M(q) q''     = K (theta - q) + D (theta' - q') + J^T W
    J_m theta''  = tau_drive - K (theta - q) - D (theta' - q')

with q the link angles, theta the motors' (link-side units), K the
compensator's (identified) joint stiffness, D its modal damping (each mode
of the links on their gears, M against K, gets the damping ratio zeta_i:
D = M Phi diag(2 zeta_i omega_i) Phi^T M; the stated ratios are the
drives-closed modes', what a modal test with the drives on measures, and
zeta_i the motors-held ratios that realise them with the compensator's
drives at the path's first pose, as the plant's joints do:
model/joint_dynamics.realise_drives_closed), W the cutting wrench at the
tool point, M the robot file's nominal inertias (ArmInertia) and J_m the
motors' rotor inertias (the robot file's, or its stated assumption).  For
the links to stay on the path q_p the motors must lead it by the gears'
twist d, and the gears then carry f = M q_p'' - J^T W:

    K d + D d' = f

The robot controller moves the motor by a correction c sent with the
path's joint reference, after the same dead time (it cancels) and through
its position loop (gain Kp) and its velocity loop (a PI: gain K_v =
omega_v (J_m + M_jj), the rigid axis's tuning, integral corner omega_i)
without feed-forward; the path's own reference comes with velocity
feed-forward and so needs no correction but for the torque the drive has
to find.  Solving the drive's equation for c with theta = q_p + d:

    c = d + d' / Kp + s / (s + omega_i) [J_m (q_p'' + d'') + f] / (K_v Kp)

the last term being the drive's own give under the torque it supplies
(the gears' pull and the motor's inertia), which its integral action
removes at low frequency (ServoModel: the dead time, Kp, omega_v and
omega_i; identified from a step test: diagrams/user_model.py).

``PreviewStream`` computes c one sample ahead per controller cycle from
the planned path (the joint reference, the tool point, the feed direction),
the force model and the arm's inertia; it splits c into the parts of each
force group (tangential, radial, axial coefficients) and of the path's
inertia, so that a scale per group estimated during the cut (the measured
force against the model's: see systems/preview_correction.py) scales each
part without recomputing the preview.  It also gives the wrench the wrist
sensor should read by the model (the cut's wrench in the sensor frame, and
the payload's inertia), for the measured-minus-model feedback.

Units: times s, angles rad, wrenches (N, N*m) at the tool point in the base
frame unless named otherwise.
"""

import math
from dataclasses import dataclass

import numpy as np
from scipy import linalg, optimize

from robstiff_drake.model import joint_dynamics
from robstiff_drake.model.servo import ServoParameters

N_FORCE_GROUPS = 3  # tangential, radial, axial coefficient groups
GROUPS = ("tangential", "radial", "axial", "inertia")  # the parts of the preview
MASS_MATRIX_EVERY = 10  # samples between two mass matrices (it changes slowly along a path)


@dataclass(frozen=True)
class ServoModel:
    """The compensator's model of the robot controller from a joint target
    to the motor, per joint, the rigid axis's response (model/servo.py's
    form, the compensator's own numbers): a dead time, then a position loop
    (gain Kp, 1/s) around a velocity loop of bandwidth omega_v with integral
    action (a PI: corner omega_i; 0: a proportional velocity loop),

        theta'' = omega_v (e_v + omega_i z),   z' = e_v,
        e_v = Kp (theta_ref - theta) + f_v omega_ref - theta';

    the path's reference comes with velocity feed-forward (f_v = 1), a
    correction without.  The drive's gain on the motor's velocity error is
    K_v = omega_v J (J: the axis's rigid inertia, motor and link), so a
    torque tau on the motor (the gear's) moves it by
    -tau s / (K_v Kp (s + omega_i)) at the frequencies the position loop
    holds (see PreviewStream)."""

    dead_time_s: float
    position_gain_per_s: float
    velocity_bandwidth_hz: float
    velocity_integral_hz: float = 0.0

    @property
    def omega_v(self):
        return 2.0 * math.pi * self.velocity_bandwidth_hz

    @property
    def omega_i(self):
        return 2.0 * math.pi * self.velocity_integral_hz

    def _continuous(self, feedforward):
        """(A (3, 3), B (3, 2)): state (theta, theta', z), input (theta_ref, omega_ref)."""
        wv, wi, kp = self.omega_v, self.omega_i, self.position_gain_per_s
        A = np.array([[0.0, 1.0, 0.0], [-wv * kp, -wv, wv * wi], [-kp, -1.0, 0.0]])
        B = np.array([[0.0, 0.0], [wv * kp, wv * feedforward], [kp, feedforward]])
        return A, B

    def _discrete(self, step_s, feedforward):
        A, B = self._continuous(feedforward)
        E = linalg.expm(np.block([[A, B], [np.zeros((2, 5))]]) * step_s)
        return E[:3, :3], E[:3, 3:]

    def step_response(self, t_s):
        """Motor angle per unit step of a target without feed-forward at t = 0."""
        t = np.asarray(t_s, dtype=float)
        tau = np.clip(t - self.dead_time_s, 0.0, None)
        A, B = self._continuous(0.0)
        aug = np.zeros((4, 4))
        aug[:3, :3], aug[:3, 3] = A, B[:, 0]
        out = np.zeros(len(tau))
        on = np.flatnonzero(tau > 0)
        if not on.size:
            return out
        dt = np.diff(tau[on])
        if dt.size and np.allclose(dt, dt[0], rtol=1e-9, atol=1e-12):  # a uniform grid: one exponential's powers
            E, Eh = linalg.expm(aug * tau[on[0]]), linalg.expm(aug * dt[0])
            for i in on:
                out[i] = E[0, 3]
                E = Eh @ E
            return out
        for i in on:
            out[i] = linalg.expm(aug * tau[i])[0, 3]
        return out


def fit_servo(t_s, response, amplitude, *, guess=(0.012, 60.0, 30.0, 7.5)):
    """A ServoModel fitted (least squares) to the motor's measured response
    ``response`` (N,) to a target step of ``amplitude`` at t = 0 (what a
    step test through the controller's external-guidance interface records
    from the encoders).  ``guess``: dead time s, Kp 1/s, bandwidth Hz and
    the velocity loop's integral corner Hz (three values: a proportional
    velocity loop, the corner not fitted)."""
    t = np.asarray(t_s, dtype=float)
    y = np.asarray(response, dtype=float) / amplitude
    n = len(guess)

    def residual(p):
        return ServoModel(*p).step_response(t) - y

    lo, hi, scale = [0.0, 1.0, 1.0, 0.0][:n], [0.5, 2000.0, 2000.0, 200.0][:n], [0.01, 30.0, 30.0, 5.0][:n]
    fit = optimize.least_squares(residual, np.asarray(guess, dtype=float), bounds=(lo, hi), x_scale=scale)
    return ServoModel(*(float(v) for v in fit.x)), float(np.sqrt(np.mean(fit.fun ** 2)))


class PreviewStream:
    """One preview sample per controller cycle (path time u = k T), computed
    from the next joint reference: push the reference at u_k and get the
    correction parts at u_{k-2} (the derivatives need one sample on either
    side).  ``model`` supplies the compensator's knowledge (see
    ``PreviewModel`` in systems/preview_correction.py): ``q(u)`` the joint
    reference, ``force_groups(u)`` the model's wrench per coefficient group
    (3, 6) at the planned tool point, ``jacobian(q)``, ``flange_rotation(q)``
    (row-major 9), ``mass(q)`` and ``payload_com_jacobian(q)``;
    ``compliance`` (6,) rad/(N*m); ``damping_ratios`` the modal damping
    ratio of each of the arm's modes with the drives closed (one number:
    every mode; ``held_ratios``: the motors-held ratios that realise them);
    ``servo`` a ServoModel; ``motor_inertia_kgm2`` (6,) the motors'
    rotor inertias reflected to the joints; ``tool_m`` the tool point in the
    sensor frame."""

    def __init__(self, model, *, period_s, compliance, damping_ratios, servo, motor_inertia_kgm2, tool_m):
        self.m = model
        self.T = float(period_s)
        self.C = np.asarray(compliance, dtype=float)
        self.zeta_closed = np.broadcast_to(np.asarray(damping_ratios, dtype=float), (6,)).copy()
        self.zeta = None  # the motors-held ratios (held_ratios), at the first pose
        self.servo = servo
        self.Jm = np.asarray(motor_inertia_kgm2, dtype=float)
        self.tool = np.asarray(tool_m, dtype=float)
        self.a_i = math.exp(-servo.omega_i * self.T)  # the velocity loop's integral: a high-pass on the load
        self.k = 0
        self._q = []  # the last three references
        self._y = np.zeros((len(GROUPS), 6))  # the gears' twist per group: (K + D s) d = f
        self._d = []  # the last three (u, d (4, 6), f (4, 6), q'', sensor)
        self._h = np.zeros((len(GROUPS), 6))  # the drive's load torque through the integral's high-pass
        self._u_last = np.zeros((len(GROUPS), 6))
        self._M = None
        self._M_next = None  # a mass matrix whose modes the next sample computes
        self.mass_every = MASS_MATRIX_EVERY

    def _pose_terms(self, q):
        """At pose q: M, the gears' twist filter over a period and the
        drives' velocity gains (``_modal_terms``)."""
        return self._modal_terms(self.m.mass(q))

    def held_ratios(self, M):
        """(6,) the motors-held damping ratios whose drives-closed modes have
        the stated ratios, on the compensator's joints at mass matrix M (its
        stiffness and drives, the weight's stiffness left out as in
        ``_modal_terms``)."""
        sv = self.servo
        drives = ServoParameters(position_gain_per_s=sv.position_gain_per_s,
                                 velocity_bandwidth_hz=sv.velocity_bandwidth_hz, velocity_feedforward=1.0,
                                 interpolator_delay_s=sv.dead_time_s, velocity_integral_hz=sv.velocity_integral_hz)
        jm = joint_dynamics.linear_joints(M, np.zeros((6, 6)), np.diag(1.0 / self.C), self.zeta_closed, drives,
                                          self.Jm, stated_on="drives_closed")
        return jm.held_ratios()

    def _modal_terms(self, M):
        """For mass matrix M: (M, the gears' twist filter over a period (Phi =
        e^{-D^-1 K T}, D the modal damping), the drives' velocity gains K_v (6,))."""
        if self.zeta is None:
            self.zeta = self.held_ratios(M)
        K = 1.0 / self.C
        Kd = np.diag(K)
        w2, Phi = linalg.eigh(Kd, M)  # Phi^T M Phi = I, Phi^T K Phi = diag(omega^2)
        # D^-1 K = Phi diag(omega / (2 zeta)) Phi^T M: each mode's twist settles with its own rate
        # (an undamped mode: at once)
        w = np.sqrt(np.maximum(w2, 0.0))
        with np.errstate(divide="ignore"):
            rate = np.where(self.zeta > 0, w / (2.0 * np.maximum(self.zeta, 1e-300)), np.inf)
        Ed = (Phi * np.exp(-rate * self.T)) @ Phi.T @ M
        Kv = self.servo.omega_v * (self.Jm + np.diag(M))
        return M, Ed, Kv

    def _refresh(self, j, q):
        """The pose terms along the path, their cost spread over two cycles
        so that no cycle carries both: the mass matrix at sample j (every
        ``mass_every``-th), its modes and filter at the next one (the pose
        terms then lag the path by one period, 4 ms: the inertia changes
        over tens of ms)."""
        if self._M is None:
            self._M, self._Ed, self._Kv = self._pose_terms(q)
        elif j % self.mass_every == 0:
            self._M_next = self.m.mass(q)
        elif self._M_next is not None:
            self._M, self._Ed, self._Kv = self._modal_terms(self._M_next)
            self._M_next = None

    def push(self, u_s):
        """Push the reference at path time ``u_s`` (= k T); returns None for
        the first pushes, then (u, c (4, 6), sensor (4, 6)): the
        correction's parts at u = u_s - 2 T and the model's sensor wrench
        (sensor frame; the payload's inertia in the last row) at u."""
        q = np.asarray(self.m.q(u_s), dtype=float)
        self._q.append(q)
        if len(self._q) == 1:
            self._q.insert(0, q)  # at rest before the start
        if len(self._q) > 3:
            del self._q[0]
        if len(self._q) < 3:
            return None
        q0, q1, q2 = self._q
        j = self.k  # the sample whose acceleration is now known: u_j = u_s - T
        u_j = u_s - self.T
        self.k += 1
        qdd = (q2 - 2.0 * q1 + q0) / (self.T * self.T)
        self._refresh(j, q1)
        J = self.m.jacobian(q1)
        W = self.m.force_groups(u_j)  # (3, 6)
        f = np.empty((len(GROUPS), 6))  # the gears' torque that holds the link on the path, per group
        f[:N_FORCE_GROUPS] = -(W @ J)  # -J^T W per group
        f[-1] = self._M @ qdd
        x = f * self.C  # the static twist
        self._y = self._y @ self._Ed.T + x @ (np.eye(6) - self._Ed).T
        sensor = self._sensor(q1, qdd, W)
        self._d.append((u_j, self._y.copy(), f, qdd, sensor))
        if len(self._d) == 1:  # at rest before the start
            z = np.zeros_like(f)
            self._d.insert(0, (u_j - self.T, z, z, np.zeros(6), np.zeros_like(sensor)))
        if len(self._d) > 3:
            del self._d[0]
        if len(self._d) < 3:
            return None
        (_, dm, _, _, _), (u, d0, f0, qdd0, s0), (_, dp, _, _, _) = self._d
        T, kp = self.T, self.servo.position_gain_per_s
        ddd = (dp - 2.0 * d0 + dm) / (T * T)
        load = f0 + self.Jm * ddd  # the torque the drive must supply beyond the reference's (per group)
        load[-1] += self.Jm * qdd0  # the motor's own inertia on the path
        self._h = self.a_i * self._h + 0.5 * (1.0 + self.a_i) * (load - self._u_last)  # (Tustin-like: a ramp's level right)
        self._u_last = load
        c = d0 + (dp - dm) / (2.0 * T * kp) + self._h / (self._Kv * kp)
        return u, c, s0

    def _sensor(self, q, qdd, W):
        """The wrench the model says the sensor reads beyond the payload's
        weight (sensor frame, 4 x 6): each force group, and the payload's
        inertia (-m a of its centre of mass, and its moment)."""
        R = np.asarray(self.m.flange_rotation(q)).reshape(3, 3)
        out = np.empty((len(GROUPS), 6))
        mass, com = self.m.payload
        F = np.empty((len(GROUPS), 3))
        F[:N_FORCE_GROUPS] = W[:, :3] @ R  # R^T f per group
        F[-1] = (-mass * (self.m.payload_com_jacobian(q) @ qdd)) @ R
        out[:, :3] = F
        out[:N_FORCE_GROUPS, 3:] = W[:, 3:] @ R + _cross_rows(self.tool, F[:N_FORCE_GROUPS])
        out[-1, 3:] = _cross_rows(com, F[-1:])[0]
        return out


def _cross_rows(r, F):
    """r x f for each row f of F (n, 3) (numpy's cross is slow on small arrays)."""
    out = np.empty_like(F)
    out[:, 0] = r[1] * F[:, 2] - r[2] * F[:, 1]
    out[:, 1] = r[2] * F[:, 0] - r[0] * F[:, 2]
    out[:, 2] = r[0] * F[:, 1] - r[1] * F[:, 0]
    return out


def preview_table(model, *, t_end_s, period_s, compliance, damping_ratios, servo, motor_inertia_kgm2, tool_m):
    """The preview over a whole path, on the grid u = 0, T, ..., >= t_end:
    (u (N,), corrections (N, 4, 6), sensor wrenches (N, 4, 6)), from the
    same per-cycle computation as PreviewStream."""
    s = PreviewStream(model, period_s=period_s, compliance=compliance, damping_ratios=damping_ratios, servo=servo,
                      motor_inertia_kgm2=motor_inertia_kgm2, tool_m=tool_m)
    n = int(math.ceil(t_end_s / period_s)) + 1
    us, cs, ss = [], [], []
    for k in range(n + 2):
        out = s.push(k * period_s)
        if out is not None:
            us.append(out[0])
            cs.append(out[1])
            ss.append(out[2])
    return np.array(us), np.array(cs), np.array(ss)
