"""The joint reference a compensator streams: the path's joint angles in
the controller's degrees against time since the session started, with
how far it moves around each row (for cell/safety.py's envelope).

Held as numpy arrays (a 67-minute path at 4 ms is a million rows: about
150 MB here, where Python lists of it held over a gigabyte); ``at`` reads
one row pair per call, from the last call's row onward (the session's
time only advances), so a call stays a few microseconds."""

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
        n = len(t)
        # per row i: q_i (deg), then the larger of rows i and i+1's motion over a period and over the follow time
        tab = np.empty((n, 18))
        tab[:, :6] = q
        for k, window_s in ((6, self.period_s), (12, self.period_s + FOLLOW_S)):
            m = motion_within(t, q, window_s, out=tab[:, k:k + 6])
            for lo in range(0, n - 1, 1 << 16):  # (in blocks: row i's block reads row i + 1 before it is written)
                hi = min(lo + (1 << 16), n - 1)
                m[lo:hi] = np.maximum(m[lo:hi], m[lo + 1:hi + 1])
        self.t, self._tab = t, tab
        self.q = tab[:, :6]  # (a view)
        self._n, self._t0, self._t_end = n, float(t[0]), float(t[-1])
        self._hint = 0

    def hold(self, q_deg):
        """A constant: ``_set``'s table of one row, without its window
        searches (a row's motion is zero; the hold starts on the controller's
        first message, whose answer is due within a cycle)."""
        tab = np.zeros((1, 18))
        tab[0, :6] = np.asarray(q_deg, dtype=float).reshape(6)
        self.t, self._tab = np.array([0.0]), tab
        self.q = tab[:, :6]
        self._n, self._t0, self._t_end = 1, 0.0, 0.0
        self._hint = 0

    def _index(self, t_s):
        """The last row at or before t_s (0 before the start, the last after the end)."""
        t, i = self.t, self._hint
        if t[i] <= t_s and (i + 1 >= self._n or t_s < t[i + 1]):
            return i
        if i + 2 < self._n and t[i + 1] <= t_s < t[i + 2]:
            i += 1
        else:
            i = max(0, min(int(np.searchsorted(t, t_s, side="right")) - 1, self._n - 1))
        self._hint = i
        return i

    def at(self, t_s):
        """(q (list, deg) at t_s: linear between rows, motion over a period,
        motion over the follow time) (scalar code: a few microseconds)."""
        i = self._index(t_s)
        a = self._tab[i].tolist()
        m1, mf = a[6:12], a[12:18]
        if t_s <= self._t0 or self._n == 1 or t_s >= self._t_end:
            return (a[:6] if t_s <= self._t0 else self._tab[-1, :6].tolist()), m1, mf
        t0, t1 = float(self.t[i]), float(self.t[i + 1])
        f = (t_s - t0) / (t1 - t0)
        b = self._tab[i + 1, :6].tolist()
        return [x + f * (y - x) for x, y in zip(a[:6], b)], m1, mf

    def speed_at(self, t_s):
        """The reference's own joint speeds around t_s (list, deg/s): per
        joint the larger of its row segment's at t_s and the next one's
        (finite differences of the rows; 0 beyond the ends and for a
        hold) (scalar code: a few microseconds)."""
        if self._n < 2 or t_s >= self._t_end:
            return [0.0] * 6
        i = self._index(t_s)  # (0 before the start: its first segments, a bound)
        t, tab = self.t, self._tab
        j = min(i + 2, self._n - 1)
        a, b, c = tab[i, :6].tolist(), tab[i + 1, :6].tolist(), tab[j, :6].tolist()
        h1 = float(t[i + 1] - t[i])
        h2 = float(t[j] - t[i + 1]) if j > i + 1 else 0.0
        return [max(abs(y - x) / h1 if h1 > 0.0 else 0.0, abs(z - y) / h2 if h2 > 0.0 else 0.0)
                for x, y, z in zip(a, b, c)]

    @property
    def duration_s(self):
        return float(self.t[-1])
