"""The joint servo on the motor side: the robot controller's interpolator
delay, then a position loop (proportional, gain ``Kp``) around a velocity
loop (first order, bandwidth ``omega_v``) with velocity feed-forward, per
joint, in link-side units (the gear ratio divided out):

    theta'' = omega_v (Kp (theta_ref - theta) + f_v omega_ref - theta')

so that theta / theta_ref = omega_v (Kp + f_v s) / (s^2 + omega_v s + omega_v Kp).
The motor angle theta is what the encoder reads.  That kinematic form is
the rigid axis's response (the controller's own model of its lag, which
the compensator's timing uses).  The plant's drives are torque-level
(``drive_continuous``): the motor has its reflected rotor inertia J_m and
the gear's torque pushes it back, against a velocity loop with integral
action (a PI, as industrial drives have) around the position loop, with
the controller's gravity model fed forward as a torque:

    J_m theta'' = K_v (e_v + omega_i z) + tau_ff - tau_gear,
    e_v = Kp (theta_ref - theta) + f_v omega_ref - theta',   z' = e_v,

K_v tuned for the rigid axis (motor and link inertia) so that a rigid
axis has the velocity bandwidth omega_v: then the kinematic form above is
its response, and the compensator's lag estimate stays what it was.

A command without velocity feed-forward (a correction from the wrist
sensor, say) reaches the motor after the interpolator's delay and, at low
frequency, the position loop's lag 1 / Kp.

Plain numpy/scipy: the per-joint continuous model and its exact
discretisation for a step.
"""

from dataclasses import dataclass, replace

import numpy as np
from scipy import linalg, signal


@dataclass(frozen=True)
class ServoParameters:
    position_gain_per_s: float  # Kp, 1/s
    velocity_bandwidth_hz: float  # omega_v / (2 pi)
    velocity_feedforward: float  # f_v, 0..1
    interpolator_delay_s: float  # dead time from a new joint reference to the drives
    # the velocity loop's integral corner omega_i / (2 pi) (Hz): the drives' PI (``drive_continuous``).
    # ASSUMPTION: a quarter of the velocity bandwidth (the usual PI tuning keeps the integral corner a
    # factor 4-5 below the loop's crossover, for its phase margin); ABB publishes no drive tuning.  With
    # ``integral_rule`` "antiresonance" this is only the upper bound: the corner is chosen from the arm's
    # modes when the joints are built (``integral_corner_hz``; model/joint_dynamics.linear_joints).
    velocity_integral_hz: float = 7.5
    integral_rule: str = "stated"  # "stated": velocity_integral_hz as given; "antiresonance": integral_corner_hz

    @property
    def omega_v(self):
        return 2.0 * np.pi * self.velocity_bandwidth_hz

    @property
    def low_frequency_lag_s(self):
        """Lag (s) of a reference without velocity feed-forward at low
        frequency: the interpolator's delay plus 1 / Kp."""
        return self.interpolator_delay_s + 1.0 / self.position_gain_per_s

    def continuous(self):
        """(A, B, C, D) of one joint: state (theta, theta'), input
        (theta_ref, omega_ref), output (theta, theta')."""
        wv, kp, fv = self.omega_v, self.position_gain_per_s, self.velocity_feedforward
        A = np.array([[0.0, 1.0], [-wv * kp, -wv]])
        B = np.array([[0.0, 0.0], [wv * kp, wv * fv]])
        return A, B, np.eye(2), np.zeros((2, 2))

    def discrete(self, step_s, n_joints=6):
        """(A, B, C, D) of ``n_joints`` servos discretised exactly (zero-order
        hold) for ``step_s``: state (theta (n), theta' (n)), input
        (theta_ref (n), omega_ref (n)), output (theta (n), theta' (n))."""
        A, B, C, D = self.continuous()
        Ad, Bd, *_ = signal.cont2discrete((A, B, C, D), step_s, method="zoh")
        eye = np.eye(n_joints)
        # reorder the per-joint blocks into (all thetas, all rates)
        return (np.kron(Ad, eye), np.kron(Bd, eye), np.eye(2 * n_joints), np.zeros((2 * n_joints, 2 * n_joints)))

    def discrete_with_delay(self, step_s, n_delay, n_joints=6):
        """As ``discrete``, with the interpolator's dead time as a shift
        register of ``n_delay`` steps in front of the servo, in one system
        (one discrete update per step instead of three): state (the
        register's n_delay inputs, oldest last, then theta, theta')."""
        A, B, _, _ = self.discrete(step_s, n_joints)
        m = 2 * n_joints  # one input sample: (theta_ref, omega_ref)
        n = m * n_delay
        Aa = np.zeros((n + m, n + m))
        Ba = np.zeros((n + m, m))
        if n_delay == 0:
            return A, B, np.eye(m), np.zeros((m, m))
        Ba[:m] = np.eye(m)  # the newest sample enters the register
        for k in range(1, n_delay):
            Aa[k * m:(k + 1) * m, (k - 1) * m:k * m] = np.eye(m)  # and moves along it
        Aa[n:, n - m:n] = B  # the servo sees the oldest
        Aa[n:, n:] = A
        C = np.hstack([np.zeros((m, n)), np.eye(m)])
        return Aa, Ba, C, np.zeros((m, m))

    def frequency_response(self, f_hz, velocity_feedforward=True):
        """theta / theta_ref at ``f_hz`` (complex), with or without the
        reference's velocity fed forward; the interpolator's delay included."""
        s = 2j * np.pi * np.asarray(f_hz, dtype=float)
        wv, kp = self.omega_v, self.position_gain_per_s
        fv = self.velocity_feedforward if velocity_feedforward else 0.0
        return wv * (kp + fv * s) / (s * s + wv * s + wv * kp) * np.exp(-s * self.interpolator_delay_s)


# The drives' integral corner sits this factor below the arm's first antiresonance (``integral_corner_hz``).
# REASONING: the drive sees its motor's velocity; the zeros of that response (its antiresonances) are the
# frequencies of the links on the gears with the motors held, the lowest the arm's first motors-held mode.
# The PI's integral lags the motor's torque by atan(f_i / f) at frequency f: a corner at or above the
# antiresonance turns the drive's velocity feedback, which damps the arm's modes, into one that takes damping
# away (IRB 6400 at the block test's start: 5 % motors held came out 3.6 / 4.3 / 5.5 % on the first three
# modes with the drives closed at 7.5 Hz, against a first antiresonance of 4.9 Hz; studies/plant_modes.py).
# A quarter leaves 14 degrees of lag at the antiresonance, and the drives closed damp every one of the first
# modes at least as much as the gears alone (tests/test_joint_dynamics.py); the same factor 4 the stated
# corner keeps below the velocity loop's crossover.  What it costs: the drives give up a static torque error
# over 1 / (2 pi f_i) instead (0.13 s at 1.2 Hz), which the position loop's gain holds meanwhile.
INTEGRAL_BELOW_ANTIRESONANCE = 4.0


def integral_corner_hz(servo, first_antiresonance_hz):
    """The drives' integral corner (Hz): ``servo.velocity_integral_hz``
    when its rule is "stated", else the arm's first antiresonance (Hz, the
    first motors-held mode) over INTEGRAL_BELOW_ANTIRESONANCE, at most the
    stated corner."""
    if servo.integral_rule == "stated":
        return float(servo.velocity_integral_hz)
    if servo.integral_rule != "antiresonance":
        raise ValueError(f"servo integral_rule {servo.integral_rule!r}: one of stated, antiresonance")
    return float(min(servo.velocity_integral_hz, first_antiresonance_hz / INTEGRAL_BELOW_ANTIRESONANCE))


def with_integral_corner(servo, first_antiresonance_hz):
    """``servo`` with its integral corner chosen (rule "stated" from then on)."""
    return replace(servo, velocity_integral_hz=round(integral_corner_hz(servo, first_antiresonance_hz), 6),
                   integral_rule="stated")


# the drives' inputs, in order: the interpolated reference (theta_ref, omega_ref) and the torque
# feed-forward (all three delayed by the interpolator), then the gear's torque on the motor (not delayed)
DRIVE_REFERENCE_SIZE = 18


def velocity_gain_Nms(servo, rigid_inertia_kgm2):
    """K_v (6,) N*m*s/rad: the velocity loop's gain that gives a rigid axis
    of inertia ``rigid_inertia_kgm2`` (motor and link, reflected to the
    joint) the velocity bandwidth omega_v."""
    return np.asarray(rigid_inertia_kgm2, dtype=float) * servo.omega_v


def drive_continuous(servo, motor_inertia_kgm2, velocity_gain):
    """(A, B) of the six torque-level drives (see the module docstring):
    state (theta (6), theta' (6), z (6): the velocity error's integral),
    input (theta_ref, omega_ref, tau_ff, tau_gear) (24: rad, rad/s, N*m,
    N*m), motor inertias ``motor_inertia_kgm2`` (6, kg*m^2, reflected to
    the joint) and velocity gains ``velocity_gain`` (6, N*m*s/rad)."""
    Jinv = np.diag(1.0 / np.asarray(motor_inertia_kgm2, dtype=float))
    Kv = np.diag(np.asarray(velocity_gain, dtype=float))
    kp, fv, wi = servo.position_gain_per_s, servo.velocity_feedforward, 2.0 * np.pi * servo.velocity_integral_hz
    I, Z = np.eye(6), np.zeros((6, 6))
    # e_v = kp theta_ref + fv omega_ref - kp theta - theta'
    A = np.block([[Z, I, Z], [-kp * Jinv @ Kv, -Jinv @ Kv, wi * Jinv @ Kv], [-kp * I, -I, Z]])
    B = np.block([[Z, Z, Z, Z], [kp * Jinv @ Kv, fv * Jinv @ Kv, Jinv, -Jinv], [kp * I, fv * I, Z, Z]])
    return A, B


def drive_discrete(servo, step_s, motor_inertia_kgm2, velocity_gain, n_delay=0):
    """(A, B, C, D) of the drives discretised exactly for ``step_s`` with
    their inputs held over the step (zero-order hold), with the
    interpolator's dead time as a shift register of ``n_delay`` samples of
    the reference and feed-forward in front of them (one system, one
    discrete update per step): state (the register, oldest last; theta,
    theta', z), input (theta_ref, omega_ref, tau_ff, tau_gear), output
    (theta, theta')."""
    A, B = drive_continuous(servo, motor_inertia_kgm2, velocity_gain)
    nx, nu = A.shape[0], B.shape[1]
    E = linalg.expm(np.block([[A, B], [np.zeros((nu, nx + nu))]]) * step_s)
    Ad, Bd = E[:nx, :nx], E[:nx, nx:]
    m = DRIVE_REFERENCE_SIZE
    n = m * n_delay
    Aa = np.zeros((n + nx, n + nx))
    Ba = np.zeros((n + nx, nu))
    Aa[n:, n:] = Ad
    Ba[n:, m:] = Bd[:, m:]  # the gear's torque acts at once
    if n_delay == 0:
        Ba[n:, :m] = Bd[:, :m]
    else:
        Ba[:m, :m] = np.eye(m)  # the newest sample enters the register
        for k in range(1, n_delay):
            Aa[k * m:(k + 1) * m, (k - 1) * m:k * m] = np.eye(m)  # and moves along it
        Aa[n:, n - m:n] = Bd[:, :m]  # the drive sees the oldest
    C = np.hstack([np.zeros((12, n)), np.eye(12), np.zeros((12, 6))])
    return Aa, Ba, C, np.zeros((12, nu))


def drive_state_at_rest(servo, velocity_gain, theta_rad, gear_torque_Nm, feedforward_Nm, n_delay=0):
    """The drives' state (as ``drive_discrete`` orders it) at rest at motor
    angles ``theta_rad`` holding ``gear_torque_Nm`` with ``feedforward_Nm``
    fed forward: the register full of (theta, 0, tau_ff), the integral
    carrying what the feed-forward does not."""
    wi = 2.0 * np.pi * servo.velocity_integral_hz
    z = (np.asarray(gear_torque_Nm, dtype=float) - np.asarray(feedforward_Nm, dtype=float)) / (
        np.asarray(velocity_gain, dtype=float) * wi)
    sample = np.concatenate([theta_rad, np.zeros(6), feedforward_Nm])
    return np.concatenate([np.tile(sample, n_delay), theta_rad, np.zeros(6), z])
