"""The feed planner: where the compensated cut is predicted to leave more
than ``path.tolerance_mm``, lower the feed there (model/feed_plan.py's
arithmetic), and say which program lines, why and at what feed.

The prediction is the user's own: a dry run of the program on the
compensator's model of the cell (its digital twin: the identified
stiffness, its own damping assumption, the identified servo, the
calibrated sensor bias, its force model), once with the cutting
coefficients at each end of their stated uncertainty (model.identification.
coefficient_error: the twin's "true" coefficients are the model's times
1 -+ that), the compensator in the scenario's mode.  The twin knows nothing
of the plant that the compensator does not: the planner is as good as the
model, and the real cut shows whether that was enough.

Cycle time: the path's duration (dwell, motion) with and without the
adapted feeds."""

import copy
from dataclasses import dataclass, field

import numpy as np

from robstiff_drake.diagrams import user_model as user_models
from robstiff_drake.diagrams.experiment import run_cut
from robstiff_drake.diagrams.scenario import planned_path
from robstiff_drake.diagrams.scenario_step import plant_step_s
from robstiff_drake.diagrams.scenario_models import (
    model_damping_ratios, model_stiffness, payload_calibration, user_model_of
)
from robstiff_drake.model import feed_plan as fp
from robstiff_drake.model import kinematics as kin

MAX_ITERATIONS = 4


@dataclass
class FeedPlan:
    tolerance_mm: float
    windows: list  # model/feed_plan.Window, the slowed stretches
    advice: list  # [{line, error_mm, cause, feed_mm_per_min, programmed_feed_mm_per_min}]
    predicted_max_abs_mm: float  # before adaptation (the program as written)
    predicted_after_max_abs_mm: float
    program_cycle_time_s: float
    cycle_time_s: float
    iterations: int
    converged: bool
    notes: list = field(default_factory=list)
    line_ranges: dict = field(default_factory=dict)  # {program line: [(from mm, to mm along its move, feed mm/min)]}
    overrides: dict = field(default_factory=dict)  # {programmed element: [(a m, b m, speed m/s)]} (model/path.py)
    # the plan is used (its windows slow the compensated cut) only when its prediction improves on the program's
    adopted: bool = False
    predicted_errors_as_programmed: list = field(default_factory=list)  # [(s m, |error| mm, cause)] beyond tolerance

    def as_dict(self):
        return {"tolerance_mm": self.tolerance_mm, "predicted_max_abs_mm": self.predicted_max_abs_mm,
                "predicted_after_max_abs_mm": self.predicted_after_max_abs_mm,
                "program_cycle_time_s": self.program_cycle_time_s, "cycle_time_s": self.cycle_time_s,
                "cycle_time_increase": self.cycle_time_s / self.program_cycle_time_s - 1.0,
                "iterations": self.iterations, "converged": self.converged, "adopted": self.adopted,
                "slowed": [{"from_mm": w.s0 * 1e3, "to_mm": w.s1 * 1e3, "feed_mm_per_min": w.speed * 60e3,
                            "error_mm": w.error_mm, "cause": w.cause} for w in self.windows],
                "notes": list(self.notes)}


def twin_scenario(sc, robot, coefficient_factor):
    """The compensator's model of the cell as a scenario: the plant is what
    the model believes, its cutting law the model's (linear,
    revolution-averaged: no chip exponent, runout or wear, which only the
    plant has), the cutting coefficients the model's times
    ``coefficient_factor``, the compensator the scenario's with its model."""
    tw = copy.deepcopy(sc)
    k = model_stiffness(sc, robot)
    cal = payload_calibration(sc, robot)
    servo = user_models.servo_model(sc)
    h = plant_step_s(sc, robot)
    tw.plant.joint_stiffness_Nm_per_rad = [float(v) for v in k]
    tw.plant.damping_ratios = [float(v) for v in model_damping_ratios(sc)]
    tw.plant.lost_motion_rad = list(sc.model.lost_motion_rad)
    tw.plant.coupling_c23_rad_per_Nm = sc.model.coupling_c23_rad_per_Nm
    period = sc.servo.interpolator_period_ms
    tw.servo.interpolator_delay_ms = float(max(0.0, round((servo.dead_time_s - h) * 1e3 / period) * period))
    tw.servo.position_gain_per_s = float(np.clip(servo.position_gain_per_s, 1.0, 1000.0))
    tw.servo.velocity_bandwidth_hz = float(np.clip(servo.velocity_bandwidth_hz, 1.0, 500.0))
    tw.servo.velocity_feedforward = 1.0
    tw.servo.velocity_integral_hz = float(np.clip(servo.velocity_integral_hz, 0.0, 100.0))
    tw.servo.velocity_integral = "stated"  # (the identified drives' corner, not one chosen again)
    tw.sensor.force_bias_N = [float(v) for v in cal.force_bias_N]
    tw.sensor.torque_bias_Nm = [float(v) for v in cal.torque_bias_Nm]
    um = user_model_of(sc)
    factors = um.coefficient_factors if um is not None else {}
    c = tw.cutting
    c.plant_law = "linear"  # the compensator's law (linear, revolution-averaged): the plant's richer one is the plant's
    for name in ("Ktc_N_per_mm2", "Krc_N_per_mm2", "Kac_N_per_mm2", "Kte_N_per_mm", "Kre_N_per_mm", "Kae_N_per_mm"):
        setattr(c, name, getattr(c, name) * factors.get(name, 1.0) * sc.model.force_model_scale * coefficient_factor)
    tw.model.source = "nominal"
    tw.model.joint_stiffness_Nm_per_rad = [float(v) for v in k]
    tw.model.identified_json = tw.model.payload_yaml = ""
    tw.model.force_model_scale = 1.0 / coefficient_factor
    tw._user_model = None
    return tw


def coefficient_bounds(sc):
    """The twin's coefficient factors: the ends of the model's stated uncertainty."""
    u = sc.model.identification.coefficient_error if user_model_of(sc) is not None else 0.0
    return (1.0 - u, 1.0 + u) if u > 0 and sc.controller.mode != "plain" else (1.0,)


def _tool_points(res):
    t, x = res.logs["state"]
    T6 = kin.frames(res.cell.robot.dh, x[:, :6])[:, 6]
    return t, T6[:, :3, 3] + T6[:, :3, :3] @ res.cell.tool_m, -T6[:, :3, 2]


def predicted_errors(sc, robot, overrides, tolerance_mm, factors):
    """The twin's predicted surface errors beyond ``tolerance_mm``, each
    charged to the path: [(s_m, error_mm, cause)], the largest |error| (mm)
    and the coefficient factor of the twin that gave it, with the path
    lowered by ``overrides`` and the twin's coefficients the model's times
    each of ``factors``."""
    worst = {}  # (x, y) rounded -> (|e|, e, run, index)
    runs = []
    for factor in factors:
        tw = twin_scenario(sc, robot, factor)
        tw._feed_overrides = overrides
        res = run_cut(tw, robot, compensation=True)
        runs.append(res)
        for line in res.scans:
            e = line.error_m * 1e3
            for i in np.flatnonzero(np.isfinite(e)):
                key = (round(float(line.x_m[i]), 6), round(float(line.y_at[i]), 6))
                if key not in worst or abs(e[i]) > worst[key][0]:
                    worst[key] = (abs(e[i]), e[i], len(runs) - 1)
    largest, _, worst_run = max(worst.values(), default=(0.0, 0.0, 0))
    out = []
    bad = [(k, v) for k, v in worst.items() if v[0] > tolerance_mm]
    for r, res in enumerate(runs):
        pts = [(k, v) for k, v in bad if v[2] == r]
        if not pts:
            continue
        t, p, n = _tool_points(res)
        xy = np.array([k for k, _ in pts])
        deepest, first = fp.deepest_pass(xy[:, 0], xy[:, 1], p, n, res.cell.force_model.cutter.radius_m)
        tw_t, w = res.logs["cutting_wrench"]
        fmag = np.linalg.norm(w[:, :3], axis=1)

        def force_at(tt, tw_t=tw_t, fmag=fmag):
            return float(np.interp(tt, tw_t, fmag))

        path = res.cell.path
        for (key, v), di, fi in zip(pts, deepest, first):
            if di < 0:
                continue
            s = path.arc_length(t[di])
            why = fp.cause(path, s, t[di], t[max(fi, 0)], force_at, res.cell.force_model.cutter.radius_m)
            out.append((s, v[0], why))
    return out, largest, factors[worst_run]


def plan_feeds(sc, robot, tolerance_mm=None):
    """The feed plan of scenario ``sc`` (its identified model resolved):
    where the twin's predicted error exceeds the tolerance, the feed there
    lowered, iterating until it holds or the feeds reach their floor."""
    from robstiff_drake.diagrams.milling_cell import planned_path as cell_path

    tol = float(tolerance_mm if tolerance_mm is not None else sc.path.tolerance_mm)
    _, _, q_ref = cell_path(sc, robot, robot.tool_point(where="the feed planner"))
    user_models.resolve(sc, robot, q_ref[0])
    base = copy.deepcopy(sc)
    base._feed_overrides = None
    path0 = planned_path(base)
    radius = sc.cutter.diameter_mm / 2e3
    margin = max(sc.path.zone_mm / 1e3, 0.25 * radius)
    windows, first, largest0, largest = [], None, None, None
    converged = False
    it = 0
    factors = coefficient_bounds(sc)
    tried = []  # (largest predicted |error| mm, iteration, windows): every set of windows the twin ran
    for it in range(1, MAX_ITERATIONS + 2):
        # both ends of the coefficients' uncertainty first, then the end that was worse
        errs, largest, worst = predicted_errors(sc, robot, fp.line_ranges(path0, windows), tol, factors)
        factors = (worst,)
        tried.append((largest, it, windows))
        if first is None:
            first, largest0 = errs, largest
        if not errs:
            converged = True
            break
        if it > MAX_ITERATIONS:  # the last windows predicted, not changed again
            break
        spans = fp.merge_windows([(s, s, e, c) for s, e, c in errs], margin, path0.total_length)
        path_now = path0.with_speed_overrides(fp.line_ranges(path0, windows))
        new = []
        for a, b, e, c in spans:
            ss = np.linspace(a, b, 12)
            v_prog = min(path0.speeds[path0._element(s)] for s in ss)
            v_now = min(path_now.speeds[path_now._element(s)] for s in ss)
            floor = sc.path.min_feed_fraction * v_prog
            if v_now <= floor * (1 + 1e-9):
                continue
            new.append(fp.Window(a, b, fp.new_speed(v_now, e, tol, floor), e, c))
        if not new:
            break
        windows = _combine(windows, new)
    # the plan is the windows whose prediction was the best; none (the program as written) unless that improves on
    # the program's own prediction: a slower feed also changes the path's dynamics (a corner taken at another
    # speed rings the arm differently), so a plan can be predicted worse than the program it adapts
    largest, _, windows = min(tried, key=lambda t: (t[0], t[1]))
    adopted = bool(windows) and largest < largest0
    rejected = None
    if not adopted:
        if len(tried) > 1:  # slower feeds were tried and none was predicted better
            rejected = (min(t[0] for t in tried[1:]), len(tried) - 1)
        windows, largest = [], largest0
    overrides = fp.line_ranges(path0, windows)
    adapted = path0.with_speed_overrides(overrides)
    # the advice: each slowed stretch with the worst error and cause predicted there for the program as written
    for w in windows:
        inside = [(e, c) for s, e, c in (first or []) if w.s0 <= s <= w.s1]
        if inside:
            w.error_mm, w.cause = max(inside)
    def programmed(w):
        return min(path0.speeds[path0._element(s)] for s in np.linspace(w.s0, w.s1, 12))

    shown = windows
    if rejected is not None:  # the lines beyond the tolerance as programmed, at their own feeds (nothing adopted)
        shown = [fp.Window(a, b, 0.0, e, c) for a, b, e, c in
                 fp.merge_windows([(s, s, e, c) for s, e, c in first], margin, path0.total_length)]
        shown = [fp.Window(w.s0, w.s1, programmed(w), w.error_mm, w.cause) for w in shown]
    advice = fp.advice_rows(path0, shown, programmed)
    if path0.program_lines is not None:  # each row's block (sequence) number as the program writes it, if any
        numbers = fp.block_numbers(_program_text(sc))
        for row in advice:
            row["block"] = numbers.get(row["line"])
    ranges = {}  # each program line's parts as the adapted path runs them
    if path0.program_lines is not None:
        slowed = {i for i, *_ in adapted.parts if len([p for p in adapted.parts if p[0] == i]) > 1}
        slowed |= {i for i, a, b, v in adapted.parts if v < path0.programmed_speeds[i] - 1e-12}
        for i in sorted(slowed):
            ranges[path0.program_lines[i]] = [(a * 1e3, b * 1e3, v * 60e3) for j, a, b, v in adapted.parts if j == i]
    notes = []
    if rejected is not None:
        notes.append(f"feed plan not used: the slower feeds tried ({rejected[1]} set(s)) were predicted to leave "
                     f"{rejected[0]:.3f} mm at best, no better than the program as written ({largest0:.3f} mm): the "
                     "error there is the path's own dynamics and the servo's lag (at corners and arcs), which a "
                     "lower feed does not remove; the program runs at its own feeds"
                     + (" (controller.mode: preview anticipates them)" if sc.controller.mode != "preview" else ""))
    elif not converged:
        notes.append(f"the predicted error stays above {tol:g} mm where the feed reached its floor "
                     f"({sc.path.min_feed_fraction:g} of the programmed, path.min_feed_fraction)")
    return FeedPlan(tol, windows, advice, float(largest0 or 0.0), float(largest or 0.0), path0.duration_s,
                    adapted.duration_s, it, converged, notes, ranges, overrides, adopted,
                    predicted_errors_as_programmed=list(first or []))


def advised_program(sc, plan):
    """The scenario's program text with the plan's feeds (model/feed_plan.
    rewrite_program); ValueError for a program it cannot rewrite."""
    from robstiff_drake.diagrams.scenario import _program

    program = _program(sc)
    return fp.rewrite_program(_program_text(sc), program.moves, plan.line_ranges)


def _program_text(sc):
    """The text of the scenario's G-code program."""
    from pathlib import Path

    from robstiff_drake.diagrams.scenario import resolve

    return Path(resolve(sc, sc.toolpath.program)).read_bytes().decode("utf-8-sig", errors="replace")


def _combine(old, new):
    """Windows of both lists; where they overlap, the lower speed over the union."""
    out = list(old)
    for w in new:
        merged = False
        for i, o in enumerate(out):
            if w.s0 <= o.s1 and o.s0 <= w.s1:
                out[i] = fp.Window(min(o.s0, w.s0), max(o.s1, w.s1), min(o.speed, w.speed), max(o.error_mm, w.error_mm),
                                   o.cause if o.error_mm >= w.error_mm else w.cause)
                merged = True
                break
        if not merged:
            out.append(w)
    return sorted(out, key=lambda w: w.s0)
