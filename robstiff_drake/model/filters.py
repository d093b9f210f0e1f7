"""The force filter's design (a discrete Butterworth low-pass, or a moving
average over one spindle revolution) and a per-sample six-channel filter in
plain Python for the compensator process.  No Drake: the Drake block
(systems/force_filter.py) realises the same (b, a) as a LinearSystem."""

import numpy as np
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


def filter_coefficients(kind, cutoff_hz, order, rate_hz, spindle_rpm):
    """(b, a) of the force filter ``kind``: "lowpass", "revolution_average" or "none"."""
    if kind == "lowpass":
        return lowpass_coefficients(cutoff_hz, rate_hz, order)
    if kind == "revolution_average":
        return revolution_average_coefficients(spindle_rpm, rate_hz)
    if kind == "none":
        return np.array([1.0]), np.array([1.0])
    raise ValueError(f"unknown filter kind {kind!r}")


def group_delay_s(b, a, rate_hz, f_hz=0.5):
    """Low-frequency group delay of the filter (s), the lag it adds to a
    slowly changing force."""
    w, gd = signal.group_delay((b, a), w=[f_hz], fs=rate_hz)
    return float(gd[0]) / rate_hz


class SampleFilter:
    """The SISO filter (b, a) on six channels, one sample at a time
    (direct form II transposed, scalar arithmetic: a few microseconds per
    sample).  ``reset(u0)`` settles it on a constant input u0."""

    def __init__(self, b, a, channels=6):
        b = np.atleast_1d(np.asarray(b, dtype=float))
        a = np.atleast_1d(np.asarray(a, dtype=float))
        n = max(len(a), len(b))
        b = np.r_[b, np.zeros(n - len(b))] / a[0]
        a = np.r_[a, np.zeros(n - len(a))] / a[0]
        self._b = b.tolist()
        self._a = a.tolist()
        self._n = n - 1  # state length per channel
        self._channels = channels
        self._z = [[0.0] * self._n for _ in range(channels)]

    def reset(self, u0):
        """Settle every channel on the constant input u0 (output u0 times the DC gain)."""
        b, a, n = self._b, self._a, self._n
        for c, u in enumerate(u0):
            y = u * sum(b) / sum(a)
            # steady state of z_i = b_i u - a_i y + z_{i+1} (from the last one back)
            z = [0.0] * n
            acc = 0.0
            for i in range(n, 0, -1):
                acc += b[i] * u - a[i] * y
                z[i - 1] = acc
            self._z[c] = z

    def step(self, u):
        """One sample of six channels in, six out (lists)."""
        b, a, n = self._b, self._a, self._n
        if n == 2:  # (a biquad, the default order: the loop below unrolled, the same operations in the same order)
            b0, b1, b2 = b
            a1, a2 = a[1], a[2]
            out = []
            for x, z in zip(u, self._z):
                y = b0 * x + z[0]
                z[0] = b1 * x - a1 * y + z[1]
                z[1] = b2 * x - a2 * y
                out.append(y)
            return out
        return self._step_general(u)

    def _step_general(self, u):
        """``step`` for any order: the direct-form loop."""
        b, a, n = self._b, self._a, self._n
        out = []
        for c, x in enumerate(u):
            z = self._z[c]
            y = b[0] * x + (z[0] if n else 0.0)
            for i in range(n - 1):
                z[i] = b[i + 1] * x - a[i + 1] * y + z[i + 1]
            if n:
                z[n - 1] = b[n] * x - a[n] * y
            out.append(y)
        return out


def noise_std_factor(b, a, n_samples=1 << 16):
    """The factor the filter (b, a) scales white noise's standard deviation
    by, per sample at its own rate: the root of the sum of its impulse
    response's squares (``n_samples`` of it)."""
    impulse = np.zeros(int(n_samples))
    impulse[0] = 1.0
    h = signal.lfilter(b, a, impulse)
    return float(np.sqrt(np.sum(h * h)))
