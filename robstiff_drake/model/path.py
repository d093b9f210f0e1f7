"""The planned tool path: lines and arcs (waypoints or a G-code program),
corners blended within a zone as a robot controller does, a smooth speed
profile, the spindle axis straight down, and the joint references that IK
gives along it.  Plain numpy; no Drake.

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

import numpy as np

from robstiff_drake.model import ik
from robstiff_drake.model import kinematics as kin
from robstiff_drake.model.stiffness import describe_singularity, singular_joints

# Closest a path may come to a singularity: smallest over largest singular
# value of the Jacobian (a pose this close would need huge joint rates).
MIN_JACOBIAN_CONDITION = 1e-3
# A corner turning more than this is a reversal: the path stops there.
MAX_BLEND_TURN_DEG = 170.0
# Tangent directions closer than this (rad) are one smooth path: no blend.
TANGENT_TOLERANCE_RAD = 1e-4
_BEZIER_TABLE = 257  # arc-length samples of a corner curve


class PathError(ValueError):
    """The path cannot be followed (reach, joint limits, singularity);
    ``where``: the tag of the path's element concerned (a program's
    "file:line"), or None."""

    def __init__(self, message, where=None):
        super().__init__(message)
        self.where = where


# ---------------------------------------------------------------- elements


class Line:
    def __init__(self, p0, p1):
        self.p0 = np.asarray(p0, dtype=float)
        self.p1 = np.asarray(p1, dtype=float)
        d = self.p1 - self.p0
        self.length = float(np.linalg.norm(d))
        self.u = d / self.length

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


# ---------------------------------------------------------------- speed profile


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


# ---------------------------------------------------------------- the path


class PlannedPath:
    """Tool point (m, base frame) along waypoints at ``feed_m_per_s``, or
    along the elements of a program (``from_elements``).

    The motion starts after ``dwell_s`` at rest, speeds up (and, at the end,
    slows down) with a cosine velocity ramp of ``ramp_s``; corners are
    blended within ``zone_m`` (see the module docstring).  For a straight
    path this is the constant feed between two ramps that the project has
    always used."""

    def __init__(self, waypoints_m, feed_m_per_s, yaw_rad=0.0, dwell_s=0.0, ramp_s=0.0, zone_m=0.0,
                 speed_overrides=None):
        wp = np.asarray(waypoints_m, dtype=float).reshape(-1, 3)
        if len(wp) < 2:
            raise PathError("a path needs at least two waypoints")
        if not feed_m_per_s > 0:
            raise PathError(f"feed must be > 0, got {feed_m_per_s}")
        seg = np.linalg.norm(np.diff(wp, axis=0), axis=1)
        if np.any(seg <= 0):
            raise PathError("two consecutive waypoints are the same point")
        elements = [Line(a, b) for a, b in zip(wp[:-1], wp[1:])]
        self._setup(elements, [float(feed_m_per_s)] * len(elements), wp, yaw_rad, dwell_s, ramp_s, zone_m,
                    speed_overrides=speed_overrides)

    @classmethod
    def from_elements(cls, elements, speeds_m_per_s, yaw_rad=0.0, dwell_s=0.0, ramp_s=0.0, zone_m=0.0, *,
                      stops=None, dwells_s=None, tags=None, speed_overrides=None, lines=None):
        """A path through Line / Arc elements, each at its own speed (m/s).
        ``stops[i]``: the path comes to rest after element i (an exact
        stop: no zone there); ``dwells_s[i]``: and rests there that long
        (s); ``tags[i]``: where element i comes from (a program's
        "file:line"), named by the errors of joint_references;
        ``lines[i]``: element i's program line (for the feed advice);
        ``speed_overrides``: see with_speed_overrides."""
        if not elements:
            raise PathError("a path needs at least one move")
        if any(not v > 0 for v in speeds_m_per_s):
            raise PathError("every move needs a speed > 0")
        self = cls.__new__(cls)
        wp = np.array([elements[0].point(0.0)] + [e.point(e.length) for e in elements])
        n = len(elements)
        dwells = [float(d) for d in dwells_s] if dwells_s is not None else [0.0] * n
        stops = [bool(x) or d > 0 for x, d in zip(stops if stops is not None else [False] * n, dwells)]
        self._setup(list(elements), [float(v) for v in speeds_m_per_s], wp, yaw_rad, dwell_s, ramp_s, zone_m,
                    stops, dwells, tags, speed_overrides, lines)
        return self

    def with_speed_overrides(self, overrides):
        """The same path with the speeds lowered over parts of its programmed
        elements ({element index: [(a, b, v m/s)]}, a..b m along it; see
        split_for_speeds), replacing its own overrides: the feed planner's
        adapted path (model/feed_plan.py)."""
        out = self.__class__.__new__(self.__class__)
        a = dict(self._args)
        a["speed_overrides"] = overrides
        out._setup(**a)
        return out

    def _setup(self, elements, speeds, waypoints, yaw_rad, dwell_s, ramp_s, zone_m, forced_stops=None, dwells=None,
               tags=None, speed_overrides=None, lines=None):
        self._args = dict(elements=elements, speeds=speeds, waypoints=waypoints, yaw_rad=yaw_rad, dwell_s=dwell_s,
                          ramp_s=ramp_s, zone_m=zone_m, forced_stops=forced_stops, dwells=dwells, tags=tags,
                          speed_overrides=speed_overrides, lines=lines)
        # the programmed elements and their speeds (m/s), before the feed planner's overrides
        self.programmed_elements = list(elements)
        self.programmed_speeds = list(speeds)
        self.program_lines = list(lines) if lines is not None else None
        self.speed_overrides = dict(speed_overrides or {})
        self.waypoints = waypoints
        self.directions = np.array([e.tangent(0.0) for e in elements])
        self.yaw = float(yaw_rad)
        self.dwell_s = float(dwell_s)
        self.zone_m = float(zone_m)
        self.feed = float(max(speeds))
        parts, part_speeds, part_of = split_for_speeds(elements, speeds, self.speed_overrides, self.zone_m)
        # the programmed elements' parts and their speeds: (element, from m, to m, speed m/s)
        self.parts = [(i, c0, c1, v) for (i, c0, c1), v in zip(part_of, part_speeds)]
        # an element's exact stop and dwell belong to its last part
        last_part = {i: j for j, (i, _c0, _c1) in enumerate(part_of)}
        part_stops = [bool(forced_stops[i]) and last_part[i] == j if forced_stops is not None else False
                      for j, (i, _c0, _c1) in enumerate(part_of)]
        self.elements, self.speeds, stops, source, blended = blend_corners(parts, part_speeds, self.zone_m,
                                                                           part_stops, provenance=True)
        # a dwell belongs to the last piece of its element (a stop: no corner path follows it)
        last_piece = {part_of[j][0]: k for k, j in enumerate(source)}
        self._dwells = [0.0] * len(self.elements)
        for i, d in enumerate(dwells or ()):
            if d > 0:
                self._dwells[last_piece[i]] = d
        self.tags = [tags[part_of[j][0]] for j in source] if tags is not None else None
        # each element's origin in the programmed elements: ("move", i, s0, s1): the part s0..s1 of element i;
        # ("corner", i, r_in, r_out): the corner between element i and the next, r before and after it
        self.origins = []
        for kind, j, a, b in blended:
            i, c0, c1 = part_of[j]
            if kind == "move":
                self.origins.append(("move", i, c0 + a, c0 + b))
            else:
                self.origins.append(("corner", i, a, b))
        self.lengths = np.array([e.length for e in self.elements])
        self.total_length = float(self.lengths.sum())
        self._s_knots = np.r_[0.0, np.cumsum(self.lengths)].tolist()
        # blocks of constant commanded speed (consecutive elements at one speed, no stop between)
        blocks, bspeeds, bstops, bdwells = [], [], [], []
        for i, (L, v) in enumerate(zip(self.lengths, self.speeds)):
            if blocks and bspeeds[-1] == v and not bstops[-1]:
                blocks[-1] += L
                bstops[-1] = stops[i]
                bdwells[-1] = self._dwells[i]
            else:
                blocks.append(float(L))
                bspeeds.append(v)
                bstops.append(stops[i])
                bdwells.append(self._dwells[i])
        # a short path has no cruise phase: as before, the ramps shrink to fit
        # a single block rather than slowing it down
        if len(blocks) == 1:
            ramp_s = min(float(ramp_s), blocks[0] / bspeeds[0])
        self.ramp_s = float(ramp_s)
        self.profile = SpeedProfile(blocks, bspeeds, bstops, self.ramp_s, bdwells)
        self.move_s = self.profile.duration_s
        # horizontal feed direction per element (the previous one's where an element is vertical)
        # and the feed the chip follows (the last horizontal move's along a
        # vertical one: a plunge or a retract makes no chip of its own speed)
        dirs, last = [], (1.0, 0.0)
        feeds, last_feed = [], None
        for e, v in zip(self.elements, self.speeds):
            t = e.tangent(0.5 * e.length)
            n = math.hypot(t[0], t[1])
            if n > 1e-6:
                last = (t[0] / n, t[1] / n)
                last_feed = v
            dirs.append(last)
            feeds.append(v if last_feed is None else last_feed)
        self._elem_dirs = dirs
        self._elem_feeds = feeds

    @property
    def duration_s(self):
        return self.dwell_s + self.move_s

    def signature(self):
        """A key that changes with the path's geometry or timing (for caches)."""
        parts = [self.dwell_s, self.ramp_s, self.zone_m, self.yaw, tuple(self._dwells), self.move_s]
        for e, v in zip(self.elements, self.speeds):
            parts.append(v)
            parts.extend(np.round(e.point(0.0), 12).tolist())
            parts.extend(np.round(e.point(e.length), 12).tolist())
            parts.append(round(e.length, 12))
        return tuple(parts)

    def arc_length(self, t):
        """Distance along the path at time t (m)."""
        return self.profile.arc_length(t - self.dwell_s)

    def speed(self, t):
        """Path speed at time t (m/s)."""
        return self.profile.speed(t - self.dwell_s)

    def programmed_speed(self, t):
        """The programmed speed (m/s) of the move the tool is on at time t
        (before the start: the first move's; after the end: the last's;
        along a vertical move, the last horizontal one's): the feed the chip
        thickness follows (the speed ramps between moves are left out: a
        cosine ramp of ramp_s changes it over a few mm)."""
        return self._elem_feeds[self._element(self.arc_length(t))]

    def _element(self, s):
        i = bisect.bisect_right(self._s_knots, s) - 1
        return min(max(i, 0), len(self.elements) - 1)

    def point_at(self, s):
        """Tool point (m) at arc length s."""
        i = self._element(s)
        e = self.elements[i]
        return e.point(min(max(s - self._s_knots[i], 0.0), e.length))

    def tangent_at(self, s):
        i = self._element(s)
        e = self.elements[i]
        return e.tangent(min(max(s - self._s_knots[i], 0.0), e.length))

    def position(self, t):
        return self.point_at(self.arc_length(t))

    def positions(self, ts):
        return np.array([self.position(t) for t in np.atleast_1d(ts)]).reshape(-1, 3)

    def feed_direction(self, t):
        """Horizontal unit feed direction (u_x, u_y) at time t (the
        cutting-force model's u); the first element's before the start, the
        last's after; along a vertical move, the last horizontal one's."""
        if len(self._elem_dirs) == 1:
            return self._elem_dirs[0]
        s = self.arc_length(t)
        i = self._element(s)
        e = self.elements[i]
        if isinstance(e, Line):
            return self._elem_dirs[i]
        tg = e.tangent(min(max(s - self._s_knots[i], 0.0), e.length))
        n = math.hypot(tg[0], tg[1])
        return (tg[0] / n, tg[1] / n) if n > 1e-6 else self._elem_dirs[i]

    def sample_xy(self, spacing_m):
        """(s (N,), points (N, 3), horizontal unit tangents (N, 2)) every
        ``spacing_m`` along the path, leaving out the (near-)vertical parts."""
        s = np.arange(0.0, self.total_length + 1e-12, spacing_m)
        pts = np.array([self.point_at(x) for x in s]).reshape(-1, 3)
        tg = np.array([self.tangent_at(x) for x in s]).reshape(-1, 3)
        n = np.hypot(tg[:, 0], tg[:, 1])
        keep = n > 0.5  # less than 60 degrees from horizontal
        return s[keep], pts[keep], tg[keep, :2] / n[keep, None]

    def tag_at(self, t):
        """Where the path at time t comes from (``tags`` of from_elements), or None."""
        return self.tags[self._element(self.arc_length(t))] if self.tags else None

    def joint_references(self, robot, tool_m, dt_s, q_start=None):
        """(times, q (N, 6) rad) along the path every dt_s, by IK with each
        solution warm-started from the previous one.  Raises PathError when
        a point is out of reach, outside the joint limits or near a
        singularity (its ``where``: the tag of the element, e.g. the
        program's file:line, the first that leaves them)."""
        ts = np.arange(0.0, self.duration_s + 0.5 * dt_s, dt_s)
        qs = np.empty((len(ts), 6))
        q_prev = q_start
        for k, t in enumerate(ts):
            p = self.position(t)
            try:
                q = ik.solve_for(robot, ik.tool_down_pose(p, self.yaw), tool_m, q_ref_rad=q_prev)
            except ik.IKError as e:
                raise PathError(f"path point at t = {t:.3f} s, tool point ({p[0] * 1e3:.1f}, {p[1] * 1e3:.1f}, "
                                f"{p[2] * 1e3:.1f}) mm: {e}", where=self.tag_at(t)) from None
            J = kin.jacobian(robot.dh, q, tool_m)
            s = np.linalg.svd(J, compute_uv=False)
            if s[-1] < MIN_JACOBIAN_CONDITION * s[0]:
                joints = singular_joints(J, rel_tol=MIN_JACOBIAN_CONDITION) or (5,)
                raise PathError(f"path point at t = {t:.3f} s, tool point ({p[0] * 1e3:.1f}, {p[1] * 1e3:.1f}, "
                                f"{p[2] * 1e3:.1f}) mm passes through a singularity ({describe_singularity(joints)})",
                                where=self.tag_at(t))
            qs[k] = q
            q_prev = q
        return ts, qs
