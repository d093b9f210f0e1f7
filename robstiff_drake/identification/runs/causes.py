"""How the causes of a machining run's residual are fitted and tested
(identification/runs/diagnosis.py, whose docstring describes the
method; the candidates' columns: identification/runs/candidate_causes.py): the face's envelope, the nested fits,
forward selection, the noise floor and the damping's profile.  Plain numpy
and scipy."""

from dataclasses import dataclass, replace

import numpy as np
from scipy.optimize import least_squares

from robstiff_drake.errors import InputError
from robstiff_drake.identification.runs import tables as rt
from robstiff_drake.identification.runs import scan_statistics as ss
from robstiff_drake.identification.runs.candidate_causes import (  # noqa: F401 (re-exported: callers take them here)
    BIAS_DIRECTION_TOL, FORCE_BIAS_N, LOOP, LOST_MOTION_CATALOGUE_RAD, LOST_MOTION_LIMIT_RAD, Candidate, Param,
    candidates, loop_lag_ms,
)


ALPHA = 1e-3  # per test; about 10 causes are tried per round
SIZE_FACTOR = 1.0  # a named cause changes the surface by at least this many noise floors (RMS)
MAX_CAUSES = 2
MIN_FLOOR_MM = 5e-4  # below half a micrometre a machining question is not decided
EXPLAIN_ALPHA = 0.01  # the residual is consistent with the floor unless chi2 says otherwise at this level
NO_DATA = 0.1  # of the floor: what a parameter must move the surface by over its range to be kept
NOISE_DISAGREE = 2.0  # warn when the stated and the estimated noise differ by more than this factor
REBUILDS = 4  # refits of a cause not linear in its parameters (lost motion: the crossing), each at the last's
REBUILD_RTOL = 0.01  # ... until its parameters move by less than 1 %
ALIKE = 1.0  # causes whose mean-square residuals differ by less than ALIKE x floor^2 are alike


def _physical(c, k, theta):
    """{name: SI value} of a cause's fitted parameters (kept indices k)."""
    if c.basis is None:
        return {c.params[i].name: float(v) for i, v in zip(k, theta)}
    full = np.zeros(len(c.params))
    full[list(k)] = theta
    return dict(zip(c.basis_names, (c.basis @ full).tolist()))


class Envelope:
    """The face a deviation dz(t) leaves along the scan: each point is the
    lowest the cutter's face (radius R, centred on the program's tool point,
    moved by the arm's own motion error ``sig.dz_motion_m``) went while
    covering it."""

    def __init__(self, scan, sig, cutter_diameter_mm):
        x, y = scan.x_mm / 1e3, scan.y_mm / 1e3
        p = sig.p_nominal_m
        R = cutter_diameter_mm / 2e3
        cover = (x[:, None] - p[None, :, 0]) ** 2 + (y[:, None] - p[None, :, 1]) ** 2 <= R * R
        self.covered = cover.any(axis=1)  # scan points the pass went over
        cover = cover[self.covered]
        self.samples = np.flatnonzero(cover.any(axis=0))  # samples that cover a scan point
        cover = cover[:, self.samples]
        # the covering (point, sample) pairs, point by point: the envelope is a minimum over each point's run
        rows, cols = np.nonzero(cover)
        self._pair_samples = self.samples[cols]
        self._starts = np.flatnonzero(np.r_[True, np.diff(rows) > 0])
        z = p[self._pair_samples, 2]
        self.base = np.minimum.reduceat(z, self._starts)  # the programmed face
        self._Z = z + sig.dz_motion_m[self._pair_samples]

    def surface(self, dz):
        """Surface error (m, + = cut more) at the covered scan points."""
        return self.base - np.minimum.reduceat(self._Z + dz[self._pair_samples], self._starts)


@dataclass
class Fit:
    causes: list  # Candidate
    keep: list  # per cause: indices of its parameters kept
    theta: np.ndarray  # SI, concatenated
    rss: float
    residual: np.ndarray  # m

    def columns(self):
        return np.hstack([c.columns[:, k] for c, k in zip(self.causes, self.keep)]) if self.causes else None

    def params(self):
        return [p for c, k in zip(self.causes, self.keep) for p in (c.params[i] for i in k)]

    def slices(self):
        out, i = [], 0
        for k in self.keep:
            out.append(slice(i, i + len(k)))
            i += len(k)
        return out


def _solve(env, cols, params, y, starts):
    """Bounded least squares of surface(cols @ theta) = y from each start;
    (theta SI, rss m^2) of the best.  Solved for each parameter's fraction
    of its range and residuals in mm, so that the solver's tolerances (made
    for numbers of order one) stop it at the optimum, not at the start."""
    lo = np.array([p.lo for p in params])
    span = np.array([p.hi for p in params]) - lo

    def resid(u):
        return (env.surface(cols @ (lo + span * u)) - y) * 1e3

    best = None
    for start in starts:
        u0 = np.clip((np.asarray(start, dtype=float) - lo) / span, 0.0, 1.0)
        sol = least_squares(resid, u0, bounds=(0.0, 1.0), method="trf", x_scale="jac")
        if best is None or sol.cost < best.cost:
            best = sol
    return lo + span * best.x, float(2.0 * best.cost) * 1e-6


def fit_model(env, causes, keep, y, base=None):
    """Fit the causes (their kept parameters) to y.  ``base``: the fit of
    the model this one extends (its causes first): its solution, with the
    new parameters at zero, is the first start, so the extension is never
    worse; the new parameters also start at a quarter and three quarters of
    their range, and all parameters start once more at their nominal
    values (a fit through the face's envelope has local minima: an old
    parameter that absorbed what the new one explains may not come back
    from where the smaller model left it)."""
    fit = Fit(list(causes), [list(k) for k in keep], np.zeros(0), float(y @ y), -y)
    params = fit.params()
    if not params:
        return fit
    n_old = len(base.theta) if base is not None else 0
    head = base.theta if base is not None else np.zeros(0)
    new = params[n_old:]
    starts = [np.r_[head, [p.nominal for p in new]]]
    for frac in (0.25, 0.75):
        starts.append(np.r_[head, [p.lo + frac * (p.hi - p.lo) for p in new]])
    if n_old:
        starts.append(np.array([p.nominal for p in params]))
    fit.theta, fit.rss = _solve(env, fit.columns(), params, y, starts)
    fit.residual = env.surface(fit.columns() @ fit.theta) - y
    return fit


def without(fit, i, value=None):
    """fit.theta with cause i's parameters set to zero (or parameter ``i``, a flat index, to ``value``)."""
    th = fit.theta.copy()
    if value is None:
        th[fit.slices()[i]] = 0.0
    else:
        th[i] = value
    return th


def rms(v):
    return float(np.sqrt(np.mean(np.square(v)))) if np.size(v) else 0.0


def _no_data(env, fit, floor_m, first_new):
    """Flat indices (>= first_new) of parameters that cannot move the surface
    by NO_DATA x the floor over their whole range."""
    cols, params = fit.columns(), fit.params()
    out = []
    for i in range(first_new, len(params)):
        s_lo = env.surface(cols @ without(fit, i, params[i].lo))
        s_hi = env.surface(cols @ without(fit, i, params[i].hi))
        if rms(s_hi - s_lo) < NO_DATA * floor_m:
            out.append(i)
    return out


def _identifiable(env, cols):
    X = cols[env.samples]
    norms = np.linalg.norm(X, axis=0)
    if np.any(norms == 0):
        return False
    return np.linalg.matrix_rank(X / norms, tol=1e-8) == X.shape[1]


def try_cause(env, base, cand, y, floor_m, stats_ctx):
    """Extend ``base`` by ``cand``: the fit, its test and whether it is named."""
    row = {"name": cand.name, "what": cand.what}
    keep = list(range(len(cand.params)))
    # a parameter whose column is zero over the covered samples cannot act here
    norms = np.linalg.norm(cand.columns[env.samples], axis=0)
    keep = [i for i in keep if norms[i] > 1e-9 * max(norms.max(), 1e-300)]
    n_old = len(base.theta)
    while True:
        if not keep:
            row["status"] = "no data in this run (the cause cannot change the surface here)"
            return row, None
        causes, keeps = base.causes + [cand], base.keep + [keep]
        trial = Fit(causes, keeps, np.zeros(0), 0.0, None)
        if not _identifiable(env, trial.columns()):
            row["status"] = "not identifiable from this run (its deviation is a combination of the model's)"
            return row, None
        fit = fit_model(env, causes, keeps, y, base)
        dropped = _no_data(env, fit, floor_m, n_old)
        if not dropped:
            break
        keep = [k for j, k in enumerate(keep) if n_old + j not in dropped]
    if cand.rebuild is not None:  # a cause not linear in its parameters: its columns where the fit put them
        for _ in range(REBUILDS):
            full = np.zeros(len(cand.params))
            full[keep] = fit.theta[n_old:]
            cand = replace(cand, columns=cand.rebuild(full))
            prev = fit.theta[n_old:].copy()
            fit = fit_model(env, base.causes + [cand], base.keep + [keep], y, base)
            if np.allclose(fit.theta[n_old:], prev, rtol=REBUILD_RTOL, atol=0.0):
                break
    n = y.size
    n_eff, tau = ss.effective_points(fit.residual * 1e3, stats_ctx["segs"], stats_ctx["length_mm"],
                                     stats_ctx["cutter_mm"])
    F, p = ss.f_test(base.rss, fit.rss, len(keep), len(fit.theta), n, n_eff)
    # what the cause adds: how far the face it fits moves from the smaller model's own fit (a cause that
    # only trades places with one already in the model, as an offset and a stiffness error on a steady
    # cut, moves it little however large its parameter)
    before = env.surface(base.columns() @ base.theta) if base.causes else np.zeros(n)
    size = rms(env.surface(fit.columns() @ fit.theta) - before)
    mine = fit.theta[fit.slices()[-1]]
    ps = [cand.params[i] for i in keep]
    at_bound = [q.name for q, v in zip(ps, mine)
                if (abs(v - q.hi) <= 1e-6 * (q.hi - q.lo)) or (not q.lo_is_limit and abs(v - q.lo) <= 1e-6 * (q.hi - q.lo))]
    row.update(status="ok", rms_mm=rms(fit.residual) * 1e3, f_stat=F, p_value=p, n_effective=n_eff,
               size_mm=size * 1e3, params={f"{q.name} ({q.unit})": float(v * q.scale) for q, v in zip(ps, mine)},
               dropped_no_data=[cand.params[i].name for i in range(len(cand.params)) if i not in keep],
               at_bound=at_bound)
    reasons = []
    if p >= ALPHA:
        reasons.append(f"p = {p:.2g} >= {ALPHA:g}")
    if size < SIZE_FACTOR * floor_m:
        reasons.append(f"changes the surface by {size * 1e3:.4f} mm, below the noise floor")
    if at_bound:
        reasons.append(f"needs {', '.join(at_bound)} at its plausibility bound")
    row["named"] = not reasons
    row["why_not"] = "; ".join(reasons)
    return row, fit


def noise_floor(scan, segs, stated_mm, warnings):
    """(floor mm, source, stated mm or None, estimated mm or None)."""
    estimated = ss.noise_from_scan(scan.error_mm, segs)
    stated, source = stated_mm, "stated (--noise-mm)"
    if stated is None and scan.noise_mm is not None:
        stated, source = scan.noise_mm, f"stated ({rt.SCAN} noise_mm)"
    if stated is None:
        if estimated is None:
            raise InputError(f"{scan.path}: too few neighbouring points to estimate the scan's noise; "
                             "state it with --noise-mm SIGMA")
        floor, source = estimated, "estimated from the scan (second differences)"
    else:
        floor = stated
        if estimated is not None and stated > 0 and not 1 / NOISE_DISAGREE <= estimated / stated <= NOISE_DISAGREE:
            warnings.append(f"the scan's own noise ({estimated:.4f} mm, from its second differences) differs from "
                            f"the stated {stated:.4f} mm by more than {NOISE_DISAGREE:g}x")
    if floor < MIN_FLOOR_MM:
        warnings.append(f"noise floor {floor:.5f} mm raised to {MIN_FLOOR_MM} mm (nothing finer is decided)")
        floor = MIN_FLOOR_MM
    return floor, source, stated, estimated


def trace(env, cands, y, floor_m, stats_ctx, base):
    """Forward selection of causes on top of ``base`` (the loop's tracking
    error: always in the model); returns (rounds, final Fit)."""
    fit = base
    rounds = []
    while len(fit.causes) - len(base.causes) < MAX_CAUSES:
        results, fits = [], {}
        for cand in cands:
            if any(c.name == cand.name for c in fit.causes):
                continue
            row, f = try_cause(env, fit, cand, y, floor_m, stats_ctx)
            results.append(row)
            if f is not None:
                fits[cand.name] = f
        rounds.append(results)
        named = [r for r in results if r.get("named")]
        if not named:
            break
        fit = fits[min(named, key=lambda r: fits[r["name"]].rss)["name"]]
    return rounds, fit


def alternatives(env, cands, y, floor_m, stats_ctx, final):
    """Models as good as the final one with one named cause swapped for
    another candidate: its fit's mean square within ALIKE x floor^2 of the
    final's, changing the surface by at least the floor, no parameter at a
    plausibility bound.  [(row, Fit)], the row naming the cause replaced."""
    out = []
    names = [c.name for c in final.causes]
    for i, c in enumerate(final.causes):
        if c.name == LOOP:
            continue  # always in the model
        rest = Fit([], [], np.zeros(0), float(y @ y), -y)
        others = [(cc, k) for j, (cc, k) in enumerate(zip(final.causes, final.keep)) if j != i]
        if others:
            rest = fit_model(env, [o[0] for o in others], [o[1] for o in others], y)
        for cand in cands:
            if cand.name in names:
                continue
            row, f = try_cause(env, rest, cand, y, floor_m, stats_ctx)
            if f is None or row["at_bound"] or row["size_mm"] < SIZE_FACTOR * floor_m * 1e3:
                continue
            if (f.rss - final.rss) / y.size <= ALIKE * floor_m**2:
                row["instead_of"] = c.name
                out.append((row, f))
    return out


def cause_params(fit):
    """{cause name: {param (unit): value}} of a fit."""
    out = {}
    for c, k, sl in zip(fit.causes, fit.keep, fit.slices()):
        if c.basis is not None:  # physical parameters, in the unit of the fitted ones
            out[c.name] = {f"{n} ({c.params[0].unit})": v * c.params[0].scale
                           for n, v in _physical(c, k, fit.theta[sl]).items()}
            continue
        out[c.name] = {f"{c.params[i].name} ({c.params[i].unit})": float(v * c.params[i].scale)
                       for i, v in zip(k, fit.theta[sl])}
    return out


def si_params(fit):
    out = {}
    for c, k, sl in zip(fit.causes, fit.keep, fit.slices()):
        out[c.name] = _physical(c, k, fit.theta[sl])
    return out
