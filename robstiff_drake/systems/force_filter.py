"""The force filter: a discrete low-pass (Butterworth, designed with
scipy.signal) or a spindle-revolution moving average, on all six channels,
as a Drake LinearSystem running at the sensor rate.  The design is
model/filters.py's (shared with the compensator process)."""

import numpy as np
from pydrake.systems.primitives import LinearSystem
from scipy import signal

from robstiff_drake.model.filters import group_delay_s, lowpass_coefficients, revolution_average_coefficients

__all__ = ["filter_system", "group_delay_s", "lowpass_coefficients", "revolution_average_coefficients", "steady_state"]


def filter_system(b, a, rate_hz, channels=6):
    """A discrete LinearSystem applying the SISO filter (b, a) to each channel."""
    A, B, C, D = signal.tf2ss(b, a)
    n = A.shape[0]
    eye = np.eye(channels)
    if n == 0:
        return LinearSystem(np.zeros((0, 0)), np.zeros((0, channels)), np.zeros((channels, 0)),
                            float(np.squeeze(D)) * eye, 1.0 / rate_hz)
    return LinearSystem(np.kron(eye, A), np.kron(eye, B), np.kron(eye, C), np.kron(eye, D), 1.0 / rate_hz)


def steady_state(system, u0):
    """State at which the filter outputs u0 for the constant input u0
    (start the filter settled on the initial reading, not at zero)."""
    A, B = system.A(), system.B()
    if A.shape[0] == 0:
        return np.zeros(0)
    return np.linalg.solve(np.eye(A.shape[0]) - A, B @ np.asarray(u0, dtype=float))
