"""The elements of a planned tool path (model/path.py): lines, arcs (helical
where they climb) and the corner paths that blend two of them, and the
cutting of programmed moves into parts of their own speed.  Plain numpy;
no Drake.

Corners (zones).  A robot controller does not stop at a programmed corner
it may fly by: within a zone of radius r around the corner (ABB's zone data
z1, z5, z10 ...: r = 1, 5, 10 mm) it leaves the programmed path and joins
the next move on a rounded corner path, at the programmed speed.  Here the
corner path is the cubic Bezier curve from the point r before the corner to
the point r after it with both inner control points at the corner: it is
tangent to both moves and, for two lines, has zero curvature where it
joins them (curvature-continuous), so the tool's acceleration has no step
there; its closest approach to the corner is a quarter of the way from the
corner to the chord's midpoint.  As the controller does, a zone is reduced
to half the shorter of the two moves.  A reversal (a turn of more than
``MAX_BLEND_TURN_DEG``) cannot be flown by: the path stops there.  Zone 0
keeps the sharp corner at full speed (the path this module planned before
blending existed, for comparison: no controller moves like that).
"""

import math

import numpy as np

# A corner turning more than this is a reversal: the path stops there.
MAX_BLEND_TURN_DEG = 170.0
# Tangent directions closer than this (rad) are one smooth path: no blend.
TANGENT_TOLERANCE_RAD = 1e-4
_BEZIER_TABLE = 257  # arc-length samples of a corner curve


class Line:
    def __init__(self, p0, p1):
        self.p0 = np.asarray(p0, dtype=float)
        self.p1 = np.asarray(p1, dtype=float)
        d = self.p1 - self.p0
        self.length = float(np.linalg.norm(d))
        self.u = d / self.length
        # the same as floats, for scalar code (PlannedPath.project, every force update)
        self.p0_xyz, self.u_xyz = tuple(self.p0.tolist()), tuple(self.u.tolist())

    def point(self, s):
        return self.p0 + self.u * s

    def tangent(self, s):
        return self.u

    def trimmed(self, s0, s1):
        return Line(self.point(s0), self.point(s1))


class Arc:
    """An arc about an axis n (a helix when the point moves along n): its
    centre, radius, start angle and signed sweep (rad, counter-clockwise +
    seen from +n) in the plane of the unit vectors u, v (n = u x v), and
    the positions h0, h1 along n at its start and end.  The default plane
    is XY (u = x, v = y, n = z): centre (x, y), heights z.  ``center``:
    (x, y) in that default plane, or a 3D point on the axis."""

    def __init__(self, center, radius, angle0, sweep, h0, h1, u=(1.0, 0.0, 0.0), v=(0.0, 1.0, 0.0)):
        self.u = np.asarray(u, dtype=float)
        self.v = np.asarray(v, dtype=float)
        self.n = np.cross(self.u, self.v)
        c = np.zeros(3)
        c[: len(center)] = np.asarray(center, dtype=float)
        self.c = c - self.n * float(np.dot(self.n, c))  # the axis' point in the plane through the origin
        self.r = float(radius)
        self.a0 = float(angle0)
        self.sweep = float(sweep)
        self.z0, self.z1 = float(h0), float(h1)
        self.length = math.hypot(self.r * self.sweep, self.z1 - self.z0)

    def point(self, s):
        f = s / self.length
        a = self.a0 + self.sweep * f
        return (self.c + self.r * (math.cos(a) * self.u + math.sin(a) * self.v)
                + self.n * (self.z0 + (self.z1 - self.z0) * f))

    def tangent(self, s):
        a = self.a0 + self.sweep * s / self.length
        k = self.r * self.sweep / self.length
        return k * (-math.sin(a) * self.u + math.cos(a) * self.v) + self.n * ((self.z1 - self.z0) / self.length)

    def trimmed(self, s0, s1):
        f0, f1 = s0 / self.length, s1 / self.length
        dz = self.z1 - self.z0
        return Arc(self.c, self.r, self.a0 + self.sweep * f0, self.sweep * (f1 - f0), self.z0 + dz * f0,
                   self.z0 + dz * f1, self.u, self.v)


class Corner:
    """The zone's corner path: a cubic Bezier curve P0 -> P3 with control
    points P1, P2, evaluated at arc length through a table."""

    def __init__(self, p0, p1, p2, p3):
        self.P = np.array([p0, p1, p2, p3], dtype=float)
        u = np.linspace(0.0, 1.0, _BEZIER_TABLE)
        pts = self._at(u)
        seg = np.linalg.norm(np.diff(pts, axis=0), axis=1)
        self._s = np.r_[0.0, np.cumsum(seg)]
        self._u = u
        self.length = float(self._s[-1])

    def _at(self, u):
        u = np.asarray(u, dtype=float)[..., None]
        a, b, c, d = self.P
        return (1 - u) ** 3 * a + 3 * (1 - u) ** 2 * u * b + 3 * (1 - u) * u * u * c + u ** 3 * d

    def _param(self, s):
        return float(np.interp(s, self._s, self._u))

    def point(self, s):
        return self._at(self._param(s))

    def tangent(self, s):
        u = self._param(s)
        a, b, c, d = self.P
        t = 3 * (1 - u) ** 2 * (b - a) + 6 * (1 - u) * u * (c - b) + 3 * u * u * (d - c)
        n = np.linalg.norm(t)
        return t / n if n > 0 else (d - a) / np.linalg.norm(d - a)

    def trimmed(self, s0, s1):
        """The part between arc lengths s0 and s1: the same curve (de
        Casteljau's subdivision of the Bezier curve)."""
        u0, u1 = self._param(s0), self._param(s1)

        def split(P, u):  # (left, right) control points at parameter u
            a, b, c, d = P
            ab, bc, cd = a + u * (b - a), b + u * (c - b), c + u * (d - c)
            abc, bcd = ab + u * (bc - ab), bc + u * (cd - bc)
            m = abc + u * (bcd - abc)
            return (a, ab, abc, m), (m, bcd, cd, d)

        left, _ = split(self.P, u1) if u1 < 1.0 else (tuple(self.P), None)
        _, mid = split(np.array(left), u0 / u1) if u0 > 0.0 and u1 > 0.0 else (None, left)
        return Corner(*mid)


def _turn_rad(t_in, t_out):
    c = float(np.clip(np.dot(t_in, t_out), -1.0, 1.0))
    return math.acos(c)


def blend_corners(elements, speeds, zone_m, forced_stops=None, provenance=False):
    """Insert a corner path at every corner between consecutive elements.

    ``forced_stops[i]``: the path must stop after element i (an exact stop
    of the program: G61, G9, M0, a dwell): no zone there.  Returns
    (elements, speeds, stop_after, source): ``stop_after[k]`` is True where
    the path must stop after element k (a reversal, or a forced stop; a
    sharp corner at zone 0 keeps full speed, as before blending: False);
    ``source[k]``: the index of the input element that element k is part
    of (a corner path: the element it leaves).  With ``provenance``, also
    each output element's origin: ("move", i, s0, s1) for the part s0..s1
    of input element i, ("corner", i, r, r) for the corner between
    elements i and i + 1 (from r before its end to r into the next)."""
    n = len(elements)
    stops = list(forced_stops) if forced_stops is not None else [False] * n
    if n < 2 or zone_m < 0:
        origins = [("move", i, 0.0, e.length) for i, e in enumerate(elements)]
        return (list(elements), list(speeds), stops, list(range(n))) + ((origins,) if provenance else ())
    # zone of each corner: at most half of each neighbour's length
    zones = []
    for i in range(n - 1):
        a, b = elements[i], elements[i + 1]
        turn = _turn_rad(a.tangent(a.length), b.tangent(0.0))
        if stops[i] or turn < TANGENT_TOLERANCE_RAD or zone_m == 0:
            zones.append(0.0)
        elif turn > math.radians(MAX_BLEND_TURN_DEG):
            zones.append(0.0)
            stops[i] = True
        else:
            zones.append(min(zone_m, 0.5 * a.length, 0.5 * b.length))
    out, out_speeds, out_stops, source, origins = [], [], [], [], []
    for i, e in enumerate(elements):
        s0 = zones[i - 1] if i > 0 else 0.0
        s1 = e.length - (zones[i] if i < n - 1 else 0.0)
        if s1 - s0 > 1e-12:  # (an element between two full zones vanishes)
            out.append(e.trimmed(s0, s1) if (s0 > 0 or s1 < e.length) else e)
            out_speeds.append(speeds[i])
            out_stops.append(stops[i])
            source.append(i)
            origins.append(("move", i, s0, s1))
        if i < n - 1 and zones[i] > 0:
            b = elements[i + 1]
            r = zones[i]
            p0, p3 = e.point(e.length - r), b.point(r)
            # control points where the tangents at p0 and p3 meet the corner
            # (for two lines: the corner itself)
            c1 = p0 + e.tangent(e.length - r) * r
            c2 = p3 - b.tangent(r) * r
            out.append(Corner(p0, c1, c2, p3))
            out_speeds.append(min(speeds[i], speeds[i + 1]))
            out_stops.append(False)
            source.append(i)
            origins.append(("corner", i, r, r))
    return (out, out_speeds, out_stops, source) + ((origins,) if provenance else ())


def split_for_speeds(elements, speeds, overrides, zone_m):
    """The programmed elements split where speed ``overrides`` ({element
    index: [(a, b, v m/s)]}, a..b m along the element) begin and end, each
    part at the lower of its own speed and the override over it.  A span
    is widened to whole parts of at least two zones from the element's ends
    (and parts shorter than two zones join their neighbour), so every corner
    keeps its zone: the same geometry.  Returns (elements, speeds, origins): origin
    (i, a, b) of each part (model/feed_plan.py maps them back to the program)."""
    out, out_v, origins = [], [], []
    near = 2.0 * zone_m
    short = near - 1e-9  # (a part of exactly two zones is long enough)
    for i, (e, v) in enumerate(zip(elements, speeds)):
        spans = (overrides or {}).get(i, [])
        L = e.length
        cuts = {0.0, L}
        snapped = []
        for a, b, w in spans:  # each span widened to whole parts of at least two zones
            if L < 2.0 * near:
                a, b = 0.0, L
            a = 0.0 if a < near else min(a, L - near)
            b = L if b > L - near else max(b, near)
            snapped.append((a, b, w))
            cuts |= {a, b}
        spans = snapped
        cuts = sorted(cuts)
        keep = [cuts[0]]
        for x in cuts[1:]:  # no part shorter than two zones (unless the element is)
            if x - keep[-1] >= short or x == L:
                keep.append(x)
        if len(keep) > 2 and keep[-1] - keep[-2] < short:
            del keep[-2]
        for c0, c1 in zip(keep[:-1], keep[1:]):
            mid = 0.5 * (c0 + c1)  # (a snapped cut moved a span's end outwards by less than two zones)
            vv = min([v] + [o[2] for o in spans if o[0] <= mid <= o[1]])
            whole = len(keep) == 2
            out.append(e if whole else e.trimmed(c0, c1))
            out_v.append(vv)
            origins.append((i, c0, c1))
    return out, out_v, origins
