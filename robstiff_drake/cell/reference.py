"""The joint reference a compensator streams: the path's joint angles in
the controller's degrees against time since the session started, with
how far it moves around each row (for cell/safety.py's envelope)."""

import bisect

import numpy as np

from robstiff_drake.cell.safety import FOLLOW_S, motion_within


class Reference:
    """The joint reference in the controller's degrees against time since
    the session started: (times s, q (N, 6) deg), held at its ends, or a
    constant (``hold``); with each row's motion over one period and over
    the servo's follow time (for the safety envelope)."""

    def __init__(self, times_s=None, q_deg=None, period_s=0.004):
        self.period_s = float(period_s)
        if times_s is not None:
            self._set(np.asarray(times_s, dtype=float), np.asarray(q_deg, dtype=float).reshape(-1, 6))
        else:
            self.t = self.q = None

    def _set(self, t, q):
        self.t, self.q = t, q
        self._t = t.tolist()
        self._rows = q.tolist()
        self._m1 = motion_within(t, q, self.period_s).tolist()
        self._mf = motion_within(t, q, self.period_s + FOLLOW_S).tolist()

    def hold(self, q_deg):
        self._set(np.array([0.0]), np.asarray(q_deg, dtype=float).reshape(1, 6))

    def _index(self, t_s):
        return max(0, min(bisect.bisect_right(self._t, t_s) - 1, len(self._t) - 1))

    def at(self, t_s):
        """(q (list, deg) at t_s: linear between rows, motion over a period,
        motion over the follow time) (scalar code: a few microseconds)."""
        t, rows = self._t, self._rows
        i = self._index(t_s)
        j = min(i + 1, len(t) - 1)
        m1 = [max(a, b) for a, b in zip(self._m1[i], self._m1[j])]
        mf = [max(a, b) for a, b in zip(self._mf[i], self._mf[j])]
        if t_s <= t[0] or len(t) == 1 or t_s >= t[-1]:
            return list(rows[0] if t_s <= t[0] else rows[-1]), m1, mf
        f = (t_s - t[i]) / (t[i + 1] - t[i])
        a, b = rows[i], rows[i + 1]
        return [x + f * (y - x) for x, y in zip(a, b)], m1, mf

    @property
    def duration_s(self):
        return float(self.t[-1])
