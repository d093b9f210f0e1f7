"""Residual diagnosis of a machining run (``robstiff diagnose-run RUN_DIR``):
from what a cell records -- the force estimate, the commanded joint angles
and the laser scan of the machined surface -- find what the compensated
surface error is, trace it to a cause, add the cause to the compensator (or
switch on predictive compensation where the cause is the loop's lag), run
the cut again and report before and after.

Each candidate cause predicts the tool's vertical deviation over the pass
from the recorded data, up to its parameter(s):
  loop_lag               tau_lag * d/dt (C J^T W)_z  (error that follows dF/dt,
                         at entries and exits)
  stiffness_error_jN     r_N (J_v,N c_N tau_N)_z      (joint N softer by r_N)
  lost_motion            sum_N b_N (J_v,N tanh(tau_N / 50 N*m))_z, joints 1-3
  joint_coupling         c23 (J_v,2 tau_3 + J_v,3 tau_2)_z
and the surface error at x is minus the deviation when the cutter's centre
passes x (cut more when the tool is low); a constant set-up offset (tool
length, workpiece height) is a candidate too.  On a steady cut a stiffness
error and an offset look alike; they part where the force changes.  The
starting model is the compensator as it is (no error).  Forward selection as in the
campaign diagnosis: a nested F-test (p < ALPHA) and a held-out error (blocks
of the scan) that falls by at least MIN_GAIN.
"""

import copy
import csv
from dataclasses import dataclass
from pathlib import Path

import numpy as np
from scipy import stats

from robstiff_drake.diagrams.experiment import run_cut
from robstiff_drake.diagrams.scenario import load_scenario, model_stiffness, planned_path
from robstiff_drake.errors import InputError
from robstiff_drake.model import kinematics as kin
from robstiff_drake.systems.joint_effects import LOST_MOTION_TORQUE_NM

ALPHA = 1e-4
MIN_GAIN = 0.10
N_BLOCKS = 8
REQUIRED = ("scenario.yaml", "timeseries_compensated.csv", "surface_compensated.csv")


def read_csv(path):
    with open(path) as f:
        rows = [r for r in csv.reader(line for line in f if not line.startswith("#"))]
    header, body = rows[0], rows[1:]
    data = {h: np.array([float(r[i]) if r[i] != "" else np.nan for r in body]) for i, h in enumerate(header)}
    return data


@dataclass
class RunData:
    run_dir: Path
    scenario: object
    t: np.ndarray
    q: np.ndarray  # (N, 6) rad, commanded
    W: np.ndarray  # (N, 6) estimated tool wrench, base frame
    x: np.ndarray  # scan positions (m)
    y: float  # the scan line (m)
    error_mm: np.ndarray  # compensated surface error


def load_run(run_dir, robot):
    run_dir = Path(run_dir)
    if not run_dir.is_dir():
        raise InputError(f"{run_dir}: no such run directory")
    for name in REQUIRED:
        if not (run_dir / name).exists():
            raise InputError(f"{run_dir}: missing {name} (write the run with `robstiff simulate SCENARIO --out DIR`; "
                             "diagnose-run reads the compensated run)")
    sc = load_scenario(run_dir / "scenario.yaml")
    ts = read_csv(run_dir / "timeseries_compensated.csv")
    for key in ("t_s", "q1_deg", "tool_wrench_fx_N"):
        if key not in ts:
            raise InputError(f"{run_dir / 'timeseries_compensated.csv'}: missing column {key}")
    q = robot.joint_rad(np.column_stack([ts[f"q{j}_deg"] for j in range(1, 7)]))
    W = np.column_stack([ts[f"tool_wrench_{c}"] for c in ("fx_N", "fy_N", "fz_N", "mx_Nm", "my_Nm", "mz_Nm")])
    surf = read_csv(run_dir / "surface_compensated.csv")
    ok = np.isfinite(surf["error_mm"])
    if ok.sum() < 20:
        raise InputError(f"{run_dir / 'surface_compensated.csv'}: fewer than 20 scanned points")
    # one scan line: the first
    y0 = surf["y_mm"][ok][0]
    line = ok & (surf["y_mm"] == y0)
    return RunData(run_dir, sc, ts["t_s"], q, W, surf["x_mm"][line] / 1e3, float(y0) / 1e3, surf["error_mm"][line])


def signatures(run, robot):
    """Each candidate's predicted tool deviation dz(t) (m per unit parameter,
    at the run's sample times), and the cover mask: which samples' cutter
    disc covers each scan point (the surface there is the lowest the face
    went while it covered it)."""
    sc = run.scenario
    tool = robot.payload.tool_point_m
    J = kin.jacobian(robot.dh, run.q, tool)
    tau = np.einsum("nrj,nr->nj", J, run.W)
    c = 1.0 / model_stiffness(sc, robot)
    Jz = J[:, 2, :]  # the tool's vertical row
    path = planned_path(sc)
    centre = path.positions(run.t)
    R = sc.cutter.diameter_mm / 2e3
    y_scan = run.y
    cover = ((run.x[:, None] - centre[None, :, 0]) ** 2 + (y_scan - centre[None, :, 1]) ** 2) <= R * R
    d = np.einsum("nj,nj->n", Jz, c * tau)  # the model's deflection (z), m
    # parameters: (name, unit, scale to the unit, physical bounds): a cause
    # that needs an implausible size to fit is not that cause
    cand = {"loop_lag": ([np.gradient(d, run.t)], [("tau_lag", "ms", 1e3, (0.0, 0.5))])}
    for j in range(6):
        cand[f"stiffness_error_j{j + 1}"] = ([Jz[:, j] * c[j] * tau[:, j]], [(f"r{j + 1}", "%", 100.0, (-0.5, 1.0))])
    cand["lost_motion"] = ([Jz[:, j] * np.tanh(tau[:, j] / LOST_MOTION_TORQUE_NM) for j in range(3)],
                           [(f"b{j + 1}", "urad", 1e6, (0.0, 5e-4)) for j in range(3)])
    cand["joint_coupling"] = ([Jz[:, 1] * tau[:, 2] + Jz[:, 2] * tau[:, 1]],
                              [("c23", "rad/(N*m)", 1.0, (-1e-6, 1e-6))])
    cand["setup_offset"] = ([np.full(len(run.t), 1.0)], [("dz", "mm", 1e3, (-1e-3, 1e-3))])
    return {k: (np.column_stack(cols), params) for k, (cols, params) in cand.items()}, cover


def surface_of(dz, cover):
    """Surface error (m, + = cut more) the deviation dz(t) leaves at each scan point."""
    return np.where(cover, -dz[None, :], -np.inf).max(axis=1)


def _fit(cols, bounds, cover, y, rows):
    """Parameters (within their bounds) that make the surface of
    dz = cols @ theta match y on ``rows``; (theta, residual sum of squares)."""
    from scipy.optimize import least_squares

    scale = np.maximum(np.abs(cols).max(axis=0), 1e-300)
    C = cols / scale
    lo = np.array([b[0] for b in bounds]) * scale
    hi = np.array([b[1] for b in bounds]) * scale
    sub = cover[rows]

    def resid(th):
        return surface_of(C @ th, sub) - y[rows]

    best = None
    for frac in (0.0, 0.25, 0.75):  # a few starts across the box: the envelope's max is not smooth
        start = np.clip(lo + frac * (hi - lo), lo, hi)
        sol = least_squares(resid, start, bounds=(lo, hi), method="trf")
        if best is None or sol.cost < best.cost:
            best = sol
    return best.x / scale, float(2 * best.cost)


def _held_out(cols, bounds, cover, y, blocks):
    sq = 0.0
    for test in blocks:
        train = np.setdiff1d(np.arange(len(y)), test)
        th, _ = _fit(cols, bounds, cover, y, train)
        r = surface_of(cols @ th, cover[test]) - y[test]
        sq += float(r @ r)
    return float(np.sqrt(sq / len(y))) * 1e3


def trace(run, robot):
    """Forward selection over the candidate causes; returns a dict."""
    y = run.error_mm * 1e-3  # m
    cand, cover = signatures(run, robot)
    blocks = np.array_split(np.arange(len(y)), N_BLOCKS)
    rows = np.arange(len(y))
    cols = np.zeros((len(run.t), 0))
    bounds = []
    current = float(np.sqrt(np.mean(y**2))) * 1e3  # the compensator as it is: no error expected
    before, rss = current, float(y @ y)
    selected, rounds, params = [], [], {}
    while len(selected) < 2:
        results = []
        for name, (C, pnames) in cand.items():
            if name in selected:
                continue
            if C.shape[1] > 1:  # a parameter this run cannot see (no vertical effect) is left out
                norms = np.linalg.norm(C, axis=0)
                keep = norms > 1e-9 * norms.max()
                C, pnames = C[:, keep], [pn for pn, k in zip(pnames, keep) if k]
                cand[name] = (C, pnames)
            cols1 = np.hstack([cols, C])
            Xn = cols1 / np.maximum(np.linalg.norm(cols1, axis=0), 1e-300)
            if np.linalg.matrix_rank(Xn, tol=1e-8) < cols1.shape[1]:
                results.append({"name": name, "status": "not identifiable from this run"})
                continue
            b1 = bounds + [p[3] for p in pnames]
            th, rss1 = _fit(cols1, b1, cover, y, rows)
            df2 = len(y) - cols1.shape[1]
            F = ((rss - rss1) / C.shape[1]) / (rss1 / df2) if rss1 > 0 else np.inf
            p = float(stats.f.sf(F, C.shape[1], df2)) if np.isfinite(F) and F > 0 else 1.0
            results.append({"name": name, "status": "ok", "held_out_rms_mm": _held_out(cols1, b1, cover, y, blocks),
                            "f_stat": float(F), "p_value": p,
                            "params": {f"{pn} ({u})": float(v * s) for (pn, u, s, _), v in zip(pnames, th[-C.shape[1]:])}})
        rounds.append(results)
        ok = [r for r in results if r["status"] == "ok" and r["p_value"] < ALPHA
              and r["held_out_rms_mm"] <= (1 - MIN_GAIN) * current]
        if not ok:
            break
        best = min(ok, key=lambda r: r["held_out_rms_mm"])
        selected.append(best["name"])
        params[best["name"]] = best["params"]
        cols = np.hstack([cols, cand[best["name"]][0]])
        bounds = bounds + [p[3] for p in cand[best["name"]][1]]
        current = best["held_out_rms_mm"]
        _, rss = _fit(cols, bounds, cover, y, rows)
    first = [r for r in rounds[0] if r["status"] == "ok"] if rounds else []
    alike = []
    if selected:
        best = next(r for r in first if r["name"] == selected[0])
        alike = [r["name"] for r in first if r["name"] != selected[0]
                 and r["held_out_rms_mm"] <= (1 + MIN_GAIN) * best["held_out_rms_mm"]]
    return {"selected": selected, "params": params, "rounds": rounds, "held_out_rms_before_mm": before,
            "held_out_rms_after_mm": current, "also_consistent_with": alike}


def apply_fix(sc, robot, cause, params):
    """The scenario with the cause added to the compensator (or predictive on)."""
    sc = copy.deepcopy(sc)
    if cause == "loop_lag":
        sc.controller.mode = "predictive"
        return sc, "switched on predictive compensation (the error follows dF/dt: the loop's lag)"
    if cause.startswith("stiffness_error_j"):
        j = int(cause[-1]) - 1
        r = params[f"r{j + 1} (%)"] / 100.0
        k = np.array(model_stiffness(sc, robot), dtype=float)
        k[j] = k[j] / (1.0 + r)
        sc.model.joint_stiffness_Nm_per_rad = list(k)
        sc.model.identified_json = ""
        return sc, f"joint {j + 1}'s model stiffness {k[j] * (1 + r):.4g} -> {k[j]:.4g} N*m/rad"
    if cause == "lost_motion":
        b = [max(0.0, params.get(f"b{j + 1} (urad)", 0.0) * 1e-6) for j in range(3)] + [0.0, 0.0, 0.0]
        sc.model.lost_motion_rad = b
        return sc, "lost motion in the model: " + ", ".join(f"{v * 1e6:.1f}" for v in b[:3]) + " urad (joints 1-3)"
    if cause == "setup_offset":
        return sc, "none in the compensator: a constant offset is the set-up's (tool length, workpiece height)"
    if cause == "joint_coupling":
        sc.model.coupling_c23_rad_per_Nm = params["c23 (rad/(N*m))"]
        return sc, f"joint 2-3 coupling in the model: {sc.model.coupling_c23_rad_per_Nm:.3g} rad/(N*m)"
    raise ValueError(cause)


def first_round_params(found, name):
    for r in found["rounds"][0]:
        if r["name"] == name and r["status"] == "ok":
            return r["params"]
    return found["params"].get(name)


def diagnose_run(run_dir, robot, try_alternatives=True):
    """Trace, fix, rerun.  When the run cannot tell the traced cause from
    others (within 10 % of its held-out error), each of their fixes is run
    too: a second cut decides what one pass cannot.  Returns (report dict,
    the run before, the run with the best fix or None)."""
    run = load_run(run_dir, robot)
    found = trace(run, robot)
    report = {"run_dir": str(run.run_dir), **found}
    before = run_cut(run.scenario, robot, compensation=True)
    report["surface_error_before_mm"] = before.surface_error_mm
    if not found["selected"]:
        report["fix"] = "none: no cause explains the residual better than noise"
        return report, before, None
    causes = [found["selected"][0]] + (found["also_consistent_with"] if try_alternatives else [])
    trials = []
    for cause in causes:
        if cause == "setup_offset":
            continue
        fixed_sc, what = apply_fix(run.scenario, robot, cause, first_round_params(found, cause))
        res = run_cut(fixed_sc, robot, compensation=True)
        trials.append({"cause": cause, "fix": what, "surface_error_mm": res.surface_error_mm, "_run": res})
    if not trials:
        report["fix"] = apply_fix(run.scenario, robot, "setup_offset", {})[1]
        return report, before, None
    best = min(trials, key=lambda tr: tr["surface_error_mm"]["rms"])
    report["trials"] = [{k: v for k, v in tr.items() if k != "_run"} for tr in trials]
    report["cause"] = best["cause"]
    report["fix"] = best["fix"]
    report["surface_error_after_mm"] = best["surface_error_mm"]
    return report, before, best["_run"]
