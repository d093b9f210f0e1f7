"""The force filter: a discrete low-pass (Butterworth, designed with
scipy.signal) or a spindle-revolution moving average, on all six channels,
as a Drake LinearSystem running at the sensor rate."""

import numpy as np
from pydrake.systems.primitives import LinearSystem
from scipy import signal


def lowpass_coefficients(cutoff_hz, rate_hz, order=2):
    """(b, a) of a discrete Butterworth low-pass (bilinear, prewarped)."""
    if not 0 < cutoff_hz < 0.5 * rate_hz:
        raise ValueError(f"cutoff {cutoff_hz} Hz must be between 0 and the Nyquist rate {0.5 * rate_hz} Hz")
    return signal.butter(order, cutoff_hz, btype="low", fs=rate_hz)


def revolution_average_coefficients(spindle_rpm, rate_hz):
    """(b, a) of a moving average over one spindle revolution (rounded to
    whole samples, at least 1): a notch at the spindle and tooth-pass
    frequencies and their harmonics."""
    n = max(1, int(round(rate_hz * 60.0 / spindle_rpm)))
    return np.ones(n) / n, np.r_[1.0, np.zeros(n - 1)]


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


def group_delay_s(b, a, rate_hz, f_hz=0.5):
    """Low-frequency group delay of the filter (s), the lag it adds to a
    slowly changing force."""
    w, gd = signal.group_delay((b, a), w=[f_hz], fs=rate_hz)
    return float(gd[0]) / rate_hz
