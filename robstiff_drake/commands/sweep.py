"""``robstiff sweep SCENARIO.yaml --period-ms ...``: the sampling-delay
study.  Every combination of period, delay, cutoff and mode is one
closed-loop simulation (local process pool, or a Dask cluster), set beside
the linear loop model's prediction."""

import sys
from pathlib import Path

import numpy as np

from robstiff_drake.diagrams.run_vibration import vibration_warnings
from robstiff_drake.diagrams.sweep import check_combinations, combinations, run_sweep
from robstiff_drake.errors import InputError
from robstiff_drake.io import Warnings, check_outputs, emit_json, save_figure_atomic, staged_outputs
from robstiff_drake.paths import library_robots
from robstiff_drake.progress import info, wrote


def parse_list(text, what, kind=float):
    """'0.5,1,2' -> [0.5, 1.0, 2.0]; a one-line error for an empty or bad list."""
    parts = [p.strip() for p in str(text).split(",")]
    if not text or not all(parts):
        raise InputError(f"sweep: {what}: expected a comma-separated list, got {text!r}")
    out = []
    for p in parts:
        try:
            v = kind(p)
        except ValueError:
            raise InputError(f"sweep: {what}: {p!r} is not a {'whole number' if kind is int else 'number'}") from None
        if kind is float and not np.isfinite(v):
            raise InputError(f"sweep: {what}: {p!r} is not finite")
        out.append(v)
    if kind is float and any(v <= 0 for v in out):
        raise InputError(f"sweep: {what}: values must be > 0, got {text!r}")
    return out


def plot(rows, out):
    """Surface error against the controller period, one column per delay:
    simulated (o) and the loop model's prediction (x), one colour per cutoff
    and mode; unstable runs marked along the bottom edge.  With one period
    the x axis lists the cutoff/mode combinations instead."""
    save_figure_atomic(plot_figure(rows), out, dpi=100)


UNSTABLE_STYLE = {"marker": "X", "color": "k", "mec": "w", "ms": 10, "ls": ""}
UNSTABLE_STRIP = 0.1  # share of the axes' height below the data where unstable runs are marked


def plot_figure(rows):
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt
    from matplotlib.lines import Line2D
    from matplotlib.transforms import blended_transform_factory

    delays = sorted({r["delay_steps"] for r in rows})
    periods = sorted({r["period_ms"] for r in rows})
    keys = sorted({(r["cutoff_hz"], r["mode"]) for r in rows})
    colors = {k: f"C{i % 10}" for i, k in enumerate(keys)}
    one_period = len(periods) == 1
    fig, axes = plt.subplots(2, len(delays), figsize=(5.5 * len(delays) + 2.5, 8), squeeze=False,
                             layout="constrained")
    strip_axes = set()
    for col, d in enumerate(delays):
        for ki, (cut, mode) in enumerate(keys):
            sel = sorted((r for r in rows if r["delay_steps"] == d and r["cutoff_hz"] == cut and r["mode"] == mode),
                         key=lambda r: r["period_ms"])
            if not sel:
                continue
            x = [ki] * len(sel) if one_period else [r["period_ms"] for r in sel]
            for row, metric in enumerate(("zone", "mean")):
                ax = axes[row, col]
                sim = [_metric(r.get("surface_error_mm"), metric) if r.get("stable") else np.nan for r in sel]
                pred = [_metric(r.get("predicted", {}).get("surface_error_mm"), metric) for r in sel]
                ls = "" if one_period else ("-" if mode == "plain" else "--")
                ax.plot(x, sim, ls, marker="o", color=colors[(cut, mode)])
                ax.plot(x, pred, "" if one_period else ":", marker="x", color=colors[(cut, mode)], alpha=0.7)
                unstable = [xi for xi, r in zip(x, sel) if not r.get("stable")]
                if unstable:  # in a strip along the bottom: an unstable run has no surface error to show
                    strip_axes.add(ax)
                    ax.plot(unstable, [UNSTABLE_STRIP / 2] * len(unstable),
                            transform=blended_transform_factory(ax.transData, ax.transAxes), **UNSTABLE_STYLE)
        for row, label in enumerate(("entry/exit max |error| (mm)", "mean error (mm)")):
            ax = axes[row, col]
            if one_period:
                ax.set_xticks(range(len(keys)), [f"{m}\n{c:g} Hz" for c, m in keys])
                ax.set_xlim(-0.5, len(keys) - 0.5)
                ax.set_xlabel(f"filter cutoff and mode (controller period {periods[0]:g} ms)")
            else:
                if periods[-1] / periods[0] >= 10:
                    ax.set_xscale("log")
                    ax.set_xticks(periods, [f"{p:g}" for p in periods])
                    ax.minorticks_off()
                ax.set_xlabel("controller period (ms)")
            ax.set_ylabel(label)
            if ax in strip_axes:  # room for the strip below the data
                lo, hi = ax.dataLim.intervaly
                pad = 0.05 * (hi - lo) if hi > lo else 0.05
                ax.set_ylim(lo - (UNSTABLE_STRIP * (hi - lo + 2 * pad)) / (1 - UNSTABLE_STRIP) - pad, hi + pad)
                ax.add_patch(plt.Rectangle((0, 0), 1, UNSTABLE_STRIP, transform=ax.transAxes, fc="0.9", ec="none",
                                           zorder=0))
            ax.set_title(f"transport delay {d} period{'s' if d != 1 else ''}")
            ax.grid(True, which="both", alpha=0.3)
    handles = [Line2D([], [], color=colors[k], marker="o", ls="" if one_period else ("-" if k[1] == "plain" else "--"),
                      label=f"{k[1]}, {k[0]:g} Hz") for k in keys]
    handles += [Line2D([], [], color="0.3", marker="o", ls="", label="simulated"),
                Line2D([], [], color="0.3", marker="x", ls="", label="loop model")]
    if strip_axes:
        handles.append(Line2D([], [], label="unstable run", **UNSTABLE_STYLE))
    fig.legend(handles=handles, loc="outside right upper", fontsize=8)
    fig.suptitle("surface error against the controller period" if not one_period else
                 "surface error by filter cutoff and mode")
    return fig


def _metric(stats, metric):
    if not stats:
        return np.nan
    if metric == "zone":
        return max(stats.get("entry_max_abs", np.nan), stats.get("exit_max_abs", np.nan))
    return stats.get("mean", np.nan)


def run(*, scenario, periods, delays="1", cutoffs="5", modes="plain", json_out=None, plot_out=None, workers=None,
        scheduler=None, plant_step_ms=None, predict=True, progress=None, robot_yaml=None):
    check_outputs(inputs=[scenario], files={"--json": json_out, "--plot": plot_out})
    periods_ms = parse_list(periods, "--period-ms")
    delay_steps = parse_list(delays, "--delay-steps", int)
    if any(d < 0 for d in delay_steps):
        raise InputError(f"sweep: --delay-steps: values must be >= 0, got {delays!r}")
    cutoffs_hz = parse_list(cutoffs, "--cutoff-hz")
    mode_list = [m.strip() for m in str(modes).split(",")]
    if not modes or any(m not in ("plain", "predictive") for m in mode_list):
        raise InputError(f"sweep: --mode: expected plain and/or predictive, got {modes!r}")
    if workers is not None and workers < 1:
        raise InputError(f"sweep: --workers must be >= 1, got {workers}")
    if plant_step_ms is not None and not plant_step_ms > 0:
        raise InputError(f"sweep: --plant-step-ms must be > 0, got {plant_step_ms}")
    # Drake comes with these: after the checks of the arguments above
    from robstiff_drake.diagrams.milling_cell import check_plant_step
    from robstiff_drake.diagrams.scenario import load_scenario, scenario_robot
    from robstiff_drake.diagrams.scenario_step import plant_step_s, step_choice
    from robstiff_drake.diagrams.scenario_models import model_stiffness, payload_calibration

    sc = load_scenario(scenario)
    plant_step_ms = plant_step_ms or shortest_period_step(sc, periods_ms, json_out)
    if plant_step_ms:
        sc.plant_config.time_step = plant_step_ms / 1e3
    combos = combinations(periods_ms, delay_steps, cutoffs_hz, mode_list)
    check_combinations(sc, combos, plant_step_ms)
    robot = scenario_robot(sc, robot_yaml)
    check_plant_step(sc, robot)
    # the files the scenario names for the compensator's model (model.identified_json, payload_yaml) read once,
    # here: a broken one is refused (exit 2) before any run, not found in every run (exit 0, every row failed)
    if sc.model.identified_json:
        model_stiffness(sc, robot)
    if sc.model.payload_yaml:
        payload_calibration(sc, robot)
    spec = None if robot_yaml is None else str(robot_yaml if robot_yaml in library_robots() else
                                                Path(robot_yaml).resolve())
    info(plan_line(sc, combos, periods_ms, delay_steps, cutoffs_hz, mode_list, workers, scheduler),
         file=sys.stderr if json_out == "-" else None)
    # would the cut chatter? (every run's plant leaves the regenerative chip out, and the compensator's settings
    # swept do not change the cut: one check, before the runs; diagrams/chatter_check.py)
    from robstiff_drake.diagrams.chatter_check import check_job

    warnings = Warnings()
    chatter = check_job(sc, robot, warnings)
    rows = run_sweep(Path(scenario), combos, workers=workers, scheduler=scheduler, plant_step_ms=plant_step_ms,
                     progress=progress, predict=predict, robot_spec=spec)
    # did each run itself vibrate? (its row's `vibration`, from its own logs in the worker: simulate's check)
    warnings.extend_from(vibration_warnings({run_name(r): r.get("vibration") for r in rows}, sc))
    failed = [r for r in rows if "error" in r]
    if failed:
        warnings.add(f"{len(failed)} of {len(rows)} runs failed (see their 'error'); the first: {failed[0]['error']}")
    result = {"scenario": str(scenario), "robot": robot.name, "n_runs": len(rows), "n_failed": len(failed),
              "complete": not failed, "plant_step_ms": plant_step_s(sc) * 1e3,
              "plant_step_choice": step_choice(sc), "chatter_check": chatter, "runs": rows,
              "warnings": list(warnings)}
    with staged_outputs():  # the JSON and the plot, both or neither
        if json_out is not None:
            emit_json(result, json_out)
        if plot_out is not None:
            plot(rows, plot_out)
    if json_out != "-":
        print(format_table(rows))
    wrote(json_out, f"{len(rows)} runs", to_stderr=json_out == "-")
    wrote(plot_out, to_stderr=json_out == "-")
    return 0


def run_name(row):
    """A sweep run's name in a warning: 'compensated (period 4 ms, delay 1, cutoff 2 Hz, plain)'."""
    return (f"compensated (period {row['period_ms']:g} ms, delay {row['delay_steps']}, cutoff {row['cutoff_hz']:g} Hz, "
            f"{row['mode']})")


def plan_line(sc, combos, periods_ms, delay_steps, cutoffs_hz, modes, workers, scheduler):
    """What the sweep is about to run, in one line: how many closed-loop
    runs, of how much simulated time each, on how many processes (a sweep
    of a thousand runs takes hours; the user should know before it starts)."""
    import os

    from robstiff_drake.diagrams.experiment import RUN_OUT_S
    from robstiff_drake.diagrams.scenario import planned_path

    each_s = planned_path(sc).duration_s + RUN_OUT_S
    n = len(combos)
    where = (f"on the Dask cluster at {scheduler}" if scheduler else
             f"on {min(workers or os.cpu_count() or 1, n)} local process(es) (--workers)")
    return (f"sweep: {n} closed-loop run{'s' if n != 1 else ''} ({len(periods_ms)} period(s) x {len(delay_steps)} "
            f"delay(s) x {len(cutoffs_hz)} cutoff(s) x {len(modes)} mode(s)), {each_s:.1f} s simulated each, "
            f"{n * each_s / 60:.1f} min simulated in all, {where}")


def shortest_period_step(sc, periods_ms, json_out=None):
    """The plant step (ms) for a sweep whose shortest controller period is
    below the scenario's plant step: that period, for every run (a plant
    steps at least as often as its controller; one step for all runs keeps
    them comparable, and a finer step changes the block test's result by
    less than 0.1 um, studies/time_step_convergence.py).  None: the
    scenario's step serves."""
    from robstiff_drake.diagrams.scenario_step import plant_step_s

    step_ms = plant_step_s(sc) * 1e3
    shortest = min(periods_ms)
    if shortest >= step_ms - 1e-9:
        return None
    info(f"sweep: plant step {shortest:g} ms for every run (the scenario's {step_ms:g} ms is longer than the "
         f"shortest period, {shortest:g} ms; --plant-step-ms sets it)",
         file=sys.stderr if json_out == "-" else None)
    return shortest


def format_table(rows):
    lines = ["period  delay  cutoff  mode        stable  mean    entry   exit   | model: |pole| entry/exit  mean",
             " (ms)           (Hz)                      (mm)    (mm)    (mm)   |         max     (mm)      (mm)"]
    for r in rows:
        s = r.get("surface_error_mm") or {}
        p = r.get("predicted") or {}
        ps = p.get("surface_error_mm") or {}
        sim = (f"{s.get('mean', np.nan):+.3f}  {s.get('entry_max_abs', np.nan):.3f}   {s.get('exit_max_abs', np.nan):.3f}"
               if s else f"failed: {r.get('error', r.get('why', ''))[:40]}")
        model = (f"{p.get('spectral_radius', np.nan):.3f}  {_metric(ps, 'zone'):.3f}     {ps.get('mean', np.nan):+.3f}"
                 if p else "")
        lines.append(f"{r['period_ms']:6g}  {r['delay_steps']:5d}  {r['cutoff_hz']:6g}  {r['mode']:10s}  "
                     f"{str(r.get('stable')):6s}  {sim}  | {model}")
    return "\n".join(lines)
