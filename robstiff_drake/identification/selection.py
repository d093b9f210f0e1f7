"""Sparse selection of terms by grouped cross-validation: forward steps that
add the candidate which earns its place on held-out poses, then a backward
check that drops any that no longer does.  Plain numpy + scipy.

Each round tries every candidate not yet in the model (the named library and
the dictionary together) and measures, on the same pose-grouped folds:

  * its held-out RMS (all displacement components; every nonlinear parameter
    refitted inside each fold, see identification/terms.py);
  * a grouped test of its held-out gain: a one-sided paired t-test over
    poses of the held-out squared error with and without it;
  * for reference, a nested F-test on all rows and the change in BIC (these
    treat rows as independent; the decision does not use them).

A candidate qualifies when its grouped test passes at ALPHA_ROUND divided
by the number of candidates tried in the round (Bonferroni) and it lowers
the held-out RMS by MIN_GAIN of the current value (10 % for a named effect,
5 % for a dictionary term).  The best qualifying named effect is preferred
unless a dictionary term beats its held-out RMS by more than
NAMED_PREFERENCE.  A candidate whose columns the campaign cannot separate
from the model's (rank) is "not identifiable" and never selected; one that
needs a column the file lacks, or more parameters than the data support, is
skipped, with the reason.
"""

from dataclasses import dataclass, field

import numpy as np
from scipy import stats

from robstiff_drake.identification.cross_validation import grouped_gain_test, per_group_sse, rows_to_eq
from robstiff_drake.identification.terms import GAUSS_NEWTON, GRID, fit_model, held_out, lstsq, rms_mm, term_columns

ALPHA_ROUND = 0.01
MIN_GAIN = {"library": 0.10, "dictionary": 0.05}
NAMED_PREFERENCE = 0.05
MIN_KEEP_GAIN = 0.02  # backward check: a kept term must still lower the held-out RMS by this much
MAX_LIBRARY = 3
MAX_TERMS = 5
RANK_TOL = 1e-6


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
    p_grouped: float = float("nan")
    params: dict = field(default_factory=dict)  # "name (unit)" -> value, fitted on all rows
    values: np.ndarray = None  # SI
    grid: float = None


@dataclass
class State:
    """The current model: its held-out residual, fold fits and full fit."""

    terms: list
    resid: np.ndarray  # (3N,) held out, zero outside the rows
    rms_mm: float
    fold_fits: list
    full: object  # ModelFit on all rows
    sse: np.ndarray  # held-out SSE per pose
    rss: float
    basis: np.ndarray  # orthonormal basis of the full fit's columns on the rows


def model_state(ctx, terms, rows, fold_rows, gidx):
    resid, fits = held_out(ctx, terms, fold_rows, rows)
    full = fit_model(ctx, terms, rows)
    eq = rows_to_eq(rows)
    r = ctx.b[eq] - full.predict(rows)
    X = full.X[eq]
    Q, _ = np.linalg.qr(X / np.maximum(np.linalg.norm(X, axis=0), 1e-300))
    return State(list(terms), resid, rms_mm(resid[eq]), fits, full, per_group_sse(resid[eq], gidx), float(r @ r), Q)


def _label(t):
    return [f"{n} ({u})" for n, u, _ in t.params]


def evaluate(ctx, rows, fold_rows, gidx, state, t):
    """One candidate added to the current model (see module docstring)."""
    reason = t.needs(ctx) if t.needs else None
    if reason:
        return CandidateResult(t.name, t.source, "skipped", reason)
    eq = rows_to_eq(rows)
    p0, pe, n_eq = state.full.X.shape[1], len(t.params), len(eq)
    if n_eq - p0 - pe < 3 * (p0 + pe):
        return CandidateResult(t.name, t.source, "skipped", f"{pe} more parameters need more than the {len(rows)} "
                               "measurements (3 equations each)")
    grid = t.grid(ctx) if t.kind == GRID else [None]
    Z0, _ = term_columns(ctx, t, state.full.c, None, grid[0])
    Z = Z0[eq]
    norms = np.linalg.norm(Z, axis=0)
    added = 0
    if np.all(norms > 0):
        Zs = Z / norms
        Zp = Zs - state.basis @ (state.basis.T @ Zs)
        added = int(np.sum(np.linalg.svd(Zp, compute_uv=False) > RANK_TOL))
    if added < pe:
        return CandidateResult(t.name, t.source, "not identifiable",
                               f"its {pe} column(s) add only {added} independent direction(s) to the model's: "
                               "the campaign cannot separate it")
    resid = np.zeros(3 * ctx.n)
    for test, fk in zip(fold_rows, state.fold_fits):
        train = np.setdiff1d(rows, test)
        te, tr = rows_to_eq(test), rows_to_eq(train)
        if t.kind == GAUSS_NEWTON:
            pred = fit_model(ctx, state.terms + [t], train, grid=fk.grid).predict(test)
        else:
            best = None
            for g in grid:
                Zk, _ = term_columns(ctx, t, fk.c, None, g)
                X = np.hstack([fk.X, Zk])
                coef = lstsq(X[tr], ctx.b[tr] - fk.offset[tr])
                sse = 0.0
                if len(grid) > 1:
                    r = ctx.b[tr] - fk.offset[tr] - X[tr] @ coef
                    sse = float(r @ r)
                if best is None or sse < best[0]:
                    best = (sse, X[te] @ coef + fk.offset[te])
            pred = best[1]
        resid[te] = ctx.b[te] - pred
    rms = rms_mm(resid[eq])
    sse_groups = per_group_sse(resid[eq], gidx)
    p_grouped, _ = grouped_gain_test(state.sse, sse_groups)
    # all rows: parameters, F-test and BIC
    if t.kind == GAUSS_NEWTON:
        f = fit_model(ctx, state.terms + [t], rows)
        r = ctx.b[eq] - f.predict(rows)
        rss1, values, g_best = float(r @ r), f.values[t.name], None
    else:
        best = None
        for g in grid:
            Zf, _ = term_columns(ctx, t, state.full.c, None, g)
            X = np.hstack([state.full.X, Zf])
            coef = lstsq(X[eq], ctx.b[eq] - state.full.offset[eq])
            r = ctx.b[eq] - state.full.offset[eq] - X[eq] @ coef
            if best is None or r @ r < best[0]:
                best = (float(r @ r), coef[p0:], g)
        rss1, values, g_best = best
    df2 = n_eq - p0 - pe
    F = ((state.rss - rss1) / pe) / (rss1 / df2) if rss1 > 0 else np.inf
    p = float(stats.f.sf(F, pe, df2)) if np.isfinite(F) else 0.0
    dbic = n_eq * np.log(rss1 / state.rss) + pe * np.log(n_eq) if state.rss > 0 and rss1 > 0 else float("nan")
    params = {lab: float(v * s) for lab, (_, _, s), v in zip(_label(t), t.params, values)}
    return CandidateResult(t.name, t.source, "ok", "", rms, float(F), p, float(dbic), p_grouped, params,
                           np.asarray(values), g_best)


def _qualifies(r, current_rms, m):
    return (r.status == "ok" and r.p_grouped < ALPHA_ROUND / max(m, 1)
            and r.rms_mm <= (1 - MIN_GAIN[r.source]) * current_rms)


def _choose(qualified):
    lib = [r for r in qualified if r.source == "library"]
    dic = [r for r in qualified if r.source == "dictionary"]
    best_lib = min(lib, key=lambda r: r.rms_mm) if lib else None
    best_dic = min(dic, key=lambda r: r.rms_mm) if dic else None
    if best_lib and (best_dic is None or best_lib.rms_mm <= (1 + NAMED_PREFERENCE) * best_dic.rms_mm):
        return best_lib
    return best_dic


@dataclass
class SearchResult:
    state: State
    rms_before_mm: float
    rounds: list  # per round, the list of CandidateResult
    n_hypotheses: int  # candidates tested (status ok) over all rounds
    added: list  # [(name, held-out RMS before, after)]
    dropped: list  # names dropped by the backward check
    rms_without_mm: dict  # kept term -> held-out RMS of the final model without it


def search(ctx, rows, fold_rows, terms_by_name):
    """Forward selection over ``terms_by_name`` (library and dictionary), then the backward check."""
    gidx = np.unique(ctx.groups[rows], return_inverse=True)[1]
    state = model_state(ctx, [], rows, fold_rows, gidx)
    rms_before = state.rms_mm
    rounds, added, dropped, n_tried = [], [], [], 0
    while len(state.terms) < MAX_TERMS:
        names = {t.name for t in state.terms}
        n_lib = sum(t.source == "library" for t in state.terms)
        pool = [t for t in terms_by_name.values() if t.name not in names
                and (t.source != "library" or n_lib < MAX_LIBRARY)]
        if not pool:
            break
        results = [evaluate(ctx, rows, fold_rows, gidx, state, t) for t in pool]
        rounds.append(results)
        m = sum(r.status == "ok" for r in results)
        n_tried += m
        best = _choose([r for r in results if _qualifies(r, state.rms_mm, m)])
        if best is None:
            break
        new = model_state(ctx, state.terms + [terms_by_name[best.name]], rows, fold_rows, gidx)
        added.append((best.name, state.rms_mm, new.rms_mm))
        state = new
    without = {}
    while len(state.terms) > 1:
        trial = {}
        for t in state.terms:
            s = model_state(ctx, [u for u in state.terms if u is not t], rows, fold_rows, gidx)
            p, _ = grouped_gain_test(s.sse, state.sse)
            trial[t.name] = (s, p, 1 - state.rms_mm / s.rms_mm)
        weak = [(gain, name) for name, (s, p, gain) in trial.items()
                if p > ALPHA_ROUND / len(state.terms) or gain < MIN_KEEP_GAIN]
        if not weak:
            without = {name: s.rms_mm for name, (s, _, _) in trial.items()}
            break
        name = min(weak)[1]
        dropped.append(name)
        state = trial[name][0]
    if len(state.terms) == 1:
        without = {state.terms[0].name: rms_before}
    return SearchResult(state, rms_before, rounds, n_tried, added, dropped, without)
