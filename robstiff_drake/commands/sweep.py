"""``robstiff sweep SCENARIO.yaml --period-ms ...``: the sampling-delay
study.  Every combination of period, delay, cutoff and mode is one
closed-loop simulation (local process pool, or a Dask cluster), set beside
the linear loop model's prediction."""

from pathlib import Path

import numpy as np

from robstiff_drake.diagrams.milling_cell import check_plant_step
from robstiff_drake.diagrams.scenario import load_scenario, scenario_robot
from robstiff_drake.diagrams.sweep import check_combinations, combinations, run_sweep
from robstiff_drake.errors import InputError
from robstiff_drake.io import Warnings, check_outputs, emit_json, save_figure_atomic
from robstiff_drake.paths import library_robots


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
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    delays = sorted({r["delay_steps"] for r in rows})
    fig, axes = plt.subplots(2, len(delays), figsize=(6.5 * len(delays), 8), squeeze=False, constrained_layout=True)
    keys = sorted({(r["cutoff_hz"], r["mode"]) for r in rows})
    colors = {k: f"C{i % 10}" for i, k in enumerate(keys)}
    for col, d in enumerate(delays):
        for (cut, mode) in keys:
            sel = sorted((r for r in rows if r["delay_steps"] == d and r["cutoff_hz"] == cut and r["mode"] == mode),
                         key=lambda r: r["period_ms"])
            if not sel:
                continue
            T = [r["period_ms"] for r in sel]
            for row, metric in enumerate(("zone", "mean")):
                sim = [_metric(r.get("surface_error_mm"), metric) if r.get("stable") else np.nan for r in sel]
                pred = [_metric(r.get("predicted", {}).get("surface_error_mm"), metric) for r in sel]
                ls = "-" if mode == "plain" else "--"
                axes[row, col].plot(T, sim, ls, marker="o", color=colors[(cut, mode)], label=f"{mode}, {cut:g} Hz")
                axes[row, col].plot(T, pred, ":", marker="x", color=colors[(cut, mode)], alpha=0.7)
                unstable = [t for t, r in zip(T, sel) if not r.get("stable")]
                if unstable:
                    axes[row, col].plot(unstable, [0.0] * len(unstable), "rX", ms=10)
        for row, label in enumerate(("entry/exit max |error| (mm)", "mean error (mm)")):
            ax = axes[row, col]
            ax.set_xscale("log")
            ax.set_xlabel("controller period (ms)")
            ax.set_ylabel(label)
            ax.set_title(f"delay {d} period(s): simulated (o), loop model (x); red X: unstable")
            ax.grid(True, which="both", alpha=0.3)
        axes[0, col].legend(fontsize=7)
    save_figure_atomic(fig, out, dpi=100)


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
    sc = load_scenario(scenario)
    if plant_step_ms:
        sc.plant_config.time_step = plant_step_ms / 1e3
    combos = combinations(periods_ms, delay_steps, cutoffs_hz, mode_list)
    check_combinations(sc, combos, plant_step_ms)
    robot = scenario_robot(sc, robot_yaml)
    check_plant_step(sc, robot)
    spec = None if robot_yaml is None else str(robot_yaml if robot_yaml in library_robots() else
                                                Path(robot_yaml).resolve())
    rows = run_sweep(Path(scenario), combos, workers=workers, scheduler=scheduler, plant_step_ms=plant_step_ms,
                     progress=progress, predict=predict, robot_spec=spec)
    warnings = Warnings()
    failed = [r for r in rows if "error" in r]
    if failed:
        warnings.add(f"{len(failed)} of {len(rows)} runs failed (see their 'error'); the first: {failed[0]['error']}")
    result = {"scenario": str(scenario), "robot": robot.name, "n_runs": len(rows), "n_failed": len(failed),
              "complete": not failed, "runs": rows, "warnings": list(warnings)}
    if json_out is not None:
        emit_json(result, json_out)
    if plot_out is not None:
        plot(rows, plot_out)
    if json_out != "-":
        print(format_table(rows))
    return 0


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
