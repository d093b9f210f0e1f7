"""The planned tool path: straight segments between waypoints at a constant
feed, the spindle axis straight down, and the joint references that IK
gives along it.  Plain numpy; no Drake."""

import bisect
import math

import numpy as np

from robstiff_drake.model import ik
from robstiff_drake.model import kinematics as kin
from robstiff_drake.model.stiffness import describe_singularity, singular_joints

# Closest a path may come to a singularity: smallest over largest singular
# value of the Jacobian (a pose this close would need huge joint rates).
MIN_JACOBIAN_CONDITION = 1e-3


class PathError(ValueError):
    """The path cannot be followed (reach, joint limits, singularity)."""


class PlannedPath:
    """Tool point (m, base frame) along waypoints at ``feed_m_per_s``.

    The motion starts after ``dwell_s`` at rest and speeds up (and, at the
    end, slows down) with a cosine velocity ramp of ``ramp_s``: a step in the
    commanded velocity would ring the arm's first mode, which no real path
    planner does.  The feed is constant between the ramps."""

    def __init__(self, waypoints_m, feed_m_per_s, yaw_rad=0.0, dwell_s=0.0, ramp_s=0.0):
        self.waypoints = np.asarray(waypoints_m, dtype=float).reshape(-1, 3)
        if len(self.waypoints) < 2:
            raise PathError("a path needs at least two waypoints")
        if not feed_m_per_s > 0:
            raise PathError(f"feed must be > 0, got {feed_m_per_s}")
        seg = np.diff(self.waypoints, axis=0)
        self.lengths = np.linalg.norm(seg, axis=1)
        if np.any(self.lengths <= 0):
            raise PathError("two consecutive waypoints are the same point")
        self.directions = seg / self.lengths[:, None]
        self.feed = float(feed_m_per_s)
        self.yaw = float(yaw_rad)
        self.dwell_s = float(dwell_s)
        self.total_length = float(self.lengths.sum())
        self.ramp_s = min(float(ramp_s), self.total_length / self.feed)  # a short path has no cruise phase
        self._s_knots = np.r_[0.0, np.cumsum(self.lengths)].tolist()
        d = self.directions[:, :2]
        n = np.linalg.norm(d, axis=1, keepdims=True)
        dirs = np.where(n > 1e-12, d / np.where(n > 1e-12, n, 1.0), [1.0, 0.0])
        self._feed_dirs = [tuple(u) for u in dirs.tolist()]
        self.move_s = self.total_length / self.feed + self.ramp_s

    @property
    def duration_s(self):
        return self.dwell_s + self.move_s

    def _ramp_distance(self, tau):
        """Distance covered tau seconds into a cosine speed-up from rest."""
        tr = self.ramp_s
        return 0.5 * self.feed * (tau - tr / math.pi * math.sin(math.pi * tau / tr))

    def arc_length(self, t):
        """Distance along the path at time t (m)."""
        tau = min(max(t - self.dwell_s, 0.0), self.move_s)
        tr = self.ramp_s
        if tr <= 0:
            return self.feed * tau
        if tau < tr:
            return self._ramp_distance(tau)
        if tau <= self.move_s - tr:
            return 0.5 * self.feed * tr + self.feed * (tau - tr)
        return self.total_length - self._ramp_distance(self.move_s - tau)

    def _segment(self, s):
        i = bisect.bisect_right(self._s_knots, s) - 1
        return min(max(i, 0), len(self.lengths) - 1)

    def position(self, t):
        s = self.arc_length(t)
        i = self._segment(s)
        return self.waypoints[i] + self.directions[i] * (s - self._s_knots[i])

    def positions(self, ts):
        return np.array([self.position(t) for t in np.atleast_1d(ts)])

    def feed_direction(self, t):
        """Horizontal unit feed direction (u_x, u_y) at time t (the
        cutting-force model's u); the first segment's before the start, the
        last's after."""
        if len(self._feed_dirs) == 1:
            return self._feed_dirs[0]
        return self._feed_dirs[self._segment(self.arc_length(t))]

    def joint_references(self, robot, tool_m, dt_s, q_start=None):
        """(times, q (N, 6) rad) along the path every dt_s, by IK with each
        solution warm-started from the previous one.  Raises PathError when
        a point is out of reach, outside the joint limits or near a
        singularity."""
        ts = np.arange(0.0, self.duration_s + 0.5 * dt_s, dt_s)
        qs = np.empty((len(ts), 6))
        q_prev = q_start
        for k, t in enumerate(ts):
            p = self.position(t)
            try:
                q = ik.solve_for(robot, ik.tool_down_pose(p, self.yaw), tool_m, q_ref_rad=q_prev)
            except ik.IKError as e:
                raise PathError(f"path point at t = {t:.3f} s, tool point ({p[0] * 1e3:.1f}, {p[1] * 1e3:.1f}, "
                                f"{p[2] * 1e3:.1f}) mm: {e}") from None
            J = kin.jacobian(robot.dh, q, tool_m)
            s = np.linalg.svd(J, compute_uv=False)
            if s[-1] < MIN_JACOBIAN_CONDITION * s[0]:
                joints = singular_joints(J, rel_tol=MIN_JACOBIAN_CONDITION) or (5,)
                raise PathError(f"path point at t = {t:.3f} s, tool point ({p[0] * 1e3:.1f}, {p[1] * 1e3:.1f}, "
                                f"{p[2] * 1e3:.1f}) mm passes through a singularity ({describe_singularity(joints)})")
            qs[k] = q
            q_prev = q
        return ts, qs
