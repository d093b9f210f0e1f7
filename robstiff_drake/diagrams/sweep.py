"""Parameter sweeps of the closed loop: every combination of controller
period, transport delay, filter cutoff and compensation mode is one
closed-loop simulation, run on a local process pool or a Dask cluster.

A run that fails comes back as a row that says why; the others are kept.
"""

import itertools
import math
import os
import signal
import time
from concurrent.futures import ProcessPoolExecutor, as_completed
from concurrent.futures.process import BrokenProcessPool

import numpy as np

from robstiff_drake.diagrams.run_vibration import vibration_of
from robstiff_drake.diagrams.sweep_config import configure
from robstiff_drake.errors import InputError
from robstiff_drake.progress import progress as progress_bar

# A run counts as diverged past these (the loop blew up or saturated for good).
DIVERGED_SURFACE_MM = 3.0
SATURATED_SHARE = 0.5  # of the last second of correction samples at the saturation limit


def combinations(periods_ms, delay_steps, cutoffs_hz, modes):
    return [{"period_ms": float(p), "delay_steps": int(d), "cutoff_hz": float(c), "mode": m}
            for p, d, c, m in itertools.product(periods_ms, delay_steps, cutoffs_hz, modes)]


def check_combinations(sc, combos, plant_step_ms=None):
    """Refuse, before anything runs, a combination the scenario cannot take."""
    from robstiff_drake.diagrams.scenario import bounding_step_s  # (Drake's: after the arguments' checks)

    for c in combos:
        step_ms = plant_step_ms or bounding_step_s(sc) * 1e3
        if c["period_ms"] < step_ms - 1e-9:
            raise InputError(f"sweep: period {c['period_ms']:g} ms is below the plant step "
                             f"({step_ms:g} ms); pass --plant-step-ms {c['period_ms']:g} or drop it")
        if not 0 < c["cutoff_hz"] < 0.5 * sc.sensor.rate_hz:
            raise InputError(f"sweep: cutoff {c['cutoff_hz']:g} Hz must be between 0 and half the sensor rate "
                             f"({0.5 * sc.sensor.rate_hz:g} Hz)")
        if c["delay_steps"] < 0:
            raise InputError(f"sweep: delay steps must be >= 0, got {c['delay_steps']}")
        if c["mode"] not in ("plain", "predictive"):
            raise InputError(f"sweep: mode must be plain or predictive, got {c['mode']!r}")
        try:
            configure(sc, c, plant_step_ms)  # every key of the run within its range, and its size
        except InputError as e:
            error = InputError(f"sweep: period {c['period_ms']:g} ms, delay {c['delay_steps']}, cutoff "
                               f"{c['cutoff_hz']:g} Hz: {e}")
            error.why = getattr(e, "why", None)
            raise error from None


_MASS_MATRICES = {}  # per process: the loop model's mass matrix at a pose


def run_one(scenario_path, combo, plant_step_ms=None, predict=True, robot_spec=None):
    """One sweep run (a top-level function: picklable for process pools and
    Dask workers), with the linear loop model's prediction for the same
    combination.  Never raises: a failure is a row with ``error``."""
    from robstiff_drake.diagrams.experiment import run_cut
    from robstiff_drake.diagrams.scenario import load_scenario, scenario_robot

    row = dict(combo)
    t0 = time.perf_counter()
    try:
        base = load_scenario(scenario_path)
        robot = scenario_robot(base, robot_spec)
        if predict:
            from robstiff_drake.diagrams.loop_prediction import predict as loop_predict

            row["predicted"] = loop_predict(base, robot, combo, plant_step_ms=plant_step_ms,
                                            mass_matrix_cache=_MASS_MATRICES)
        sc = configure(base, combo, plant_step_ms)
        res = run_cut(sc, robot, compensation=True)
        s = res.surface_error_mm
        corr = res.logs["correction"][1]
        last = corr[-max(1, int(round(1000.0 / combo["period_ms"]))):]
        sat = math.radians(sc.controller.saturation_deg)
        saturated = float(np.mean(np.any(np.abs(last) >= sat * (1 - 1e-9), axis=1)))
        finite = bool(np.all(np.isfinite(res.logs["state"][1])))
        stable = finite and bool(s) and s["max_abs"] < DIVERGED_SURFACE_MM and saturated < SATURATED_SHARE
        row.update(surface_error_mm=s, stable=stable, saturated_share=saturated,
                   wall_seconds=res.wall_seconds, sim_seconds=res.sim_seconds,
                   # did the run itself vibrate? (its own logs, numpy: diagrams/run_vibration.py)
                   vibration=vibration_of(res))
        if not stable:
            row["why"] = ("state not finite" if not finite else "correction saturated" if saturated >= SATURATED_SHARE
                          else f"surface error above {DIVERGED_SURFACE_MM} mm")
    except Exception as e:  # a failed run is a row, not the end of the sweep
        row.update(stable=False, error=" ".join(f"{type(e).__name__}: {e}".split())[:500])
        if getattr(e, "why", None):  # a refusal's detail (a plant step's numbers: diagrams/plant_step.py), as printed
            row["error_why"] = " ".join(str(e.why).split())[:2000]
    row["run_seconds"] = time.perf_counter() - t0
    return row


def run_sweep(scenario_path, combos, *, workers=None, scheduler=None, plant_step_ms=None, progress=None,
              predict=True, robot_spec=None):
    """All runs, in the order of ``combos`` (``robot_spec``: --robot, or None
    for the scenario's robot)."""
    with progress_bar(len(combos), progress, "sweep", unit="run") as bar:
        return _run_all(scenario_path, combos, bar, workers=workers, scheduler=scheduler,
                        plant_step_ms=plant_step_ms, predict=predict, robot_spec=robot_spec)


def _run_all(scenario_path, combos, bar, *, workers, scheduler, plant_step_ms, predict, robot_spec):
    rows = [None] * len(combos)
    if scheduler:
        try:
            from distributed import Client
        except ImportError:
            raise InputError("sweep: --scheduler needs Dask: pip install 'dask[distributed]'") from None
        try:
            client = Client(scheduler, timeout="10s")
        except (OSError, TimeoutError) as e:
            raise InputError(f"sweep: cannot reach the Dask scheduler at {scheduler} ({type(e).__name__})") from None
        try:
            futures = [client.submit(run_one, str(scenario_path), c, plant_step_ms, predict, robot_spec, pure=False)
                       for c in combos]
            index = {f.key: i for i, f in enumerate(futures)}
            from distributed import as_completed as dask_completed

            for f in dask_completed(futures):
                rows[index[f.key]] = f.result()
                bar.update(1)
        finally:
            client.close()
        return rows
    workers = min(workers or os.cpu_count() or 1, len(combos))
    if workers == 1:
        for i, c in enumerate(combos):
            rows[i] = run_one(str(scenario_path), c, plant_step_ms, predict, robot_spec)
            bar.update(1)
        return rows
    pool = ProcessPoolExecutor(max_workers=workers, initializer=_worker_init)
    try:
        futures = {pool.submit(run_one, str(scenario_path), c, plant_step_ms, predict, robot_spec): i
                   for i, c in enumerate(combos)}
        for f in as_completed(futures):
            i = futures[f]
            try:
                rows[i] = f.result()
            except BrokenProcessPool:  # a worker died (killed, out of memory): its run and the rest fail
                break
            bar.update(1)
    finally:
        _stop(pool)
    for i, c in enumerate(combos):
        if rows[i] is None:
            rows[i] = dict(c, stable=False, error="the worker process running it died (killed, or out of memory)")
    return rows


def _worker_init():
    """Workers leave Ctrl-C to the parent, which stops them, and die
    quietly on SIGTERM (the parent's handler is not theirs)."""
    signal.signal(signal.SIGINT, signal.SIG_IGN)
    signal.signal(signal.SIGTERM, signal.SIG_DFL)


def _stop(pool):
    """Shut a process pool down at once: queued runs cancelled, running
    workers terminated (an interrupted sweep leaves no process behind)."""
    procs = list(getattr(pool, "_processes", {}).values())
    manager = getattr(pool, "_executor_manager_thread", None)  # (shutdown forgets it)
    pool.shutdown(wait=False, cancel_futures=True)
    for p in procs:
        if p.is_alive():
            p.terminate()
    for p in procs:
        p.join(timeout=5)
    # and its manager thread ended, which closes the pipe it is woken by: on Python 3.11 the interpreter's exit
    # (concurrent.futures.process._python_exit) wakes it without the pool's lock, and a thread closing that pipe
    # meanwhile made it print "Exception ignored ... OSError: [Errno 9] Bad file descriptor" after "robstiff:
    # terminated" (seen once in CI, tests/test_reliability.py::test_sigterm_stops_a_sweep_and_its_workers)
    if manager is not None:
        manager.join(timeout=5)
