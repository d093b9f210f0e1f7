"""What may be sent to a robot controller: the one check every protocol's
send path goes through (``PCLink.send_targets``, cell/link.py), and the
checks of a joint reference and of a hold pose before the loop.

Every angle here is the controller's (degrees, as the pendant shows them),
the convention of the wire and of the robot file's working ranges.

A target (six joint angles, deg) may be sent only when

* every angle is finite and inside the robot file's working range
  (``joint_limits.lower_deg``/``upper_deg``);
* it is within ``reference_tol_deg`` of where the arm should be (the
  reference at this moment): the correction's clamp (its saturation,
  mapped to the controller's joints) plus the reference's motion over one
  controller period;
* it is within ``measured_tol_deg`` of where the arm is (the controller's
  joint feedback): the same, plus the reference's motion over the time the
  servo takes to follow a target (``FOLLOW_S``);
* (when the envelope gives the axis limits) it is within one period's axis
  speed (``step_tol_deg``) of the pose the controller commands now, and
  its step changes by at most ``accel_tol_deg`` from the last one (the
  controller's motion supervision, ``SUPERVISION_ACCEL``).

The target checked is the pose the controller will command: the link
decodes its own answer as the controller reads it (for RSI its start plus
the axis corrections AK, after any restart; cell/link.PCLink.send_targets).

``unsafe_reason`` says which rule a target breaks (None: it may be sent).
No protocol encodes a target without it: a protocol class only turns
targets that passed into bytes.
"""

import math
from dataclasses import dataclass

import numpy as np

from robstiff_drake.errors import InputError

# How long the robot's servo takes to follow a target (s): the arm's
# feedback lags the targets by the reference's motion over this time.
# ASSUMPTION: an IRC5-like controller's interpolator dead time (12-18 ms,
# docs/run_files.md), its position loop's lag 1/Kp (17 ms at 60 1/s) and
# the network's cycle or two (8 ms), about 45 ms, doubled for margin.
FOLLOW_S = 0.1
# Rounding of the angles on the wire (deg): a target that equals a limit
# or a bound up to this is taken.
WIRE_EPS_DEG = 1e-6
# The smallest time step of a reference (s) that is taken as the
# controller period: rows written with a few digits (0.004 as 0.0039999)
# are not refused for that.
TIME_EPS_S = 1e-6
# ASSUMPTION: a controller's motion supervision lets a streamed target
# change its step (a held cycle, then two steps) up to this many times the
# robot file's acceleration limit (a lost datagram at machining feeds is
# within it) and stops the robot beyond (a hold of tens of ms, then a jump:
# a jerk no servo should follow).  The simulated controller
# (cell/sim_cell.py) stops at the same bound.
SUPERVISION_ACCEL = 10.0


class UnsafeTarget(Exception):
    """A target that ``unsafe_reason`` refused; the message says why."""


@dataclass(frozen=True)
class Envelope:
    """Where a target may lie this cycle (deg, 6 each)."""

    lower_deg: tuple
    upper_deg: tuple
    reference_deg: tuple
    reference_tol_deg: tuple
    measured_deg: tuple
    measured_tol_deg: tuple
    # the controller's motion supervision (None: not checked): the largest step
    # from the pose it commands now in one period (deg, its axis speeds times the
    # period), and the largest change of that step (deg, SUPERVISION_ACCEL times
    # its acceleration limits times the period squared)
    step_tol_deg: tuple = None
    accel_tol_deg: tuple = None


def supervision_tolerances(robot, period_s):
    """(step_tol_deg, accel_tol_deg) of an Envelope for ``robot``'s axis
    speeds and accelerations at ``period_s`` (None, None without them)."""
    v, a = robot.speed_limit_deg_per_s, robot.acceleration_limit_deg_per_s2
    step = None if v is None else tuple((np.asarray(v, dtype=float) * period_s).tolist())
    acc = None if a is None else tuple((SUPERVISION_ACCEL * np.asarray(a, dtype=float) * period_s**2).tolist())
    return step, acc


def motion_reason(target_deg, env, previous_deg):
    """None when ``target_deg`` after ``previous_deg`` (the poses the
    controller commanded, newest last; deg) keeps within the envelope's
    step and acceleration tolerances; else why not."""
    if not previous_deg or env.step_tol_deg is None:
        return None
    p1 = previous_deg[-1]
    for j in range(6):
        d = abs(target_deg[j] - p1[j])
        if not d <= env.step_tol_deg[j] + WIRE_EPS_DEG:
            return (f"q{j + 1} target {target_deg[j]:.4f} deg is {d:.4f} deg from the pose the controller commands "
                    f"now ({p1[j]:.4f}); one period at the axis speed allows {env.step_tol_deg[j]:.4f}")
    if env.accel_tol_deg is None or len(previous_deg) < 2:
        return None
    p2 = previous_deg[-2]
    for j in range(6):
        a = abs(target_deg[j] - 2.0 * p1[j] + p2[j])
        if not a <= env.accel_tol_deg[j] + WIRE_EPS_DEG:
            return (f"q{j + 1} target {target_deg[j]:.4f} deg changes the controller's step by {a:.4f} deg in one "
                    f"period; its acceleration supervision allows {env.accel_tol_deg[j]:.4f}")
    return None


def unsafe_reason(target_deg, env):
    """None when ``target_deg`` (6 floats, controller degrees) may be sent
    within ``env``; else one line saying which joint breaks which rule."""
    if len(target_deg) != 6:
        return f"{len(target_deg)} joint targets, expected 6"
    for j in range(6):
        x = target_deg[j]
        if not math.isfinite(x):
            return f"q{j + 1} target {x} is not finite"
        if not env.lower_deg[j] - WIRE_EPS_DEG <= x <= env.upper_deg[j] + WIRE_EPS_DEG:
            return (f"q{j + 1} target {x:.4f} deg is outside the working range [{env.lower_deg[j]:g}, "
                    f"{env.upper_deg[j]:g}] deg")
        d = abs(x - env.reference_deg[j])
        if not d <= env.reference_tol_deg[j] + WIRE_EPS_DEG:
            return (f"q{j + 1} target {x:.4f} deg is {d:.4f} deg from the reference {env.reference_deg[j]:.4f} "
                    f"(at most {env.reference_tol_deg[j]:.4f})")
        d = abs(x - env.measured_deg[j])
        if not d <= env.measured_tol_deg[j] + WIRE_EPS_DEG:
            return (f"q{j + 1} target {x:.4f} deg is {d:.4f} deg from the arm's feedback "
                    f"{env.measured_deg[j]:.4f} (at most {env.measured_tol_deg[j]:.4f})")
    return None


def clamp_deg(robot, saturation_deg):
    """The largest correction per controller joint (deg) when each model
    joint's is ``saturation_deg``: |G^-1| times the clamp (a coupled joint,
    FANUC's J3, moves by the sum of two)."""
    Ginv = np.abs(np.linalg.inv(robot.joint_map.G))
    return Ginv @ np.broadcast_to(np.asarray(saturation_deg, dtype=float), 6)


def pose_problem(robot, q_deg):
    """None when ``q_deg`` (controller degrees) is six finite angles inside
    the working ranges; else what is wrong, naming the joint."""
    lo, hi = np.degrees(robot.q_lower_rad), np.degrees(robot.q_upper_rad)
    for j, v in enumerate(q_deg):
        if not math.isfinite(v):
            return f"q{j + 1} = {v} is not finite"
        if not lo[j] <= v <= hi[j]:
            return f"q{j + 1} = {v:g} deg is outside {robot.name}'s working range [{lo[j]:g}, {hi[j]:g}] deg"
    return None


def check_reference(where, robot, t_s, q_deg, period_s, rows=None):
    """Refuse (InputError naming the file and line) a joint reference whose
    times are not strictly increasing at ``period_s`` or coarser, whose
    angles leave the working ranges, or that asks more speed or
    acceleration of a joint than the robot file's limits.  ``rows``: the
    file's line number of each row."""
    t = np.asarray(t_s, dtype=float)
    q = np.asarray(q_deg, dtype=float)
    line = (lambda i: f"{where}:{rows[i]}") if rows is not None else (lambda i: f"{where}: row {i + 1}")
    dt = np.diff(t)
    bad = np.flatnonzero(dt < period_s - TIME_EPS_S)
    if bad.size:
        i = int(bad[0]) + 1
        raise InputError(f"{line(i)}: t_s {t[i]:.9g} is {dt[i - 1]:.3g} s after the previous row; rows must be at "
                         f"least the controller period ({period_s:g} s) apart")
    for i, row in enumerate(q):
        p = pose_problem(robot, row)
        if p:
            raise InputError(f"{line(i)}: {p}")
    if robot.speed_limit_deg_per_s is None or robot.acceleration_limit_deg_per_s2 is None:
        raise InputError(f"{robot.source}: key 'joint_limits.speed_deg_per_s' and 'acceleration_deg_per_s2': "
                         "missing; compensate checks the reference's joint speeds and accelerations against them "
                         "(the maker's data-sheet axis speeds; see models/*.yaml)")
    if len(t) < 2:
        return
    v = np.diff(q, axis=0) / dt[:, None]
    over = np.abs(v) > robot.speed_limit_deg_per_s
    if over.any():
        i, j = (int(x) for x in np.argwhere(over)[0])
        raise InputError(f"{line(i + 1)}: q{j + 1} moves at {abs(v[i, j]):.4g} deg/s from the previous row; "
                         f"{robot.name}'s axis speed is {robot.speed_limit_deg_per_s[j]:g} deg/s (joint_limits."
                         "speed_deg_per_s)")
    if len(t) < 3:
        return
    a = np.diff(v, axis=0) / (0.5 * (dt[1:] + dt[:-1]))[:, None]
    over = np.abs(a) > robot.acceleration_limit_deg_per_s2
    if over.any():
        i, j = (int(x) for x in np.argwhere(over)[0])
        raise InputError(f"{line(i + 1)}: q{j + 1} accelerates at {abs(a[i, j]):.4g} deg/s^2; {robot.name}'s limit "
                         f"is {robot.acceleration_limit_deg_per_s2[j]:g} deg/s^2 (joint_limits."
                         "acceleration_deg_per_s2)")


def motion_within(t_s, q_deg, window_s):
    """Per row, per joint: the largest change of the reference (deg) over
    the ``window_s`` before that row's time (inclusive), (N, 6)."""
    t = np.asarray(t_s, dtype=float)
    q = np.asarray(q_deg, dtype=float).reshape(len(t), -1)
    out = np.zeros_like(q)
    lo = 0
    for i in range(len(t)):
        while t[i] - t[lo] > window_s + 1e-12:
            lo += 1
        seg = q[max(lo - 1, 0): i + 1]  # (the row before the window: the reference moves between rows)
        out[i] = seg.max(axis=0) - seg.min(axis=0)
    return out
