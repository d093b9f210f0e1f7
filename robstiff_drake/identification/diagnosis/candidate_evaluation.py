"""One candidate term tested against the current model of the residual
diagnosis (identification/diagnosis/selection.py runs the search that calls
it): its held-out RMS on the pose-grouped folds with every nonlinear
parameter refitted inside each fold, its parameters on all rows, the nested
F-test and BIC for reference, the pose-clustered test (CR2 sandwich, a
Bell-McCaffrey t per contrast, Bonferroni over them;
identification/diagnosis/clustered_test.py), whether it keeps
every compliance physical and its size within the typical range, and its
correlations with the model's estimates.

The pose-clustered test needs more poses than the model has parameters: its
covariance is built from the G poses' score sums, which add to zero, so it
has rank G - 1 at most, and with G - 1 below the parameters (six springs and
the candidate) it is biased low.  Measured (studies/small_campaigns.py): on
campaigns of five poses of pure springs plus noise it named a term in 7-9 of
50, where the rule's level allows about 1 in 100 (that was with the CR1
sandwich and F(q, G - 1); the test is now corrected for few poses, but the
covariance's rank stays G - 1).  Such a candidate gets no
clustered p (nan: it cannot qualify) and ``poses_needed``, which the verdict
turns into the measurement that would decide.  The current model is kept as
least-squares projections, so a linear candidate costs one projection.
Plain numpy + scipy.
"""

from dataclasses import dataclass, field

import numpy as np
from scipy import special
from scipy import stats

from robstiff_drake.identification.diagnosis import plausibility as pl
from robstiff_drake.identification.diagnosis.confounding import correlation, design_covariance
from robstiff_drake.identification.diagnosis.cross_validation import clustered_cov, rows_to_eq
from robstiff_drake.identification.diagnosis.terms import GAUSS_NEWTON, GRID, fit_model, held_out, rms_mm, term_columns

RANK_TOL = 1e-6
GN_CANDIDATE_ITER = 3  # Gauss-Newton steps for a candidate (the selected model is iterated to convergence)

@dataclass
class CandidateResult:
    name: str
    source: str
    status: str  # "ok", "not identifiable", "skipped"
    reason: str = ""
    rms_mm: float = float("nan")  # held out, added to the current model
    f_stat: float = float("nan")
    p_value: float = float("nan")
    delta_bic: float = float("nan")
    p_grouped: float = float("nan")  # pose-clustered Wald test of its parameters, all rows
    params: dict = field(default_factory=dict)  # "name (unit)" -> value, fitted on all rows
    values: np.ndarray = None  # SI
    grid: float = None
    physical: bool = None  # the fit with it keeps every positive compliance positive (None: not checked)
    plausible: bool = None  # its size is within the typical range (None: not checked)
    plausibility: str = ""
    negative_joints: list = field(default_factory=list)  # 1-based joints it drives negative
    all_positive: bool = None  # with it every free joint's compliance is positive
    correlations: dict = field(default_factory=dict)  # joint or term -> correlation of the estimates, fitted together
    forbidden: bool = None  # needs a sign physics forbids (never added)
    fold_gains: np.ndarray = None  # per fold: 1 - its held-out RMS / the current model's
    refusal: str = ""  # why a candidate that fits was not added (a lead)
    excess: float = 1.0  # how many times its typical range its size is (plausibility.excess)
    poses_needed: int = 0  # > 0: the campaign has fewer poses than this, too few for the clustered test to decide


class Projection:
    """The current model's least-squares fit on some equations, kept so that
    a candidate's columns are added at the cost of a projection (the
    Frisch-Waugh-Lovell form of the joint fit: exact)."""

    def __init__(self, X, target, eq_fit, eq_pred=None):
        Xf = X[eq_fit]
        self.scale = np.linalg.norm(Xf, axis=0)
        self.scale[self.scale == 0] = 1.0
        self.Q, self.R = np.linalg.qr(Xf / self.scale)
        y = target[eq_fit]
        self.coef_s = np.linalg.solve(self.R, self.Q.T @ y)
        self.r = y - self.Q @ (self.Q.T @ y)
        self.eq_fit, self.eq_pred = eq_fit, eq_pred
        if eq_pred is not None:
            self.Xp = X[eq_pred] / self.scale
            self.pred0 = self.Xp @ self.coef_s

    def add(self, Z):
        """(term coefficients (SI), prediction on eq_pred (without the offset), SSE on eq_fit)."""
        Zf = Z[self.eq_fit]
        zn = np.linalg.norm(Zf, axis=0)
        zn[zn == 0] = 1.0
        Zs = Zf / zn
        QtZ = self.Q.T @ Zs
        Zperp = Zs - self.Q @ QtZ
        g, *_ = np.linalg.lstsq(Zperp, self.r, rcond=None)
        res = self.r - Zperp @ g
        pred = None
        if self.eq_pred is not None:
            pred = self.pred0 + (Z[self.eq_pred] / zn) @ g - self.Xp @ np.linalg.solve(self.R, QtZ @ g)
        return g / zn, pred, float(res @ res)

    def rank_added(self, Z):
        """How many independent directions Z's columns add to the fit's."""
        Zf = Z[self.eq_fit]
        zn = np.linalg.norm(Zf, axis=0)
        if np.any(zn == 0):
            return 0
        Zs = Zf / zn
        Zperp = Zs - self.Q @ (self.Q.T @ Zs)
        return int(np.sum(np.linalg.svd(Zperp, compute_uv=False) > RANK_TOL))


@dataclass
class State:
    """The current model: its held-out residual, fold fits and full fit."""

    terms: list
    resid: np.ndarray  # (3N,) held out, zero outside the rows
    rms_mm: float
    fold_fits: list
    full: object  # ModelFit on all rows
    rss: float
    folds_proj: list  # Projection per fold (fit on its training rows, predict its test rows)
    full_proj: Projection  # on all rows


def model_state(ctx, terms, rows, folds, gidx):
    resid, fits = held_out(ctx, terms, folds)
    full = fit_model(ctx, terms, rows)
    eq = rows_to_eq(rows)
    full_proj = Projection(full.X, ctx.b - full.offset, eq)
    folds_proj = [Projection(f.X, ctx.b - f.offset, rows_to_eq(train), rows_to_eq(test))
                  for f, (train, test) in zip(fits, folds)]
    return State(list(terms), resid, rms_mm(resid[eq]), fits, full, float(full_proj.r @ full_proj.r), folds_proj,
                 full_proj)


def _label(t):
    return [f"{n} ({u})" for n, u, _ in t.params]


def evaluate(ctx, rows, folds, gidx, state, t, gain_needed):
    """One candidate added to the current model (see module docstring).  The
    pose-clustered Wald test is computed only when the held-out RMS falls to
    ``gain_needed`` (mm) or below (otherwise the candidate cannot qualify)."""
    reason = t.needs(ctx) if t.needs else None
    if reason:
        return CandidateResult(t.name, t.source, "skipped", reason)
    eq = rows_to_eq(rows)
    p0, pe, n_eq = state.full.X.shape[1], len(t.params), len(eq)
    if n_eq - p0 - pe < 3 * (p0 + pe):
        return CandidateResult(t.name, t.source, "skipped", f"{pe} more parameters need more than the {len(rows)} "
                               "measurements (3 equations each)")
    grid = t.grid(ctx) if t.kind == GRID else [None]
    added = state.full_proj.rank_added(term_columns(ctx, t, state.full.c, None, grid[0])[0])
    if added < pe:
        return CandidateResult(t.name, t.source, "not identifiable",
                               f"its {pe} column(s) add only {added} independent direction(s) to the model's: "
                               "the campaign cannot separate it")
    resid = np.zeros(3 * ctx.n)
    for (train, test), fk, pk in zip(folds, state.fold_fits, state.folds_proj):
        te = rows_to_eq(test)
        if t.kind == GAUSS_NEWTON:
            pred = fit_model(ctx, state.terms + [t], train, grid=fk.grid, max_iter=GN_CANDIDATE_ITER).predict(test)
        else:
            best = None
            for g in grid:
                _, pred_g, sse = pk.add(term_columns(ctx, t, fk.c, None, g)[0])
                if best is None or sse < best[0]:
                    best = (sse, pred_g)
            pred = best[1] + fk.offset[te]
        resid[te] = ctx.b[te] - pred
    rms = rms_mm(resid[eq])
    fold_gains = np.array([1 - rms_mm(resid[rows_to_eq(te)]) / max(rms_mm(state.resid[rows_to_eq(te)]), 1e-300)
                           for _, te in folds])
    # all rows: parameters, F-test, BIC and (if it can qualify) the pose-clustered Wald test
    geq = np.repeat(gidx, 3)
    if t.kind == GAUSS_NEWTON:
        f = fit_model(ctx, state.terms + [t], rows, max_iter=GN_CANDIDATE_ITER)
        r = ctx.b[eq] - f.predict(rows)
        rss1, values, g_best, Zf = float(r @ r), f.values[t.name], None, None
    else:
        best = None
        for g in grid:
            Zf = term_columns(ctx, t, state.full.c, None, g)[0]
            coef, _, sse = state.full_proj.add(Zf)
            if best is None or sse < best[0]:
                best = (sse, coef, g, Zf)
        rss1, values, g_best, Zf = best
    p_grouped, checks = float("nan"), {}
    if rms <= gain_needed:
        if t.kind == GAUSS_NEWTON:
            X, y, sl = f.X[eq], ctx.b[eq] - f.offset[eq], f.slices[t.name]
        else:
            X = np.hstack([state.full.X, Zf])[eq]
            y, sl = ctx.b[eq] - state.full.offset[eq], slice(p0, p0 + pe)
        cf = clustered_cov(X, y, geq)
        coef, cov, G = cf.coef, cf.cov, cf.G
        p_grouped = cf.p(sl)
        if G - 1 < X.shape[1]:  # too few poses for the model's parameters: the test cannot decide (module docstring)
            p_grouped, checks["poses_needed"] = float("nan"), X.shape[1] + 1
        checks.update(physical_and_plausible(ctx, t, state, coef, cov, G, sl, g_best))
        checks["correlations"] = _correlations(ctx, state, X, sl)
    df2 = n_eq - p0 - pe
    F = ((state.rss - rss1) / pe) / (rss1 / df2) if rss1 > 0 else np.inf
    p = float(special.fdtrc(pe, df2, F)) if np.isfinite(F) else 0.0
    dbic = n_eq * np.log(rss1 / state.rss) + pe * np.log(n_eq) if state.rss > 0 and rss1 > 0 else float("nan")
    params = {lab: float(v * s) for lab, (_, _, s), v in zip(_label(t), t.params, values)}
    return CandidateResult(t.name, t.source, "ok", "", rms, float(F), p, float(dbic), p_grouped, params,
                           np.asarray(values), g_best, fold_gains=fold_gains, **checks)


def _correlations(ctx, state, X, sl):
    """Correlation of the candidate's estimates (columns ``sl`` of X) with
    each free joint's compliance and each term of the current model."""
    cov = design_covariance(X)
    idx = np.arange(sl.start, sl.stop)
    out = {f"stiffness_j{j + 1}": correlation(cov, idx, [i]) for i, j in enumerate(ctx.free)}
    for name, s in state.full.slices.items():
        out[name] = correlation(cov, idx, np.arange(s.start, s.stop))
    return out


def physical_and_plausible(ctx, t, state, coef, cov, G, sl, g=None):
    """Does the fit with term t keep the model physical (no compliance that
    was positive turns negative) and is t's size plausible (its estimate
    within the typical range; plausibility.check)?  Returns CandidateResult
    fields."""
    nf = len(ctx.free)
    c = ctx.c_from(coef[:nf])
    negative = [int(j) + 1 for j in ctx.free if c[j] <= 0 < state.full.c[j]]
    half = np.zeros(len(coef)) if cov is None else \
        stats.t.ppf(0.975, max(G - 1, 1)) * np.sqrt(np.maximum(np.diag(cov), 0.0))
    ok, why = pl.check_term(t, coef[sl], half[sl], {"ctx": ctx, "c": c, "g": g})
    if negative:
        why = (f"with it the compliance of joint(s) {', '.join(map(str, negative))} turns negative (non-physical)"
               + (f"; {why}" if why else ""))
    forbid = bool(negative) or (not ok and pl.forbidden(why))
    beyond = pl.excess(t.plausible, coef[sl], {"ctx": ctx, "c": c, "g": g}) if not ok and not forbid else 1.0
    return {"physical": not negative, "plausible": bool(ok), "plausibility": why, "negative_joints": negative,
            "all_positive": bool(np.all(c[ctx.free] > 0)), "forbidden": forbid, "excess": beyond}


def implausible_terms(ctx, state, rows, geq):
    """{name: reason} of the model's terms whose size at the full fit is
    beyond the typical range or forbidden (plausibility.check)."""
    eq = rows_to_eq(rows)
    f = state.full
    cf = clustered_cov(f.X[eq], ctx.b[eq] - f.offset[eq], geq)
    coef, cov, G = cf.coef, cf.cov, cf.G
    half = np.zeros(len(coef)) if cov is None else \
        stats.t.ppf(0.975, max(G - 1, 1)) * np.sqrt(np.maximum(np.diag(cov), 0.0))
    out = {}
    for t in state.terms:
        sl = f.slices[t.name]
        ok, why = pl.check_term(t, f.values[t.name], half[sl], {"ctx": ctx, "c": f.c, "g": f.grid.get(t.name)})
        if not ok:
            out[t.name] = why
    return out
