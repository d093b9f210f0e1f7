"""The open dictionary's terms about the loads' history, the force sensor,
the clock and the file's order (identification/diagnosis/dictionary.py holds the
rest).  Plain numpy; no Drake.

  * load_history_jJ      a joint remembers the previous load: the link sits
                          h_prev tau_prev toward the previous load at the same
                          pose (its torque: direction and size), lags h_dir behind
                          on the side its torque came from (sign(tau - tau_prev)),
                          and the pose's unloaded reading sits h_ref tau_before
                          toward the last load before the pose began
                          (measurement order: seq or t_s)
  * drift_periodic        the instrument or cell drifts periodically in time:
                          d(s) - d(s_ref), d = a sin(w s) + b cos(w s) per
                          component, s = t_s or seq, s_ref the pose's unloaded
                          reading (one step before its first load), w from a grid
  * force_crosstalk       the reported force is a 3x3 calibration matrix away
                          from the applied one: F = (I + E) F_reported, E
                          traceless (a common scale is the stiffness's)
  * moment_bias           a constant bias of the reported moment (files with
                          mx,my,mz): an untared sensor's torque channels
  * load_size_compliance  the compliance changes with the load's size
                          (preload): dq = a c tau (|F| - mean |F|) / mean |F|,
                          all joints (one a) and per joint (_jJ)
  * drift_referenced      drift since each pose's unloaded reading: v (s - s_ref)
  * play_jJ               joint J lags behind its torque's history by a play
                          operator's output (half-width r from a grid)
  * order_trend, order_periodic   without seq or t_s: a trend (linear, or
                          periodic) along the file's order (order_trend: the
                          global trend and the part since each pose's reading).  The order of the
                          rows is not known to be the order of measurement, so
                          such a term is reported as an unexplained trend, never
                          as a cause (``Term.trend``)
Every term carries its plausibility check.
"""

import numpy as np

from robstiff_drake.identification.diagnosis import plausibility as pl
from robstiff_drake.identification.diagnosis.terms import BILINEAR, GRID, LINEAR, Term, stack

# periods of 1 to 12 cycles over the campaign's span, a quarter cycle apart: a sinusoid whose period is
# off by more decorrelates over the campaign (the grid must be this fine)
PERIOD_FRACTIONS = tuple(1.0 / np.arange(1.0, 12.01, 0.25))
PLAY_FRACTIONS = (0.05, 0.1, 0.2, 0.3, 0.5)  # a play operator's half-width / the joint's largest torque
MIN_TIMES = 12  # distinct measurement times a periodic drift needs
# The part of a joint's deflection that remembers the previous load, against
# the joint's compliance: friction-held elastic deflection in a reducer is a
# fraction of its torsion (ASSUMPTION: at most half).
HISTORY_SHARE_MAX = 0.5
# Crosstalk of a six-axis load cell: calibrated, 1-2 % of full scale; an
# uncalibrated or damaged one a few %.  Bound: 5 % per matrix entry.
CROSSTALK_MAX = 0.05
# A periodic drift of the instrument or cell (air conditioning cycling): tens
# of micrometres; the bound is that of a displacement offset's, 0.05 mm.
PERIODIC_DRIFT_MAX_M = pl.DISPLACEMENT_OFFSET_MAX_M
LOAD_SIZE_SPREAD_MIN = 0.05  # the loads' sizes must differ by this (relative) to show a size dependence


def _clock(ctx):
    """(times, name) of the measurement order: t_s, else seq, else None."""
    if ctx.t_s is not None:
        return ctx.t_s, "t_s"
    if ctx.seq is not None:
        return ctx.seq, "seq"
    return None, None


def _needs_clock(ctx):
    return None if _clock(ctx)[0] is not None else "the file has neither seq nor t_s (measurement order)"


def _needs_no_clock(ctx):
    return None if _clock(ctx)[0] is None else "the file has seq or t_s (the drift terms use them)"


def _joint_col(ctx, j, values):
    dq = np.zeros_like(ctx.tau)
    dq[:, j] = values
    return ctx.from_dq(dq)


def _history(ctx, j):
    """Per row: joint j's torque of the previous load at the same pose (0 for
    a pose's first) and of the last load before the pose began."""
    s, _ = _clock(ctx)
    order = np.argsort(s, kind="stable")
    prev, before = np.zeros(ctx.n), np.zeros(ctx.n)
    last_pose, last_tau, pose_start = None, 0.0, {}
    for row in order:
        g = ctx.groups[row]
        if g not in pose_start:
            pose_start[g] = last_tau
        prev[row] = last_tau if g == last_pose else 0.0
        before[row] = pose_start[g]
        last_pose, last_tau = g, ctx.tau[row, j]
    return prev, before


def _load_history(j):
    def columns(ctx):
        prev, before = _history(ctx, j)
        came_from = np.sign(ctx.tau[:, j] - prev)  # the direction the joint's torque came from
        return stack([_joint_col(ctx, j, prev), _joint_col(ctx, j, came_from), _joint_col(ctx, j, before)])

    def plausible(v, info):
        if info["c"][j] <= 0:
            return False, f"joint {j + 1}'s compliance is not positive ({pl.NON_PHYSICAL})"
        share = max(abs(v[0]), abs(v[2])) / info["c"][j]
        ok = share <= HISTORY_SHARE_MAX
        if not ok:
            return ok, (f"remembered share {share:.2f} of joint {j + 1}'s compliance (beyond {HISTORY_SHARE_MAX:g})")
        return pl.within([v[1]], pl.LOST_MOTION_MAX_RAD, "lag in the direction the load came from", "urad", 1e6)

    def describe(v, info):
        c = info["c"][j]
        return (f"joint {j + 1} remembers the previous load: {100 * v[0] / c:+.3g} % of its compliance times the "
                f"previous load's torque at the pose, a lag of {v[1] * 1e6:+.3g} urad from the side the torque came "
                f"from, the pose's unloaded reading {100 * v[2] / c:+.3g} % of it times the last load's before the "
                "pose")

    def needs(ctx):
        if _clock(ctx)[0] is None:
            return "the file has neither seq nor t_s (measurement order)"
        return None if np.any(ctx.tau[:, j]) else f"the loads give joint {j + 1} no torque"

    return Term(f"load_history_j{j + 1}", "dictionary", LINEAR,
                [("h_prev", "rad/(N*m)", 1.0), ("h_dir", "urad", 1e6), ("h_ref", "rad/(N*m)", 1.0)],
                columns=columns, describe=describe,
                plausible=plausible, needs=needs)


def _periodic(name, variable, needs, trend=False):
    def span(ctx):
        s = variable(ctx)
        return float(np.ptp(s))

    def grid(ctx):
        return [span(ctx) * f for f in PERIOD_FRACTIONS]

    def columns(ctx, period):
        s = variable(ctx)
        step = float(np.median(np.diff(np.unique(s)))) if len(np.unique(s)) > 1 else 1.0
        first = {}
        for row in np.argsort(s, kind="stable"):
            first.setdefault(ctx.groups[row], s[row])
        s_ref = np.array([first[g] for g in ctx.groups]) - step
        w = 2 * np.pi / period
        cols = []
        for k in range(3):
            for f in (np.sin, np.cos):
                col = np.zeros((ctx.n, 3))
                col[:, k] = f(w * s) - f(w * s_ref)
                cols.append(col)
        return stack(cols)

    def amplitude(v):
        return [np.hypot(v[2 * k], v[2 * k + 1]) for k in range(3)]

    def plausible(v, info):
        return pl.within(amplitude(v), PERIODIC_DRIFT_MAX_M, "periodic drift amplitude", "mm", 1e3)

    def describe(v, info):
        amp = amplitude(v)
        what = "a periodic trend along the file's order (no seq or t_s: not known to be the order of " \
               "measurement)" if trend else "periodic drift"
        return (f"{what}: amplitude x {amp[0] * 1e3:.3g}, y {amp[1] * 1e3:.3g}, z {amp[2] * 1e3:.3g} mm, "
                f"period {info['g']:.4g} ({'rows' if trend else _clock(info['ctx'])[1]})")

    def full_needs(ctx):
        why = needs(ctx)
        if why:
            return why
        return None if len(np.unique(variable(ctx))) >= MIN_TIMES else f"fewer than {MIN_TIMES} measurement times"

    params = [(f"{f}_{a}", "mm", 1e3) for a in "xyz" for f in ("a", "b")]
    return Term(name, "dictionary", GRID, params, columns=columns, grid=grid, grid_param=("period", "", 1.0),
                describe=describe, plausible=plausible, needs=full_needs, trend=trend)


_TRACELESS = [np.outer(np.eye(3)[a], np.eye(3)[b]) for a in range(3) for b in range(3) if a != b] + \
    [np.diag([1.0, -1.0, 0.0]), np.diag([0.0, 1.0, -1.0])]


def _crosstalk_columns(ctx, c):
    cols = []
    for E in _TRACELESS:
        extra = np.zeros_like(ctx.W)
        extra[:, :3] = ctx.W[:, :3] @ E.T
        cols.append(ctx.disp_of_wrench(extra, c))
    return stack(cols)


def _crosstalk_matrix(v):
    return sum(x * E for x, E in zip(v, _TRACELESS))


def _moment_bias(ctx, c):
    cols = []
    for k in range(3):
        extra = np.zeros_like(ctx.W)
        extra[:, 3 + k] = 1.0
        cols.append(ctx.disp_of_wrench(extra, c))
    return stack(cols)


def _needs_moments(ctx):
    return None if ctx.campaign.has_moments else "the file reports no moment (no mx,my,mz columns): its loads are forces"


def _load_size(ctx):
    mag = np.linalg.norm(ctx.W[:, :3], axis=1)
    return (mag - mag.mean()) / max(mag.mean(), 1e-12)


def _needs_sizes(ctx):
    mag = np.linalg.norm(ctx.W[:, :3], axis=1)
    spread = np.ptp(mag) / max(mag.mean(), 1e-12)
    return None if spread >= LOAD_SIZE_SPREAD_MIN else (f"the loads' sizes differ by {100 * spread:.2g} % only "
                                                         "(a size dependence needs different sizes)")


def _load_size_term(j=None):
    joints = list(range(6)) if j is None else [j]

    def columns(ctx, c):
        dq = np.zeros_like(ctx.tau)
        dq[:, joints] = (c * ctx.tau)[:, joints] * _load_size(ctx)[:, None]
        return stack([ctx.from_dq(dq)])

    def plausible(v, info):
        ctx, c = info["ctx"], info["c"]
        bad, why = [], []
        for jj in joints:
            if not np.any(ctx.tau[:, jj]):
                continue
            ok, w = pl.compliance_ratio(c[jj], v[0] * c[jj] * _load_size(ctx))
            (why if ok else bad).append(f"joint {jj + 1}: {w}")
        return (not bad), "; ".join(bad or why[:1])

    def describe(v, info):
        mag = np.linalg.norm(info["ctx"].W[:, :3], axis=1)
        who = "the joints' compliance" if j is None else f"joint {j + 1}'s compliance"
        return (f"{who} changes with the load's size: {100 * v[0]:+.3g} % per mean load "
                f"({mag.min():.0f}-{mag.max():.0f} N)")

    def needs(ctx):
        if j is not None and not np.any(ctx.tau[:, j]):
            return f"the loads give joint {j + 1} no torque"
        return _needs_sizes(ctx)

    name = "load_size_compliance" + ("" if j is None else f"_j{j + 1}")
    return Term(name, "dictionary", BILINEAR, [("a", "x compliance per mean load", 1.0)], columns=columns,
                describe=describe, plausible=plausible, needs=needs)


def _order(ctx):
    return (np.arange(ctx.n) - (ctx.n - 1) / 2.0) / 1000.0


def _since_reference(ctx, s):
    """Per row: s minus its pose's unloaded reading's (one step before the pose's first row, in order of s)."""
    step = float(np.median(np.diff(np.unique(s)))) if len(np.unique(s)) > 1 else 1.0
    first = {}
    for row in np.argsort(s, kind="stable"):
        first.setdefault(ctx.groups[row], s[row])
    return s - (np.array([first[g] for g in ctx.groups]) - step)


def _order_trend(ctx):
    """A drift along the file's order: the global trend, and the part since each pose's
    unloaded reading (what loaded-minus-unloaded displacements keep of a drift)."""
    within = _since_reference(ctx, np.arange(ctx.n, dtype=float)) / 1000.0
    return stack([np.outer(x, np.eye(3)[k]) for x in (_order(ctx), within) for k in range(3)])


def _drift_referenced(ctx):
    s, _ = _clock(ctx)
    return stack([np.outer(_since_reference(ctx, s), np.eye(3)[k]) for k in range(3)])


def _play(j):
    """A play operator on joint j's torque history (measurement order): the
    link lags up to h behind the torque, z = clip(z_prev, tau - r, tau + r),
    lag (z - tau) / r; the pose's unloaded reading at tau = 0 moves it too."""
    def grid(ctx):
        tm = float(np.max(np.abs(ctx.tau[:, j])))
        return [f * tm for f in PLAY_FRACTIONS]

    def lag(ctx, r):
        s, _ = _clock(ctx)
        out = np.zeros(ctx.n)
        z, ref, seen = 0.0, {}, set()
        for row in np.argsort(s, kind="stable"):
            g = ctx.groups[row]
            if g not in seen:
                seen.add(g)
                z = min(max(z, -r), r)
                ref[g] = z / r
            tau = ctx.tau[row, j]
            z = min(max(z, tau - r), tau + r)
            out[row] = (z - tau) / r - ref[g]
        return out

    def columns(ctx, r):
        return stack([_joint_col(ctx, j, lag(ctx, r))])

    def needs(ctx):
        if _clock(ctx)[0] is None:
            return "the file has neither seq nor t_s (measurement order)"
        return None if np.any(ctx.tau[:, j]) else f"the loads give joint {j + 1} no torque"

    return Term(f"play_j{j + 1}", "dictionary", GRID, [("h", "urad", 1e6)], columns=columns, grid=grid,
                grid_param=("r", "N*m", 1.0),
                describe=lambda v, info: (f"joint {j + 1} lags behind its torque's history (a play operator): "
                                          f"{v[0] * 1e6:+.3g} urad over a play of +-{info['g']:.3g} N*m"),
                plausible=lambda v, info: pl.within(v, pl.LOST_MOTION_MAX_RAD, "lag", "urad", 1e6), needs=needs)


def terms():
    out = [_load_history(j) for j in range(6)] + [_play(j) for j in range(6)]
    out.append(Term("drift_referenced", "dictionary", LINEAR, [(f"v_{a}", "um per step", 1e6) for a in "xyz"],
                    columns=_drift_referenced,
                    describe=lambda v, info: "drift since each pose's unloaded reading: " + ", ".join(
                        f"{a} {x * 1e6:.3g}" for a, x in zip("xyz", v)) + " um per step of the clock",
                    plausible=lambda v, info: pl.within([np.linalg.norm(v)], pl.DRIFT_MAX_M_PER_MEASUREMENT,
                                                        "drift", "um per step", 1e6),
                    needs=_needs_clock))
    out += [_periodic("drift_periodic", lambda ctx: _clock(ctx)[0], _needs_clock),
            Term("force_crosstalk", "dictionary", BILINEAR, [(f"e{i}", "-", 1.0) for i in range(8)],
                 columns=_crosstalk_columns,
                 describe=lambda v, info: "the force sensor's calibration matrix is off (crosstalk): largest entry "
                                          f"{100 * np.max(np.abs(_crosstalk_matrix(v))):.3g} %",
                 plausible=lambda v, info: pl.within([np.max(np.abs(_crosstalk_matrix(v)))], CROSSTALK_MAX,
                                                     "crosstalk", "%", 100.0)),
            Term("moment_bias", "dictionary", BILINEAR, [(f"b_m{a}", "N*m", 1.0) for a in "xyz"],
                 columns=_moment_bias, needs=_needs_moments,
                 describe=lambda v, info: "constant bias of the reported moment: " + ", ".join(
                     f"m{a} {x:.3g}" for a, x in zip("xyz", v)) + " N*m",
                 plausible=lambda v, info: pl.within([np.linalg.norm(v)], pl.MOMENT_BIAS_MAX_NM, "moment bias",
                                                     "N*m", 1.0)),
            _load_size_term()]
    out += [_load_size_term(j) for j in range(6)]
    out += [Term("order_trend", "dictionary", LINEAR, [(f"{w}_{a}", "mm per 1000 rows", 1e3) for w in
                                                       ("v", "v_since_reference") for a in "xyz"],
                 columns=_order_trend, trend=True,
                 describe=lambda v, info: "a trend along the file's order (no seq or t_s: not known to be the order "
                                          "of measurement): " + ", ".join(f"{a} {x * 1e3:.3g}" for a, x in
                                                                          zip("xyz", v[:3])) + " mm per 1000 rows, "
                                          "since each pose's unloaded reading " + ", ".join(
                                              f"{a} {x * 1e3:.3g}" for a, x in zip("xyz", v[3:])),
                 plausible=lambda v, info: pl.within([np.linalg.norm(v[:3]) * np.ptp(_order(info["ctx"])),
                                                      np.linalg.norm(v[3:]) * 1e-3 / pl.DRIFT_MAX_M_PER_MEASUREMENT
                                                      * pl.DRIFT_TOTAL_MAX_M],
                                                     pl.DRIFT_TOTAL_MAX_M, "trend", "mm", 1e3),
                 needs=_needs_no_clock),
            _periodic("order_periodic", _order, _needs_no_clock, trend=True)]
    return out
