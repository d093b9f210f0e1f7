"""The arm's joints as a linear system about a pose: each joint two masses,
the link (the arm's mass matrix M) and its motor (reflected rotor inertia
J_m), coupled by the gear (stiffness K, structural damping D), the motor
driven by its drive (model/servo.py), the weight's own stiffness G with
the links.  Plain numpy/scipy; the caller supplies M and G (Drake's
controller model of the arm: diagrams/station.py).

    M q''    = K (theta - q) + D (theta' - q') + G q + tau_ext
    J_m theta'' = tau_drive - K (theta - q) - D (theta' - q')

Modes.  "Motors held" (theta fixed): the links on the gears, M against
K - G.  "Motors free": links and motors against the gears only (six
rigid-body motions at zero frequency, the arm swinging on its weight's
stiffness, and the gear modes).  "Servo closed": the whole linear loop
with the drives' position and velocity loops, complex modes with their
frequency and damping ratio.

Damping per mode.  D = M Phi diag(2 zeta_i omega_i) Phi^T M, with Phi the
mass-normalised modes of the links on the gears (motors held): each of
those modes gets exactly the damping ratio zeta_i (modal damping, the
classical damping whose ratios are set mode by mode, where Rayleigh
damping alpha M + beta K sets two: e.g. Craig and Kurdila, Fundamentals of
Structural Dynamics, 2nd ed., Wiley 2006).  D acts on the
gears' twist rate theta' - q', where the arm's damping is (gears, bearings,
structure): it does not damp the arm's motion as a whole.

The step.  The station steps the links in Drake's discrete
MultibodyPlant (symplectic Euler: v+ = v + h M^-1 (forces at the step's
start), q+ = q + h v+) and the drives exactly over the step with the gear
torque held; the gear's spring and damping are explicit.  That scheme
adds no numerical damping to any mode (its map is stable for
omega h < 2 in each mode and conserves an undamped mode's energy; a mode's
frequency comes out 2 / h asin(omega h / 2)): its stability is the step's,
not the damping's.  ``step_map`` is that scheme's exact linear map, and
``largest_stable_step_s`` the step that keeps every mode stable.
"""

from dataclasses import dataclass

import numpy as np
from scipy import linalg

from robstiff_drake.model import servo as servo_model

# ASSUMPTION: 5 % of critical damping on every mode of the links on their gears.  Experimental modal
# analyses of industrial arms report 2-10 % on their structural modes (the range a physics review of this project
# quotes; e.g. the tool-point modes of a surgical milling arm, 2.0-3.6 % at 110-122 Hz, Sci. Rep. 14 (2024),
# doi:10.1038/s41598-024-61362-2, Table 3); 5 % is the middle.  A scenario sets its own (plant.modal_damping_ratio,
# plant.damping_ratios).
DEFAULT_MODAL_DAMPING_RATIO = 0.05
STABLE_MARGIN = 1.0 + 1e-9  # spectral radius of a stable step (an undamped mode sits at 1)


def _sym(G):
    return 0.5 * (np.asarray(G, dtype=float) + np.asarray(G, dtype=float).T)


def stiffness_matrix(k_Nm_per_rad, coupling_c23_rad_per_Nm=0.0):
    """(6, 6) the gears' stiffness (N*m/rad): the inverse of their
    compliance matrix (diagonal 1/k, the 2-3 coupling off the diagonal)."""
    C = np.diag(1.0 / np.asarray(k_Nm_per_rad, dtype=float))
    C[1, 2] = C[2, 1] = float(coupling_c23_rad_per_Nm)
    return np.linalg.inv(C)


def held_modes(M, K, G=None):
    """(omega (6,) rad/s ascending, Phi (6, 6) mass-normalised columns) of
    the links on the gears, motors held."""
    Ke = np.asarray(K, dtype=float) - (0.0 if G is None else _sym(G))
    w2, Phi = linalg.eigh(_sym(Ke), _sym(M))
    return np.sqrt(np.maximum(w2, 0.0)), Phi


def modal_damping_matrix(M, K, G, ratios):
    """(6, 6) D that gives the motors-held mode i the damping ratio
    ``ratios[i]`` (a number: every mode), N*m*s/rad."""
    w, Phi = held_modes(M, K, G)
    z = np.broadcast_to(np.asarray(ratios, dtype=float), w.shape)
    MPhi = np.asarray(M, dtype=float) @ Phi
    return MPhi @ np.diag(2.0 * z * w) @ MPhi.T


def free_modes_hz(M, K, G, motor_inertia_kgm2):
    """The six undamped natural frequencies (Hz) of the gears with the
    motors free (no drive), ascending: links and motors on the gears and the
    weight (the six other motions, the arm turning as a whole on its
    weight's stiffness, are left out)."""
    Ke = np.asarray(K, dtype=float)
    KK = np.block([[Ke - (0.0 if G is None else _sym(G)), -Ke], [-Ke, Ke]])
    MM = linalg.block_diag(M, np.diag(motor_inertia_kgm2))
    w2 = linalg.eigh(_sym(KK), _sym(MM), eigvals_only=True)
    return np.sort(np.sqrt(np.abs(w2)) / (2 * np.pi))[-6:]


def motor_inertia(robot, M):
    """The motors' rotor inertias reflected to the joints (6,, kg*m^2): the
    robot file's ``motor_inertia_kgm2``; a file without them: ASSUMPTION,
    each equal to its link's inertia on the joint in M (kg*m^2; a
    load-to-motor inertia ratio of 1, inside the 1-5 that servo axes are
    sized for)."""
    if robot.motor_inertia_kgm2 is not None:
        return np.asarray(robot.motor_inertia_kgm2, dtype=float)
    return np.diag(M).copy()


def linear_joints(M, G, stiffness_matrix, damping_ratios, servo, motor_inertia_kgm2):
    """The JointModel of mass matrix M (6, 6, kg*m^2), the weight's
    stiffness G (N*m/rad), the gears (N*m/rad), their modal damping
    (``damping_ratios``, per mode or one for all), the motors and drives
    (velocity loops tuned for the rigid axes)."""
    M = np.asarray(M, dtype=float)
    D = modal_damping_matrix(M, stiffness_matrix, G, damping_ratios)
    Jm = np.asarray(motor_inertia_kgm2, dtype=float)
    return JointModel(M=M, K=stiffness_matrix, G=G, D=D, motor_inertia_kgm2=Jm, servo=servo,
                      velocity_gain=servo_model.velocity_gain_Nms(servo, Jm + np.diag(M)))


@dataclass
class JointModel:
    """The linear joints at one pose (see the module docstring)."""

    M: np.ndarray  # (6, 6) kg m^2
    K: np.ndarray  # (6, 6) N m/rad, the gears
    G: np.ndarray  # (6, 6) N m/rad, d(gravity's generalized force)/dq
    D: np.ndarray  # (6, 6) N m s/rad, the gears' damping
    motor_inertia_kgm2: np.ndarray  # (6,)
    servo: object  # model.servo.ServoParameters
    velocity_gain: np.ndarray  # (6,) N m s/rad

    def continuous(self):
        """(A (30, 30), B (30, 24)): state (q, q', theta, theta', z), input
        (theta_ref, omega_ref, tau_ff (6 each, into the drives), tau_ext (6,
        generalized forces on the links, N*m))."""
        Minv = np.linalg.inv(self.M)
        K, D, G = self.K, self.D, _sym(self.G)
        Ad, Bd = servo_model.drive_continuous(self.servo, self.motor_inertia_kgm2, self.velocity_gain)
        A = np.zeros((30, 30))
        A[0:6, 6:12] = np.eye(6)
        A[6:12, :24] = Minv @ np.hstack([-(K - G), -D, K, D])
        A[12:30, 12:30] = Ad
        A[12:30] += Bd[:, 18:24] @ self.gear_rows()  # the gear's torque on the motor
        B = np.zeros((30, 24))
        B[12:30, :18] = Bd[:, :18]
        B[6:12, 18:24] = Minv
        return A, B

    def gear_rows(self):
        """(6, 30): the gear's torque on the link, K (theta - q) + D (theta' - q')."""
        return np.hstack([-self.K, -self.D, self.K, self.D, np.zeros((6, 6))])

    def closed_loop_modes(self):
        """(frequency Hz, damping ratio) of each oscillating mode of the loop
        with the servo closed, ascending in frequency."""
        lam = np.linalg.eigvals(self.continuous()[0])
        lam = lam[lam.imag > 1e-9]
        lam = lam[np.argsort(np.abs(lam))]
        return np.abs(lam) / (2 * np.pi), -lam.real / np.abs(lam)

    def step_map(self, step_s):
        """(30, 30): the station's discrete scheme over one step, linearised
        (see the module docstring)."""
        h = float(step_s)
        Minv = np.linalg.inv(self.M)
        A, B = servo_model.drive_continuous(self.servo, self.motor_inertia_kgm2, self.velocity_gain)
        E = linalg.expm(np.block([[A, B], [np.zeros((24, 42))]]) * h)
        Adr, Btau = E[:18, :18], E[:18, 18 + 18:]
        T = self.gear_rows()
        P = np.zeros((30, 30))
        v_new = np.zeros((6, 30))
        v_new[:, 6:12] = np.eye(6)
        v_new += h * Minv @ T
        v_new[:, 0:6] += h * Minv @ _sym(self.G)
        P[6:12] = v_new
        P[0:6] = h * v_new
        P[0:6, 0:6] += np.eye(6)
        P[12:30, 12:30] = Adr
        P[12:30] += Btau @ T
        return P

    def step_modes(self, step_s):
        """(frequency Hz, damping ratio) of each oscillating mode of the
        discrete scheme at ``step_s`` (the step map's eigenvalues z read as
        s = ln(z) / h), ascending in frequency: what the step makes of
        ``closed_loop_modes``."""
        z = np.linalg.eigvals(self.step_map(step_s)).astype(complex)
        z = z[(z.imag > 1e-12) & (np.abs(z) > 0)]
        lam = np.log(z) / float(step_s)
        lam = lam[np.argsort(np.abs(lam))]
        return np.abs(lam) / (2 * np.pi), -lam.real / np.abs(lam)

    def spectral_radius(self, step_s):
        return float(np.max(np.abs(np.linalg.eigvals(self.step_map(step_s)))))

    def is_stable_step(self, step_s):
        return self.spectral_radius(step_s) <= STABLE_MARGIN

    def largest_stable_step_s(self, upper_s, resolution_s=1e-5):
        """The largest step up to ``upper_s`` (s) whose scheme is stable, by
        bisection (the spectral radius grows with the step once a mode
        passes omega h = 2), rounded down to ``resolution_s``."""
        lo, hi = 0.0, float(upper_s)
        if self.is_stable_step(hi):
            return hi
        while hi - lo > resolution_s:
            mid = 0.5 * (lo + hi)
            lo, hi = (mid, hi) if self.is_stable_step(mid) else (lo, mid)
        return np.floor(lo / resolution_s) * resolution_s
