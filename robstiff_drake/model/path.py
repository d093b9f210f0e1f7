"""The planned tool path: lines and arcs (waypoints or a G-code program),
corners blended within a zone as a robot controller does, a smooth speed
profile, the spindle axis straight down, and the joint references that IK
gives along it.  Plain numpy; no Drake.

The elements and their corners: model/path_elements.py; the speed
profile: model/speed_profile.py.
"""

import bisect
import math

import numpy as np

from robstiff_drake.model import ik
from robstiff_drake.model import kinematics as kin
from robstiff_drake.model.path_elements import Line, blend_corners, split_for_speeds
from robstiff_drake.model.speed_profile import SpeedProfile
from robstiff_drake.model.stiffness import describe_singularity, singular_joints

# Closest a path may come to a singularity: smallest over largest singular
# value of the Jacobian (a pose this close would need huge joint rates).
MIN_JACOBIAN_CONDITION = 1e-3


class PathError(ValueError):
    """The path cannot be followed (reach, joint limits, singularity);
    ``where``: the tag of the path's element concerned (a program's
    "file:line"), or None."""

    def __init__(self, message, where=None):
        super().__init__(message)
        self.where = where


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

    def feed_direction_at(self, s):
        """``feed_direction`` at arc length s (m) instead of a time."""
        i = self._element(s)
        e = self.elements[i]
        if isinstance(e, Line) or len(self._elem_dirs) == 1:
            return self._elem_dirs[i]
        tg = e.tangent(min(max(s - self._s_knots[i], 0.0), e.length))
        n = math.hypot(tg[0], tg[1])
        return (tg[0] / n, tg[1] / n) if n > 1e-6 else self._elem_dirs[i]

    def nearest_s(self, p_m, spacing_m=0.001):
        """``project`` from the nearest of the path's points every
        ``spacing_m`` (a search of the whole path: for a first guess)."""
        s = np.arange(0.0, self.total_length + spacing_m, spacing_m)
        s[-1] = min(s[-1], self.total_length)
        pts = np.array([self.point_at(x) for x in s])
        d = np.linalg.norm(pts - np.asarray(p_m, dtype=float)[None, :], axis=1)
        return self.project(p_m, float(s[int(np.argmin(d))]))

    def project(self, p_m, s_guess_m, max_step_m=0.005, iterations=4):
        """The arc length (m) of the path's point nearest the point p (m)
        near ``s_guess_m``: Newton steps s += (p - P(s)) . T(s), each at
        most ``max_step_m`` (the plant's cutting force: where along its
        path the tool really is)."""
        s = min(max(float(s_guess_m), 0.0), self.total_length)
        px, py, pz = float(p_m[0]), float(p_m[1]), float(p_m[2])
        for _ in range(iterations):
            i = self._element(s)
            e = self.elements[i]
            if type(e) is Line:  # (point_at and tangent_at in floats: the same arithmetic)
                ls = min(max(s - self._s_knots[i], 0.0), e.length)
                (x0, y0, z0), T = e.p0_xyz, e.u_xyz
                P = (x0 + T[0] * ls, y0 + T[1] * ls, z0 + T[2] * ls)
            else:
                P, T = self.point_at(s), self.tangent_at(s)
            step = (px - P[0]) * T[0] + (py - P[1]) * T[1] + (pz - P[2]) * T[2]
            step = min(max(step, -max_step_m), max_step_m)
            s = min(max(s + step, 0.0), self.total_length)
            if abs(step) < 1e-9:
                break
        return s

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
