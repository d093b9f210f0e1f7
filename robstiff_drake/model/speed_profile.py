"""The speed along a planned tool path (model/path.py): the speed each
block of moves can hold, and the arc length along the path at a time.
Plain Python; no Drake.

Speed.  Every move has its programmed speed (G1 / G2 / G3: F; G0: the
rapid speed; a blend: the slower of its two moves).  A change of speed is a
cosine ramp of ``ramp_s`` (speed (1 - cos(pi tau / ramp_s)) / 2 between
the two), placed in the faster move: a deceleration ends where the slower
move starts, an acceleration starts where the faster one starts; the
path starts and ends at rest.  A move too short to hold its ramps at its
speed gets a lower speed (as a controller's look-ahead does).  The speed
is continuous and its derivative too: nothing steps.
"""

import bisect
import math

def _ramp_distance(va, vb, w):
    """Distance (m) of a cosine ramp from va to vb over w seconds."""
    return 0.5 * (va + vb) * w


def plan_speeds(lengths, speeds, stops, ramp_s):
    """Speeds of blocks of constant commanded speed, lowered where a block
    cannot hold its ramps.  ``stops[i]``: the path stops after block i.
    Returns the block speeds (m/s)."""
    v = [float(x) for x in speeds]
    n = len(v)
    if ramp_s <= 0:
        return v

    def need(i, V):
        vp = 0.0 if i == 0 or stops[i - 1] else v[i - 1]
        vn = 0.0 if i == n - 1 or stops[i] else v[i + 1]
        return (_ramp_distance(vp, V, ramp_s) if V > vp else 0.0) + (_ramp_distance(V, vn, ramp_s) if V > vn else 0.0)

    for _ in range(10 * n + 10):  # lowering one block can lower its neighbours' needs only
        changed = False
        for i in range(n):
            if need(i, v[i]) <= lengths[i] * (1 + 1e-12):
                continue
            lo, hi = 0.0, v[i]  # need() does not decrease with V: the largest V that fits
            for _ in range(80):
                mid = 0.5 * (lo + hi)
                lo, hi = (mid, hi) if need(i, mid) <= lengths[i] else (lo, mid)
            v[i] = lo
            changed = True
        if not changed:
            break
    return v


class SpeedProfile:
    """Arc length s(t) (m) of blocks of given lengths and planned speeds,
    with cosine ramps of ``ramp_s`` in the faster block at every change;
    ``dwells[i]`` (s): a rest after block i (which must end in a stop)."""

    def __init__(self, lengths, speeds, stops, ramp_s, dwells=None):
        self.ramp_s = float(ramp_s)
        v = plan_speeds(lengths, speeds, stops, ramp_s)
        phases = []  # (t0, s0, va, vb, duration): ramp if va != vb else cruise
        t = s = 0.0
        n = len(v)
        w = self.ramp_s
        for i in range(n):
            vp = 0.0 if i == 0 or stops[i - 1] else v[i - 1]
            vn = 0.0 if i == n - 1 or stops[i] else v[i + 1]
            d_in = _ramp_distance(vp, v[i], w) if v[i] > vp and w > 0 else 0.0
            d_out = _ramp_distance(v[i], vn, w) if v[i] > vn and w > 0 else 0.0
            if d_in > 0:
                phases.append((t, s, vp, v[i], w))
                t, s = t + w, s + d_in
            cruise = lengths[i] - d_in - d_out
            if cruise > 0 and v[i] > 0:
                phases.append((t, s, v[i], v[i], cruise / v[i]))
                t, s = t + cruise / v[i], s + cruise
            if d_out > 0:
                phases.append((t, s, v[i], vn, w))
                t, s = t + w, s + d_out
            if dwells is not None and dwells[i] > 0:  # at rest: a phase of speed 0
                phases.append((t, s, 0.0, 0.0, float(dwells[i])))
                t += float(dwells[i])
        self.phases = phases
        self.duration_s = t
        self.length = float(sum(lengths))
        self._t0 = [p[0] for p in phases]
        self.block_speeds = v

    def arc_length(self, tau):
        """Distance along the path tau seconds after the motion starts."""
        if tau <= 0 or not self.phases:
            return 0.0
        if tau >= self.duration_s:
            return self.length
        k = bisect.bisect_right(self._t0, tau) - 1
        t0, s0, va, vb, dur = self.phases[k]
        x = tau - t0
        if va == vb:
            return s0 + va * x
        # cosine ramp: v = va + (vb - va) (1 - cos(pi x / w)) / 2
        return s0 + va * x + 0.5 * (vb - va) * (x - dur / math.pi * math.sin(math.pi * x / dur))

    def speed(self, tau):
        if tau <= 0 or tau >= self.duration_s or not self.phases:
            return 0.0
        k = bisect.bisect_right(self._t0, tau) - 1
        t0, _, va, vb, dur = self.phases[k]
        return va + (vb - va) * 0.5 * (1.0 - math.cos(math.pi * (tau - t0) / dur)) if va != vb else va

