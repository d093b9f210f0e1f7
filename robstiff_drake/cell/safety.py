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


def pose_limits_deg(robot):
    """(lower, upper, robot name): the working ranges in the controller's
    degrees as tuples of floats, for ``pose_problem_within`` (computed once,
    not per message)."""
    return (tuple(np.degrees(robot.q_lower_rad).tolist()), tuple(np.degrees(robot.q_upper_rad).tolist()),
            robot.name)


def pose_problem_within(limits, q_deg):
    """``pose_problem`` against precomputed ``limits`` (``pose_limits_deg``):
    scalar comparisons only, the text made only for a pose that fails."""
    lo, hi, name = limits
    if len(q_deg) == 6 and all(a <= v <= b for a, v, b in zip(lo, q_deg, hi)):  # (False for NaN)
        return None
    for j, v in enumerate(q_deg):
        if not math.isfinite(v):
            return f"q{j + 1} = {v} is not finite"
        if not lo[j] <= v <= hi[j]:
            return f"q{j + 1} = {v:g} deg is outside {name}'s working range [{lo[j]:g}, {hi[j]:g}] deg"
    return None


def pose_problem(robot, q_deg):
    """None when ``q_deg`` (controller degrees) is six finite angles inside
    the working ranges; else what is wrong, naming the joint."""
    return pose_problem_within(pose_limits_deg(robot), q_deg)


CHECK_BLOCK = 1 << 16  # rows checked at a time (a long reference's temporaries stay a few MB)


def _first(n, test, overlap=0):
    """The first (row, column) where ``test(lo, hi)`` (a boolean array over
    rows lo..hi-1, (rows,) or (rows, joints)) holds, in blocks of
    CHECK_BLOCK rows; None when it never does."""
    for lo in range(0, max(n - overlap, 0), CHECK_BLOCK):
        bad = np.argwhere(test(lo, min(lo + CHECK_BLOCK, n - overlap)))
        if len(bad):
            return (lo + int(bad[0][0]),) + tuple(int(x) for x in bad[0][1:])
    return None


def check_reference(where, robot, t_s, q_deg, period_s, rows=None, finer_fix=None):
    """Refuse (InputError naming the file and line) a joint reference whose
    times are not strictly increasing at ``period_s`` or coarser, whose
    angles leave the working ranges, or that asks more speed or
    acceleration of a joint than the robot file's limits.  ``rows``: the
    file's line number of each row; ``finer_fix``: what to set when the rows
    are finer than ``period_s`` ({period_ms}: it, in ms; default: a
    --reference file's).  Each test over all rows in turn, in
    blocks (a million-row reference)."""
    t = np.asarray(t_s, dtype=float)
    q = np.asarray(q_deg, dtype=float)
    n = len(t)
    line = (lambda i: f"{where}:{rows[i]}") if rows is not None else (lambda i: f"{where}: row {i + 1}")
    bad = _first(n, lambda a, b: t[a + 1:b + 1] - t[a:b] < period_s - TIME_EPS_S, overlap=1)
    if bad:
        i = bad[0] + 1
        step_ms, period_ms = 1e3 * (t[i] - t[i - 1]), 1e3 * period_s
        if not step_ms > 0:
            raise InputError(f"{line(i)}: t_s {t[i]:.9g} is not after the previous row's {t[i - 1]:.9g}; times must "
                             f"increase, by at least the controller period (--period-ms {period_ms:g}) a row")
        fix = finer_fix or ("write the reference at the controller's cycle (sim-cell and simulate write it at the "
                            "scenario's controller.period_ms: set it to {period_ms})")
        raise InputError(f"{line(i)}: t_s {t[i]:.9g} is {step_ms:.3g} ms after the previous row, finer than "
                         f"--period-ms {period_ms:g} (the controller period); rows must be at least {period_ms:g} ms "
                         f"apart: {fix.format(period_ms=f'{period_ms:g}')}, or, if the controller's cycle is "
                         f"{step_ms:.3g} ms, run with --period-ms {step_ms:.3g}")
    lo, hi = np.degrees(robot.q_lower_rad), np.degrees(robot.q_upper_rad)
    bad = _first(n, lambda a, b: ~((q[a:b] >= lo) & (q[a:b] <= hi)).all(axis=1))  # (NaN too)
    if bad:
        raise InputError(f"{line(bad[0])}: {pose_problem(robot, q[bad[0]])}")
    if robot.speed_limit_deg_per_s is None or robot.acceleration_limit_deg_per_s2 is None:
        raise InputError(f"{robot.source}: key 'joint_limits.speed_deg_per_s' and 'acceleration_deg_per_s2': "
                         "missing; compensate checks the reference's joint speeds and accelerations against them "
                         "(the maker's data-sheet axis speeds; see models/*.yaml)")

    def speed(a, b):  # rows a..b-1 to the next, (deg/s)
        return (q[a + 1:b + 1] - q[a:b]) / (t[a + 1:b + 1] - t[a:b])[:, None]

    bad = _first(n, lambda a, b: np.abs(speed(a, b)) > robot.speed_limit_deg_per_s, overlap=1)
    if bad:
        i, j = bad
        v = speed(i, i + 1)[0, j]
        raise InputError(f"{line(i + 1)}: q{j + 1} moves at {abs(v):.4g} deg/s from the previous row; "
                         f"{robot.name}'s axis speed is {robot.speed_limit_deg_per_s[j]:g} deg/s (joint_limits."
                         "speed_deg_per_s)")

    def acceleration(a, b):  # at rows a+1..b (deg/s^2)
        v = speed(a, b + 1)
        return np.diff(v, axis=0) / (0.5 * ((t[a + 2:b + 2] - t[a + 1:b + 1]) + (t[a + 1:b + 1] - t[a:b])))[:, None]

    bad = _first(n, lambda a, b: np.abs(acceleration(a, b)) > robot.acceleration_limit_deg_per_s2, overlap=2)
    if bad:
        i, j = bad
        acc = acceleration(i, i + 1)[0, j]
        raise InputError(f"{line(i + 1)}: q{j + 1} accelerates at {abs(acc):.4g} deg/s^2; {robot.name}'s limit "
                         f"is {robot.acceleration_limit_deg_per_s2[j]:g} deg/s^2 (joint_limits."
                         "acceleration_deg_per_s2)")


def motion_within(t_s, q_deg, window_s, out=None):
    """Per row, per joint: the largest change of the reference (deg) over
    the ``window_s`` before that row's time (inclusive), (N, 6) (into
    ``out`` when given).  Vectorised over the rows, a joint at a time:
    N log2(the rows in the longest window) steps."""
    t = np.asarray(t_s, dtype=float)
    q = np.asarray(q_deg, dtype=float).reshape(len(t), -1)
    n = len(t)
    out = np.empty_like(q) if out is None else out
    if n == 0:
        return out
    # the first row of each row's window: the first j with t[i] - t[j] <= window_s (times increase), then the
    # row before it (the reference moves between rows)
    w = window_s + 1e-12
    lo = np.searchsorted(t, t - w, side="left")
    idx = np.arange(n)
    lo = np.minimum(lo, idx)
    while True:  # (searchsorted's rounding against the difference's: the exact test, a step either way)
        up = (lo < idx) & (t - t[lo] > w)
        down = (lo > 0) & (t - t[np.maximum(lo - 1, 0)] <= w)
        if not up.any() and not down.any():
            break
        lo = lo + up - down
    size = idx - np.maximum(lo - 1, 0) + 1  # rows in each row's window
    del lo, idx, up, down
    level = np.floor(np.log2(size)).astype(int)
    groups = [(p, np.flatnonzero(level == p)) for p in range(int(level.max()) + 1)]
    groups = [(p, rows, rows - size[rows] + (1 << p)) for p, rows in groups if rows.size]
    del level, size
    # a sparse table: at level p, hi[j] and low[j] are the max and min of the 2**p rows up to j; a window of
    # 2**p <= size < 2**(p + 1) rows is the union of two such spans, one ending at its row, one starting at its first
    for j in range(q.shape[1]):
        hi, low = q[:, j].copy(), q[:, j].copy()
        for p in range(groups[-1][0] + 1):
            if p:
                s = 1 << (p - 1)
                hi[s:] = np.maximum(hi[s:], hi[:-s])
                low[s:] = np.minimum(low[s:], low[:-s])
            for level_p, rows, other in groups:
                if level_p == p:
                    out[rows, j] = np.maximum(hi[rows], hi[other]) - np.minimum(low[rows], low[other])
    return out
