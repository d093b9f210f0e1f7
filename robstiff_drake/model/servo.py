"""The joint servo on the motor side: the robot controller's interpolator
delay, then a position loop (proportional, gain ``Kp``) around a velocity
loop (first order, bandwidth ``omega_v``) with velocity feed-forward, per
joint, in link-side units (the gear ratio divided out):

    theta'' = omega_v (Kp (theta_ref - theta) + f_v omega_ref - theta')

so that theta / theta_ref = omega_v (Kp + f_v s) / (s^2 + omega_v s + omega_v Kp).
The motor angle theta is what the encoder reads.  The servo is taken as
stiff against the load: the gear's torque does not push the motor back
(the velocity loop's integral action makes its static stiffness infinite,
and its dynamic stiffness is far above the gear's at the arm's modes);
what the load does is twist the gear (model/transmission.py).

A command without velocity feed-forward (a correction from the wrist
sensor, say) reaches the motor after the interpolator's delay and, at low
frequency, the position loop's lag 1 / Kp.

Plain numpy/scipy: the per-joint continuous model and its exact
discretisation for a step.
"""

from dataclasses import dataclass

import numpy as np
from scipy import signal


@dataclass(frozen=True)
class ServoParameters:
    position_gain_per_s: float  # Kp, 1/s
    velocity_bandwidth_hz: float  # omega_v / (2 pi)
    velocity_feedforward: float  # f_v, 0..1
    interpolator_delay_s: float  # dead time from a new joint reference to the drives

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
