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

Stated on the drives-closed modes.  A ratio a scenario states is what a
modal test with the drives on measures (a hammer on the tool, the arm
servoing): the ratio of each arm mode of the loop with the drives closed
(``arm_modes``: the closed loop's mode whose link motion is the
motors-held mode's).  ``linear_joints`` solves for the motors-held ratios
that give it (``realise_drives_closed``): the drives' velocity loops add
damping to the arm's modes, their integral takes some away.  Where the
drives alone damp a mode beyond the stated ratio (the gears' modes near
the velocity loop's bandwidth) the gears keep MIN_HELD_SHARE of it and
the mode comes out more damped than stated (``arm_modes`` says by how much).

The step.  The station steps the links in Drake's discrete
MultibodyPlant (symplectic Euler: v+ = v + h M^-1 (forces at the step's
start), q+ = q + h v+) and the drives exactly over the step with the gear
torque held; the gear's spring and damping are explicit.  On the links'
side that adds no numerical damping (symplectic Euler alone is stable for
omega h < 2 in an undamped mode and conserves its energy; a mode's
frequency comes out 2 / h asin(omega h / 2)), but the motors' side is
stepped with the gear's torque held over the step, which feeds energy
into a mode that moves a motor, energy its damping (the gears' and the
drive's velocity loop) must take out: a mode with much motion in a light
motor holds only to a smaller omega h, set by its damping and its
motor's share (kr240_r2900.yaml without its motor inertias: the 191 Hz
wrist mode, 49 % in joint 6's motor, 9.4 % damped, to omega h = 0.74;
the IRB 6400 file, 3 % in the motor, to 1.93).  ``step_map`` is that scheme's
exact linear map, ``is_stable_step`` its spectral radius against 1, and
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
# ASSUMPTION: where the drives alone damp a mode beyond its stated ratio, the gears keep this share of the
# stated ratio on it (their own damping, bearings and structure, does not vanish because a drive damps the mode).
MIN_HELD_SHARE = 0.25
FIT_RATIO_FLOOR = 1e-3  # fit_path_damping weighs a mode's equation by its ratio, taken at least this
DAMPING_TOLERANCE = 1e-4  # the drives-closed ratios are realised to this (absolute, 0.01 % of critical)
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


# ASSUMPTION: a robot file without motor_inertia_kgm2 gets each motor's rotor inertia reflected to its joint
# (n^2 J_rotor) equal to its link's inertia on the joint in M at the pose (a load-to-rotor inertia ratio of
# ASSUMED_LOAD_TO_ROTOR_RATIO).  Source: the usual servo-sizing rule that the load's inertia reflected to the motor
# be at most about five times the rotor's (docs/assumptions.md, "the motors"); 1 is that rule's stiffest end.  It
# is light on the wrist: the library's files (their own assumption, irb6400.yaml's reasoning) put 8-12 kg*m^2 on
# joint 6, 25-30 times its link's inertia, and a light rotor raises the wrist's gear mode: kr240_r2900.yaml
# without them has joint 6 at 0.34 kg*m^2 and a 191 Hz wrist mode the plant's step holds only up to 0.62 ms (with
# its 12 kg*m^2: 139 Hz, 2.2 ms; tests/test_plant_step_advice.py; diagrams/plant_step.unstable_step_message
# names the mode and this key when it refuses a step).
ASSUMED_LOAD_TO_ROTOR_RATIO = 1.0


def motor_inertia(robot, M):
    """The motors' rotor inertias reflected to the joints (6,, kg*m^2): the
    robot file's ``motor_inertia_kgm2``; a file without them: ASSUMPTION,
    each its link's inertia on the joint in M (kg*m^2) over
    ASSUMED_LOAD_TO_ROTOR_RATIO (see there)."""
    if robot.motor_inertia_kgm2 is not None:
        return np.asarray(robot.motor_inertia_kgm2, dtype=float)
    return np.diag(M).copy() / ASSUMED_LOAD_TO_ROTOR_RATIO


def linear_joints(M, G, stiffness_matrix, damping_ratios, servo, motor_inertia_kgm2, stated_on="drives_closed"):
    """The JointModel of mass matrix M (6, 6, kg*m^2), the weight's
    stiffness G (N*m/rad), the gears (N*m/rad), their modal damping
    (``damping_ratios``, per mode or one for all: on the drives-closed arm
    modes, ``stated_on`` "drives_closed", see the module docstring; or on
    the motors-held modes, "motors_held"), the motors and drives (velocity
    loops tuned for the rigid axes; the integral corner chosen from the
    first motors-held mode when the servo's rule says so:
    model/servo.integral_corner_hz)."""
    M = np.asarray(M, dtype=float)
    w_held = held_modes(M, stiffness_matrix, G)[0]
    servo = servo_model.with_integral_corner(servo, w_held[0] / (2 * np.pi))
    D = modal_damping_matrix(M, stiffness_matrix, G, damping_ratios)
    Jm = np.asarray(motor_inertia_kgm2, dtype=float)
    jm = JointModel(M=M, K=stiffness_matrix, G=G, D=D, motor_inertia_kgm2=Jm, servo=servo,
                    velocity_gain=servo_model.velocity_gain_Nms(servo, Jm + np.diag(M)))
    if stated_on == "motors_held":
        return jm
    if stated_on != "drives_closed":
        raise ValueError(f"stated_on {stated_on!r}: one of drives_closed, motors_held")
    return realise_drives_closed(jm, damping_ratios)


def realise_drives_closed(jm, ratios, iterations=40):
    """``jm`` with the gears' damping D whose drives-closed arm modes
    (``arm_modes``) have the damping ratios ``ratios`` (per mode or one for
    all): the motors-held ratios found by a fixed-point iteration (each
    corrected by what its drives-closed mode misses, which moves it by
    about as much), none below MIN_HELD_SHARE of its target."""
    target = np.broadcast_to(np.asarray(ratios, dtype=float), (6,)).copy()
    floor = MIN_HELD_SHARE * target
    held = target.copy()
    out = jm
    for _ in range(iterations):
        realised = out.arm_modes()[1]
        miss = target - realised
        active = (held > floor + 1e-12) | (miss > 0)  # (a mode at its floor, damped beyond: done)
        if not np.any(np.abs(miss[active]) > DAMPING_TOLERANCE):
            break
        held = np.maximum(held + miss, floor)
        out = JointModel(**{**out.__dict__, "D": modal_damping_matrix(out.M, out.K, out.G, held)})
    return out


def fit_path_damping(jm, poses, ratios):
    """``jm`` (its drives tuned where they were) with one gears' damping D
    for every pose of a path: ``poses`` a list of (M, G) at the poses the
    path visits.  At each pose the motors-held ratios that give the stated
    drives-closed ones (``realise_drives_closed``) set what D must give
    each motors-held mode there (phi_i^T D phi_i = 2 zeta_i omega_i, and
    phi_i^T D phi_j = 0: no coupling between modes): a linear least squares
    in D's 21 entries, each equation relative to its own size, D then kept
    positive semi-definite.  The gears' damping is the joints'
    (gears, bearings), not the pose's: one D, the pose's realised ratios
    what they come out (``JointModel.arm_modes`` at each pose measures
    them)."""
    rows, rhs = [], []
    iu = np.triu_indices(6)
    for M, G in poses:
        at = realise_drives_closed(jm.at_pose(M, G), ratios)
        w, Phi = held_modes(at.M, at.K, at.G)
        need = 2.0 * at.held_ratios() * w
        scale = 2.0 * np.maximum(at.held_ratios(), FIT_RATIO_FLOOR) * w  # (each equation relative to its size)
        for i in range(6):
            for j in range(i, 6):  # (i != j: no coupling between the modes, as modal damping has none)
                P = 0.5 * (np.outer(Phi[:, i], Phi[:, j]) + np.outer(Phi[:, j], Phi[:, i]))
                s_ij = np.sqrt(scale[i] * scale[j])
                rows.append(np.where(iu[0] == iu[1], 1.0, 2.0) * P[iu] / s_ij)
                rhs.append(need[i] / s_ij if i == j else 0.0)
    x = np.linalg.lstsq(np.array(rows), np.array(rhs), rcond=None)[0]
    D = np.zeros((6, 6))
    D[iu] = x
    D = D + np.triu(D, 1).T
    lam, V = np.linalg.eigh(D)
    D = (V * np.maximum(lam, 0.0)) @ V.T
    return JointModel(**{**jm.__dict__, "D": D})


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

    def twist_inertia_kgm2(self):
        """(6,) J_eff of each gear's twist phi = theta - q (kg*m^2): its link
        (1 / (M^-1)_jj, the rest of the arm free) in series with its motor."""
        return 1.0 / (np.diag(np.linalg.inv(self.M)) + 1.0 / self.motor_inertia_kgm2)

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

    def held_ratios(self):
        """(6,) the damping ratio D gives each motors-held mode."""
        w, Phi = held_modes(self.M, self.K, self.G)
        return np.diag(Phi.T @ self.D @ Phi) / (2.0 * w)

    def arm_modes(self):
        """(frequency Hz (6,), damping ratio (6,)) of the arm's modes with
        the drives closed, one per motors-held mode (ascending): the closed
        loop's oscillating mode whose link motion is most that mode's
        (modal assurance criterion on the links' displacement, mass-weighted;
        each closed-loop mode serves one), what a modal test on the tool
        with the drives on measures.  A motors-held mode the loop leaves
        without an oscillating match (made aperiodic) gets ratio 1."""
        lam, V = np.linalg.eig(self.continuous()[0])
        osc = np.nonzero(lam.imag > 1e-9)[0]
        _, Phi = held_modes(self.M, self.K, self.G)
        MPhi = self.M @ Phi
        Vq = V[0:6, osc]
        num = np.abs(MPhi.T @ Vq) ** 2  # (6 held, n osc); Phi^T M Phi = I
        den = np.real(np.einsum("ij,ik,kj->j", Vq.conj(), self.M, Vq))
        mac = num / np.maximum(den, 1e-300)
        f, z = np.zeros(6), np.ones(6)
        taken = set()
        for i, j in sorted(np.ndindex(mac.shape), key=lambda ij: -mac[ij]):
            if i in taken or osc[j] < 0 or mac[i, j] < 0.5:
                continue
            taken.add(i)
            f[i], z[i] = abs(lam[osc[j]]) / (2 * np.pi), -lam[osc[j]].real / abs(lam[osc[j]])
            osc[j] = -1
        w = held_modes(self.M, self.K, self.G)[0]
        f[z == 1.0] = w[z == 1.0] / (2 * np.pi)
        return f, z

    def at_pose(self, M, G):
        """These gears, damping D and drives (tuned where they were) on the
        arm at another pose (its mass matrix M and weight's stiffness G)."""
        return JointModel(**{**self.__dict__, "M": np.asarray(M, dtype=float), "G": G})

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
