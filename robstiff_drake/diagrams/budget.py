"""The error budget of a compensated cut: how much of its residual each
imperfection makes, found by removing the imperfections one at a time
(``simulate --budget``).

Sources, and what "removed" means (the scenario's other settings kept):

* stiffness model error: the compensator holds the plant's joint stiffness;
* payload and bias error: the exact payload and the sensor's bias of the cut;
* cutting-coefficient error (predictive, preview): the plant's coefficients;
* force filter lag: the compensator reads the cutting wrench without lag:
  its wrist sensor is replaced by one whose samples (the sensor's rate,
  bias and noise) are the plant's true cutting wrench and the payload's
  static weight at the arm's pose, without the payload's inertia
  (systems/wrist_sensor.LagFreeCuttingSensor), and there is no force
  filter.  (Deleting the filter alone is not a removal of its lag: the
  plain loop then feeds the sensor's reading of the payload's inertia back
  at the arm's first mode and rings, 72-119 mm on the paper's cuts; the
  filter is there for that as much as for the noise.)  So that the removal
  takes away the lag and not the noise filtering too, the lag-free
  sensor's noise is the filtered noise's size: the sensor's noise times
  the filter's noise factor (model/filters.noise_std_factor, 0.067 for a
  2 Hz second-order low-pass at 1 kHz), white rather than low-passed (the
  same variance per sample, not the same spectrum);
* sensor noise: a noiseless sensor;
* servo and interpolator lag: no interpolator dead time, a 1000 1/s
  position loop around a 500 Hz velocity loop;
* sampling period and transport delay: no delay periods, the controller
  (and the sensor at >= 1 kHz) at 1 ms; the plant's step, where it is
  coarser than 1 ms, then goes to 1 ms too (a discrete plant cannot be
  sampled faster than it steps): this removal also changes the
  simulation's step, which is why the budget prints it (ALSO_CHANGES);
  the step's own effect is measured in studies/time_step_convergence.py;
* lost motion: none in the gears (nor in the compensator's model);
* the arm's dynamic response: the arm's and the payload's masses and
  inertias scaled by EPSILON and gravity by 1 / EPSILON: the same static
  loads, the links' modes on their gears sqrt(1 / EPSILON) = 5 times
  faster (the first at about 25 Hz instead of 5): the arm follows force
  changes and the path's accelerations quasi-statically; the motors' rotor
  inertias are the drives' and stay (scaled too, the drives' loop diverged
  in a step test at this step); the plant's explicit step then needs
  FAST_STEP_S for the stiffest mode (125 Hz -> about 620 Hz), checked
  converged against 0.2 ms in a step test;
* kinematic error (a study's controller whose kinematic model is not the
  arm's: its path accuracy; studies/paper_reproduction.py): the arm's own;
* scan noise: a noiseless scan (the budget's statistics are the scan's, as
  a user measures them, not the simulation's true surface).

The field split (the budget's answer: model/budget_fields.py).  Each run
keeps its error field along the scan (mm, the same scan points in every
run); source i's field is the cut's less the one with i alone removed,
and its share is its projection on the cut's field over the cut's mean
square.  When the sources' effects add, the shares and the floor's add to
1 whatever the fields' correlations; what is left is the true interaction.
The one-at-a-time split of the RMS below it calls 41-49 % of an additive
cut "interaction" (n equal uncorrelated sources add in quadrature); it is
printed beside, for comparison.

Interactions and the attribution.  Removing two sources together is not
the sum of removing each (a filter's lag matters less once the delays are
gone), so one-at-a-time shares do not add up to the total.  The budget
gives two answers, side by side:

* one at a time: each source's share is the realistic cut's residual less
  the residual with that source alone removed (what fixing this one thing
  buys); the floor is the residual with every source removed; the
  interaction, total - floor - the sum of the shares, is what no single
  source owns.
* ordered (the attribution): the sources are removed cumulatively in the
  order of SOURCES and again in the reverse order; each source's share is
  the mean of what removing it took off the residual in the two orders:
  the Shapley value estimated over these two orderings (an ordering and its
  reverse: each source is once early and once late).  Each order's steps
  sum to total - floor exactly, so the shares and the floor sum to the
  total exactly; what the two orders disagree on (half their difference,
  ``order_spread``) is the attribution's uncertainty from the
  interactions.

Costs: one at a time n + 2 runs; the ordered attribution 2 (n - 2) more
(its first steps are one-at-a-time runs).  (A first version removed the
sources cumulatively when "force filter lag removed" still meant deleting
the filter: states with no filter and no delays rang, and the shares came
out +-0.1 mm and cancelled.  With the lag-free measurement no removal
rings on the scenarios measured; a run that does is named, RINGING_FACTOR.)
"""

import copy
import dataclasses

import numpy as np

from robstiff_drake.diagrams import user_model as user_models
from robstiff_drake.diagrams.experiment import run_cut
from robstiff_drake.diagrams.milling_cell import build_milling_cell, planned_path
from robstiff_drake.diagrams.scenario_step import plant_step_s
from robstiff_drake.diagrams.scenario_models import cutting_setup, exact_payload_calibration, plant_stiffness
from robstiff_drake.model import budget_fields
from robstiff_drake.model.filters import noise_std_factor
from robstiff_drake.model.surface import surface_error_stats

EPSILON = 0.04  # the mass scale of "the arm's dynamic response removed"
FAST_STEP_S = 0.0004  # the plant step with the faster modes (about 620 Hz at EPSILON: the step's bound is diagrams/plant_step.py's)
FINE_PERIOD_S = 0.001  # the controller period (and plant step) of "sampling period removed"

SOURCES = ("stiffness model error", "payload and bias error", "cutting-coefficient error", "force filter lag",
           "sensor noise", "servo and interpolator lag", "sampling period and delay", "lost motion",
           "arm dynamic response", "kinematic error", "scan noise")
METRICS = ("mean", "rms", "max_abs", "pv")
# A run whose largest error exceeds RINGING_FACTOR times the real cut's is named in the budget (``ringing``):
# its loop rings rather than cutting better, and a share involving it is not a share of the cut's error
RINGING_FACTOR = 2.0
# what a removal changes beyond its label, where it cannot help it (printed under the budget)
ALSO_CHANGES = {"sampling period and delay": "the plant's step, to 1 ms where it is coarser",
                "arm dynamic response": f"the plant's step, to {FAST_STEP_S * 1e3:g} ms (the faster modes need it)"}


def applies(sc, source):
    """Whether ``source`` is an imperfection of this scenario at all."""
    ident = sc.model.source == "identified"
    if source == "stiffness model error":
        return ident or bool(sc.model.joint_stiffness_Nm_per_rad) or bool(sc.model.identified_json) or \
            bool(sc.plant.joint_stiffness_Nm_per_rad)
    if source == "payload and bias error":
        return ident or bool(sc.model.payload_yaml)
    if source == "cutting-coefficient error":
        return sc.controller.mode != "plain" and (ident or sc.model.force_model_scale != 1.0)
    if source == "force filter lag":
        return sc.controller.filter.kind != "none"
    if source == "sensor noise":
        return sc.sensor.noise_N > 0 or sc.sensor.noise_Nm > 0
    if source == "lost motion":
        return bool(sc.plant.lost_motion_rad) and any(sc.plant.lost_motion_rad)
    if source == "scan noise":
        return sc.scan.noise_mm > 0
    if source == "kinematic error":
        return getattr(sc, "_controller_robot", None) is not None
    return True


def scaled_robot(robot, eps):
    """The robot with every link's and the payload's mass and inertia times ``eps``."""
    links = tuple(dataclasses.replace(link, mass_kg=link.mass_kg * eps, inertia_kgm2=link.inertia_kgm2 * eps)
                  for link in robot.links)
    payload = dataclasses.replace(robot.payload, mass_kg=robot.payload.mass_kg * eps)
    return dataclasses.replace(robot, links=links, payload=payload)


def without(sc, robot, removed, model):
    """(scenario, robot, gravity scale) of ``sc`` with the sources ``removed``;
    ``model`` the identified model of the full scenario (kept, with the
    removed parts made exact)."""
    s = copy.deepcopy(sc)
    um = None if model is None else dataclasses.replace(model)
    if "stiffness model error" in removed:
        s.model.joint_stiffness_Nm_per_rad = [float(v) for v in plant_stiffness(sc, robot)]
        s.model.identified_json = ""
    if "payload and bias error" in removed:
        s.model.payload_yaml = ""
        if um is not None:
            um.calibration = exact_payload_calibration(sc, robot)
    if "cutting-coefficient error" in removed:
        s.model.force_model_scale = 1.0
        if um is not None:
            um.coefficient_factors = {k: 1.0 for k in um.coefficient_factors}
    if "force filter lag" in removed:  # a lag-free measurement of the cutting wrench, no filter (module docstring)
        b, a = _filter_ba(sc)
        factor = noise_std_factor(b, a)  # the noise as filtered: the removal takes the lag, not the filtering
        s.sensor.noise_N, s.sensor.noise_Nm = s.sensor.noise_N * factor, s.sensor.noise_Nm * factor
        s.controller.filter.kind = "none"
        s._lag_free_cutting_sensor = True
    if "sensor noise" in removed:
        s.sensor.noise_N = s.sensor.noise_Nm = 0.0
    if "servo and interpolator lag" in removed:
        s.servo.interpolator_delay_ms = 0.0
        s.servo.position_gain_per_s = 1000.0
        s.servo.velocity_bandwidth_hz = 500.0
    if "lost motion" in removed:
        s.plant.lost_motion_rad = []
        s.model.lost_motion_rad = []
    if "scan noise" in removed:
        s.scan.noise_mm = 0.0
    if "kinematic error" in removed:
        s._controller_robot = None
    gravity = 1.0
    if "arm dynamic response" in removed:
        # the compensator's payload calibration stays the real payload's (the sensor reads its weight)
        if "payload and bias error" in removed or (um is None and not s.model.payload_yaml):
            s._payload_calibration_override = exact_payload_calibration(sc, robot)
        elif not s.model.payload_yaml:
            s._payload_calibration_override = um.calibration
        robot = scaled_robot(robot, EPSILON)
        gravity = 1.0 / EPSILON
        s.plant_config.time_step = min(plant_step_s(s, robot), FAST_STEP_S)
    if "sampling period and delay" in removed:
        s.controller.delay_steps = 0
        s.plant_config.time_step = min(plant_step_s(s, robot), FINE_PERIOD_S)
        s.controller.period_ms = FINE_PERIOD_S * 1e3
        s.servo.interpolator_period_ms = FINE_PERIOD_S * 1e3
        s.sensor.rate_hz = max(s.sensor.rate_hz, 1.0 / FINE_PERIOD_S)
    # (the interpolator's hold is at least a plant step; a finer plant step keeps the controller's cycle)
    s.servo.interpolator_period_ms = max(s.servo.interpolator_period_ms, float(s.plant_config.time_step) * 1e3)
    s.controller.period_ms = max(s.controller.period_ms, float(s.plant_config.time_step) * 1e3)
    s._user_model_pinned = um
    # the compensator's servo model, identified again on a plant whose servo changed
    s._reidentify_servo = um is not None and bool({"servo and interpolator lag", "sampling period and delay",
                                                   "arm dynamic response"} & set(removed))
    return s, robot, gravity


def _filter_ba(sc):
    """(b, a) of scenario ``sc``'s force filter, at its sensor's rate."""
    from robstiff_drake.diagrams.compensator import filter_coefficients
    return filter_coefficients(sc.controller.filter, sc.sensor.rate_hz, cutting_setup(sc)[0].spindle_rpm)


def measured_field_mm(res):
    """The surface error as the scan measures it (mm), every scan line's
    points end to end (NaN where there is no machined face)."""
    return np.concatenate([np.asarray(line.measured_error_m, dtype=float) for line in res.scans]) * 1e3


def measured_stats(res):
    """Surface-error statistics (mm) of what the scan measures (its noise in)."""
    err = np.concatenate([line.measured_error_m[np.isfinite(line.measured_error_m)] for line in res.scans])
    return surface_error_stats(err)


def run(sc, robot, *, compensation=True):
    """One compensated cut of a budget scenario (``without``'s output):
    (measured statistics (mm), the measured error field (mm))."""
    s, rob, gravity = sc
    if getattr(s, "_reidentify_servo", False):  # keep the identified parts, identify the servo anew
        _, _, q_ref = planned_path(s, rob, rob.tool_point(where="the error budget"))
        fresh = user_models.user_model(_servo_only(s), rob, q_ref[0])
        s._user_model_pinned = dataclasses.replace(s._user_model_pinned, servo=fresh.servo,
                                                   servo_fit_rms=fresh.servo_fit_rms)
    cell = build_milling_cell(s, rob, compensation=compensation)
    if gravity != 1.0:
        g = np.array([0.0, 0.0, -9.81]) * gravity
        cell.station.plant.mutable_gravity_field().set_gravity_vector(g)
        cell.station.controller_plant.mutable_gravity_field().set_gravity_vector(g)
        # the sensor at rest reads the same weight (eps m times g / eps): the payload's true mass
        cal = cell.station.systems["true_calibration"]
        cell.station.systems["true_calibration"] = dataclasses.replace(cal, mass_kg=cal.mass_kg * gravity)
        if getattr(s, "_lag_free_cutting_sensor", False):  # its weight: eps m at gravity g / eps
            cell.station.systems["sensor"].set_payload(cal, g)
    res = run_cut(s, rob, compensation=compensation, cell=cell)
    return measured_stats(res), measured_field_mm(res)


def _servo_only(sc):
    """A scenario whose identification makes only the servo model (the other
    parts come from the full scenario's model)."""
    s = copy.deepcopy(sc)
    ident = s.model.identification
    ident.stiffness, ident.payload, ident.coefficients, ident.servo = "exact", "exact", "exact", "identified"
    return s


def error_budget(sc, robot, *, metric="rms", sources=None, ordered=True, progress=None):
    """The budget of scenario ``sc``'s compensated cut (module docstring), a
    dict: ``total``, ``floor`` (every source removed), ``contributions``
    ({source: mm}, one at a time), ``interaction`` (total - floor - their
    sum); with ``ordered``: ``attribution`` ({source: mm}, the mean of the
    forward and reverse cumulative removals; it and the floor sum to the
    total), ``forward``/``reverse`` (each order's steps) and ``order_spread``
    (half their difference); ``field`` (the split of the error field
    itself, model/budget_fields.field_shares: each source's and the
    floor's fraction of the cut's mean square and the true interaction);
    ``ringing`` ({run: max abs mm}, runs whose
    loop rings), ``run_stats`` ({run: METRICS}), ``metric``, ``sources``,
    ``runs``.  ``progress(text)``:
    called after each run."""
    if metric not in METRICS:
        raise ValueError(f"metric must be one of {METRICS}")
    _, _, q_ref = planned_path(sc, robot, robot.tool_point(where="the error budget"))
    model = user_models.resolve(sc, robot, q_ref[0])
    active = [s for s in SOURCES if s in (sources or SOURCES) and applies(sc, s)]
    n_runs = len(active) + 2 + (2 * max(len(active) - 2, 0) if ordered else 0)
    done, fields = {}, {}

    def stats_without(removed):
        key = frozenset(removed)
        if key not in done:
            done[key], fields[key] = run(without(sc, robot, key, model), robot)
            if progress:
                progress(f"budget: {len(done)} of {n_runs} runs; removed: {', '.join(sorted(key)) or 'nothing'}")
        return done[key]

    full = stats_without(())
    total = float(full[metric])
    alone = {src: float(stats_without([src])[metric]) for src in active}
    floor = float(stats_without(active)[metric])
    contributions, interaction = budget_fields.one_at_a_time(total, alone, floor)
    out = {"metric": metric, "total": total, "floor": floor, "contributions": contributions,
           "interaction": interaction, "sources": active}
    try:
        out["field"] = budget_fields.field_shares(fields[frozenset()], {s: fields[frozenset([s])] for s in active},
                                                  fields[frozenset(active)])
    except ValueError as e:  # no common scan points, or a zero error field: no field split, and why
        out["field_not_split"] = str(e)
    if ordered:
        steps = {}
        for name, order in (("forward", active), ("reverse", active[::-1])):
            prev, steps[name] = total, {}
            for k, src in enumerate(order):
                now = float(stats_without(order[:k + 1])[metric])
                steps[name][src] = prev - now
                prev = now
        out.update(forward=steps["forward"], reverse=steps["reverse"],
                   attribution={src: 0.5 * (steps["forward"][src] + steps["reverse"][src]) for src in active},
                   order_spread={src: 0.5 * abs(steps["forward"][src] - steps["reverse"][src]) for src in active})
    limit = RINGING_FACTOR * full["max_abs"]
    out["ringing"] = {", ".join(sorted(k)) or "nothing": float(v["max_abs"]) for k, v in done.items()
                      if v["max_abs"] > limit}
    out["runs"] = len(done)
    # every run's statistics, by what it removed (for a split by another metric without running again)
    out["run_stats"] = {", ".join(sorted(k)) or "nothing": {m: float(v[m]) for m in METRICS} for k, v in done.items()}
    return out


def interaction_fraction(b):
    """The one-at-a-time interaction as a fraction of total - floor (the
    budget's 10 % target); None when total - floor is zero."""
    span = b["total"] - b["floor"]
    return None if span == 0 else abs(b["interaction"]) / abs(span)


def budget_json(b):
    """``error_budget_mm`` for the JSON: {source: share, "all removed":
    floor, "total": total}, the shares the ordered attribution's (they and
    the floor sum to the total) or, without it, the one-at-a-time shares
    with their "interaction"."""
    if "attribution" in b:
        out = dict(b["attribution"])
    else:
        out = dict(b["contributions"])
        out["interaction"] = b["interaction"]
    out["all removed"] = b["floor"]
    out["total"] = b["total"]
    return out


def format_budget(b):
    ordered = "attribution" in b
    lines = [f"error budget of the compensated cut ({b['metric']} of the measured surface error, mm)",
             "  one at a time: the residual less the residual with that source alone removed"]
    if ordered:
        lines.append("  ordered: the mean of the source's step when the sources are removed cumulatively in "
                     "this order and in its reverse (+- half their difference); sums exactly")
        lines.append(f"    order: {', '.join(b['sources'])}")
        lines.append(f"  {'source':30s} {'one at a time':>13s} {'ordered':>9s} {'+-':>7s}")
    else:
        lines.append(f"  {'source':30s} {'one at a time':>13s}")
    key = b["attribution"] if ordered else b["contributions"]
    for s in sorted(key, key=lambda k: -abs(key[k])):
        row = f"  {s:30s} {b['contributions'][s]:+13.4f}"
        if ordered:
            row += f" {b['attribution'][s]:+9.4f} {b['order_spread'][s]:7.4f}"
        lines.append(row)
    lines.append(f"  {'interaction (no single source)':30s} {b['interaction']:+13.4f}" +
                 (f" {0.0:+9.4f}" if ordered else ""))
    frac = interaction_fraction(b)
    lines.append(f"  {'every source removed (floor)':30s} {b['floor']:+13.4f}" +
                 (f" {b['floor']:+9.4f}" if ordered else ""))
    lines.append(f"  {'total':30s} {b['total']:+13.4f}" + (f" {b['total']:+9.4f}" if ordered else ""))
    if frac is not None:
        lines.append(f"  the one-at-a-time interaction is {100 * frac:.0f} % of total - floor")
        if ordered:
            spread = sum(b["order_spread"].values()) / abs(b["total"] - b["floor"])
            lines.append(f"  the ordered shares' +- sum to {100 * spread:.0f} % of total - floor")
    if "field" in b:
        lines.extend(format_field(b["field"], b["sources"]))
    elif "field_not_split" in b:
        lines.append(f"  no split of the error field: {b['field_not_split']}")
    for src in b["sources"]:
        if src in ALSO_CHANGES:
            lines.append(f"  removing {src} also changes {ALSO_CHANGES[src]}")
    for run_, mx in b.get("ringing", {}).items():
        lines.append(f"  rings: the run with {run_} removed (max abs {mx:.3f} mm): its share is not of the cut's error")
    return "\n".join(lines)


def format_field(f, sources):
    """The field split's lines (the budget's answer: they add up)."""
    lines = [f"  the error field split ({f['points']} scan points; a source's field: the cut's less the one with it "
             "alone removed; its share: its projection on the cut's field over the cut's mean square)",
             f"  {'source':30s} {'share':>7s} {'RMS mm':>8s} {'mean mm':>8s}"]
    for s in sorted(sources, key=lambda k: -abs(f["shares"][k])):
        lines.append(f"  {s:30s} {100 * f['shares'][s]:+6.1f}% {f['shares_mm'][s]:+8.4f} {f['mean_mm'][s]:+8.4f}")
    lines.append(f"  {'every source removed (floor)':30s} {100 * f['floor']:+6.1f}% {f['floor_mm']:+8.4f} "
                 f"{f['mean_mm']['floor']:+8.4f}")
    lines.append(f"  {'interaction (what is left)':30s} {100 * f['interaction']:+6.1f}% {f['interaction_mm']:+8.4f} "
                 f"{f['mean_mm']['interaction']:+8.4f}")
    lines.append(f"  {'total':30s} {100.0:+6.1f}% {f['rms_mm']:+8.4f} {f['mean_mm']['total']:+8.4f}")
    return lines
