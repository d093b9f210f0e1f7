"""A linear model of the compensation loop that predicts what the sweep
measures.  Plain numpy/scipy: the caller supplies the arm's mass matrix.

The loop, linearised at one pose and stepped at the sensor rate h:

  arm       M dq'' + D dq' + (K - G) dq = J^T W + K theta + D theta'
            (ZOH over h; G = d tau_gravity / dq, the weight's own
            stiffness, which the gears carry)
  motor     with ``joints`` (model/joint_dynamics.JointModel, the plant's):
            its rotor inertia, the gear's torque pushing it back, the drive's
            position loop and PI velocity loop (model/servo.py), D the modal
            damping; without: kinematic, theta'' = omega_v (Kp (theta_ref -
            theta) - theta') (the rigid axis; D = beta K).  The correction
            has no velocity feed-forward
  interpolator  theta_ref = c delayed by the interpolator's dead time
            (a shift register at h)
  process   W = W_nom(t) + [K_p J_v dq; 0]           (the cut's stiffness: the
                                                     force's change with the
                                                     tool's position, N/m)
  sensor    S <- W + L dq''   (plain)   or   S <- W + L dq'' - s W_nom
            (predictive: the measured-minus-model bracket, s the model's
            scale).  L dq'' is the payload's inertia as the sensor feels it
            (the wrench it needs to be accelerated with the flange): the
            chain cannot tell it from the cutting load, so it feeds back too;
            at the arm's higher modes it is larger than the cut's own
            stiffness.  dq'' from the arm's equation at the sample.
  guard     G <- S
  filter    X <- A_f X + B_f G,  y = C_f X + D_f G  (the same discrete filter)
  every T = N h, all at once (Drake's same-instant semantics):
  ZOH       Z <- y
  predict   P = C_m J^T (Z + W_ff),  W_ff = s W_nom(t + lead) in predictive mode
  delay     n-sample shift register of P
  correct   c <- -(the register's oldest, or P when n = 0)
  (with ``servo`` None, the motor follows c at once: theta = c)

Over one controller period the homogeneous loop is the linear map
Phi = (fast step)^(N-1) (tick step); its eigenvalues are the closed-loop
poles (stable when all are inside the unit circle).  The same steps with
W_nom(t) from the planned path give the tool's deviation over a pass, from
which the surface error is predicted.  What it leaves out: saturation and
rate limit, the arm's nonlinearity (one pose), the tool's tilt, noise.

First-order lag error at an engagement change:
  e ~ C (dF/dx) v (filter group delay + (n + 1.5) T + 2 h + servo lag)
"""

from dataclasses import dataclass

import numpy as np
from scipy import linalg, signal


@dataclass
class LoopModel:
    M: np.ndarray  # (6, 6) joint-space mass matrix at the pose, kg m^2
    K: np.ndarray  # (6,) plant joint stiffness, N m/rad
    beta_s: float  # stiffness-proportional damping, D = beta K
    J: np.ndarray  # (6, 6) Jacobian at the tool point (linear rows first)
    C_model: np.ndarray  # (6,) the compensator's joint compliance, rad/(N m)
    filter_ba: tuple  # discrete filter at the sensor rate
    rate_hz: float
    period_s: float
    delay_steps: int
    mode: str = "plain"
    model_scale: float = 1.0
    # (6, 6) the payload's inertial wrench at the tool point (base frame) per
    # joint acceleration: -[m J_com; m (r_com - r_tool) x J_com + I J_w].
    # None: a sensor that feels no inertia.
    sensor_inertia: np.ndarray = None
    # (6, 6) d tau_gravity / dq at the pose (N*m/rad); None: leave it out.
    gravity_stiffness: np.ndarray = None
    # model.servo.ServoParameters of the motor side; None: the motor follows
    # the command at once (the plant before the servo was modelled).
    servo: object = None
    # model.joint_dynamics.JointModel: the motors with inertia, drives and modal damping of the plant
    # (supersedes M, K, beta_s, gravity_stiffness and servo's kinematic motor); None: the kinematic motor
    joints: object = None

    def __post_init__(self):
        self.h = 1.0 / self.rate_hz
        self.N = max(1, int(round(self.period_s * self.rate_hz)))
        Kd = np.diag(self.K) if np.ndim(self.K) == 1 else np.asarray(self.K, dtype=float)
        Ke = Kd - (self.gravity_stiffness if self.gravity_stiffness is not None else 0.0)
        Minv = np.linalg.inv(self.M)
        Z = np.zeros((6, 6))
        if self.joints is not None:  # links (q, q'), motors (theta, theta'), drives' integrals z
            jm = self.joints
            self.servo = jm.servo
            Ac, B = jm.continuous()
            Minv = np.linalg.inv(jm.M)
            I6 = np.eye(6)
            Kv = np.diag(jm.velocity_gain / jm.motor_inertia_kgm2)
            kp = jm.servo.position_gain_per_s
            Bw = np.vstack([np.zeros((6, 6)), Minv @ self.J.T, np.zeros((18, 6))])
            # the path's motion terms (see below): the reference beyond the path, the velocity error the
            # feed-forward leaves, the path's acceleration
            Br = np.vstack([np.zeros((6, 18)), np.hstack([Z, Z, -I6]), np.zeros((6, 18)),
                            np.hstack([kp * Kv, Kv, -I6]), np.hstack([kp * I6, I6, Z])])
            Bc = np.hstack([Bw, B[:, 0:6], Br])
            self.n_delay = int(round(jm.servo.interpolator_delay_s / self.h))
        elif self.servo is None:  # arm (q, q'); inputs W (6), c (6)
            Ac = np.block([[Z, np.eye(6)], [-Minv @ Ke, -self.beta_s * Minv @ Kd]])
            Bc = np.vstack([np.zeros((6, 12)), np.hstack([Minv @ self.J.T, Minv @ Kd])])
            self.n_delay = 0
        else:  # arm (q, q') and motor (theta, theta'); inputs W (6), theta_ref (6)
            wv, kp = self.servo.omega_v, self.servo.position_gain_per_s
            I6 = np.eye(6)
            Ac = np.block([[Z, I6, Z, Z],
                           [-Minv @ Ke, -self.beta_s * Minv @ Kd, Minv @ Kd, self.beta_s * Minv @ Kd],
                           [Z, Z, Z, I6],
                           [Z, Z, -wv * kp * I6, -wv * I6]])
            Bc = np.vstack([np.zeros((6, 12)), np.hstack([Minv @ self.J.T, Z]), np.zeros((6, 12)),
                            np.hstack([Z, wv * kp * I6])])
            # the path's own motion, in coordinates relative to the path where
            # the arm is meant to be, q_ref(t): inputs (the servo's position
            # reference beyond it, (f_v - 1) q_ref'(t), q_ref''(t))
            Br = np.vstack([np.zeros((6, 18)), np.hstack([Z, Z, -I6]), np.zeros((6, 18)),
                            np.hstack([wv * kp * I6, wv * I6, -I6])])
            Bc = np.hstack([Bc, Br])
            self.n_delay = int(round(self.servo.interpolator_delay_s / self.h))
        nx, nu = Ac.shape[0], Bc.shape[1]
        E = linalg.expm(np.block([[Ac, Bc], [np.zeros((nu, nx + nu))]]) * self.h)
        self.Ad, self.Bw, self.Bc = E[:nx, :nx], E[:nx, nx:nx + 6], E[:nx, nx + 6:nx + 12]
        self.Br = E[:nx, nx + 12:] if nu > 12 else None
        A, B, C, D = signal.tf2ss(*self.filter_ba)
        self.nf = A.shape[0]
        self.Af, self.Bf, self.Cf, self.Df = A, B[:, 0], C[0] if self.nf else np.zeros(0), float(np.squeeze(D))
        self.PJ = self.C_model[:, None] * self.J.T  # dq = C_m J^T W
        # joint acceleration from the arm's state and inputs: dq'' = A_q x + B_w W + B_c c
        self.acc_x, self.acc_w, self.acc_c = Ac[6:12], Bc[6:12, :6], Bc[6:12, 6:12]
        self.nx = nx
        n = self.delay_steps
        # state layout
        sizes = {"arm": nx, "S": 6, "G": 6, "X": 6 * self.nf, "Z": 6, "buf": 6 * n, "c": 6, "ff": 6,
                 "interp": 6 * self.n_delay}
        self.idx, k = {}, 0
        for name, size in sizes.items():
            self.idx[name] = slice(k, k + size)
            k += size
        self.size = k

    # -- one step of the hybrid loop (affine in z) ------------------------------------------------------------------
    def step(self, z, W_nom, Kp, tick, ff_next, path=None):
        """z at t_j -> z at t_j + h.  W_nom (6) the nominal wrench at t_j, Kp
        (3x3) the process stiffness, ``tick`` whether t_j is a controller
        tick, ``ff_next`` the feed-forward wrench the tick stores (predictive),
        ``path`` (18, with the servo): the path's motion terms at t_j (see
        ``path_terms``): the arm's own dynamics along the path (motion error)."""
        I = self.idx
        x_arm, S, G = z[I["arm"]], z[I["S"]], z[I["G"]]
        X = z[I["X"]].reshape(self.nf, 6) if self.nf else np.zeros((0, 6))
        Z, buf, c, ff = z[I["Z"]], z[I["buf"]].reshape(-1, 6), z[I["c"]], z[I["ff"]]
        interp = z[I["interp"]].reshape(-1, 6)
        p = self.J[:3] @ x_arm[:6]  # tool displacement (m)
        W = W_nom + np.concatenate([Kp @ p, np.zeros(3)])
        out = np.empty_like(z)
        u = interp[-1] if len(interp) else c  # what reaches the servo (or the spring) now
        out[I["arm"]] = self.Ad @ x_arm + self.Bw @ W + self.Bc @ u
        if path is not None and self.Br is not None:
            out[I["arm"]] += self.Br @ path
        if len(interp):
            out[I["interp"]] = np.concatenate([c, interp[:-1].ravel()])
        S_new = W - (self.model_scale * W_nom if self.mode == "predictive" else 0.0)
        if self.sensor_inertia is not None:
            acc_u = self.acc_c @ u if self.servo is None else 0.0  # the servo's input reaches q'' through theta
            # the arm's whole acceleration q'' = e'' + q_ref'': in the path's
            # coordinates the path's q_ref'' cancels, what is left is this
            S_new = S_new + self.sensor_inertia @ (self.acc_x @ x_arm + self.acc_w @ W + acc_u)
        out[I["S"]] = S_new
        out[I["G"]] = S
        if self.nf:
            out[I["X"]] = (self.Af @ X + np.outer(self.Bf, G)).ravel()
        if tick:
            y = (self.Cf @ X if self.nf else 0.0) + self.Df * G
            P = self.PJ @ (Z + ff)
            out[I["Z"]] = y
            if len(buf):
                out[I["c"]] = -buf[-1]
                out[I["buf"]] = np.concatenate([P, buf[:-1].ravel()])
            else:
                out[I["c"]] = -P
            out[I["ff"]] = ff_next
        else:
            out[I["Z"]], out[I["buf"]], out[I["c"]], out[I["ff"]] = Z, buf.ravel(), c, ff
        return out

    def step_matrix(self, Kp, tick):
        """(size, size): the homogeneous ``step`` (no nominal wrench, no
        feed-forward, no path) as a matrix, at a tick or between ticks."""
        S = np.empty((self.size, self.size))
        zero = np.zeros(6)
        for k in range(self.size):
            z = np.zeros(self.size)
            z[k] = 1.0
            S[:, k] = self.step(z, zero, Kp, tick, zero)
        return S

    def period_map(self, Kp):
        """The homogeneous map over one controller period (tick first):
        (the step between ticks)^(N-1) (the tick's step)."""
        return self.compose_period(self.step_matrix(Kp, True), self.step_matrix(Kp, False) if self.N > 1 else None)

    def compose_period(self, S_tick, S_fast):
        """The period map from the two step matrices (``step_matrix``)."""
        if self.N == 1:
            return S_tick
        return np.linalg.matrix_power(S_fast, self.N - 1) @ S_tick

    def poles(self, Kp):
        """Closed-loop poles over one period (z-plane) and the spectral radius."""
        lam = np.linalg.eigvals(self.period_map(Kp))
        return lam, float(np.max(np.abs(lam)))

    def simulate(self, t, W_nom, Kp, ff, path=None):
        """Tool deviation p (N, 3) in m over times t (every h from 0), given the
        nominal wrench (N, 6), process stiffness (N, 3, 3), the feed-forward
        wrench for each tick (N, 6: used at ticks only) and, with the servo,
        the path's motion terms (N, 18; see ``step``; None: the arm holds
        still but for the cut)."""
        z = np.zeros(self.size)
        out = np.empty((len(t), 3))
        for j in range(len(t)):
            out[j] = self.J[:3] @ z[self.idx["arm"]][:6]
            z = self.step(z, W_nom[j], Kp[j], j % self.N == 0, ff[j], None if path is None else path[j])
        return out


def path_terms(t, t_ref, q_ref, velocity_feedforward):
    """The path's motion terms of LoopModel.step on times t (N, 18), in
    coordinates relative to the path at t: (0 (the servo's reference is the
    path itself), (f_v - 1) q_ref'(t), q_ref''(t)); from the joint
    references q_ref (M, 6) at times t_ref."""
    dt = float(np.median(np.diff(t_ref)))
    v_ref = np.gradient(q_ref, dt, axis=0)
    a_ref = np.gradient(v_ref, dt, axis=0)

    def at(values):
        return np.column_stack([np.interp(t, t_ref, values[:, j]) for j in range(values.shape[1])])

    return np.hstack([np.zeros((len(t), q_ref.shape[1])), (velocity_feedforward - 1.0) * at(v_ref), at(a_ref)])


def first_order_lag_s(filter_ba, rate_hz, period_s, delay_steps, servo_lag_s=0.0):
    """Filter group delay + (n + 1.5) T + two sensor samples + the servo's
    low-frequency lag (interpolator and position loop) (s)."""
    w, gd = signal.group_delay(filter_ba, w=[0.5], fs=rate_hz)
    return float(gd[0]) / rate_hz + (delay_steps + 1.5) * period_s + 2.0 / rate_hz + servo_lag_s


def process_stiffness(force_fn, p, delta_m=1e-4):
    """K_p = dF/dp (3x3, N/m) of a force model at the tool point p, by central differences."""
    Kp = np.empty((3, 3))
    for k in range(3):
        e = np.zeros(3)
        e[k] = delta_m
        Kp[:, k] = (force_fn(p + e)[:3] - force_fn(p - e)[:3]) / (2 * delta_m)
    return Kp
