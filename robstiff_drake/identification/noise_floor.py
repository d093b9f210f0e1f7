"""The noise floor of a stiffness campaign and the lack-of-fit test of a
model's held-out error against it.  Plain numpy + scipy.

The floor is the 1-sigma noise of one displacement component (mm):

  * stated by the user (``--noise-mm``: the instrument's figure for a
    displacement, i.e. loaded minus unloaded reading);
  * estimated from replicate rows: rows at the same pose under the same
    load, whose scatter about their mean is noise only (pooled variance,
    sum(n_g - 1) degrees of freedom per component).  Replicates of one pose
    share its unloaded reading, so they measure the repeatability of the
    loaded reading: if the reference is shared, the displacement's noise is
    up to sqrt(2) larger and the test below is stricter than it should be
    (it errs towards "not explained").

Lack of fit: the held-out residuals e of a linear(ised) model are a linear
map of the measurement noise, e = M y (M built from the folds: a test row's
residual is its reading minus the prediction of the fold fitted without
it).  Under the hypothesis that the model is right and the noise is the
floor, Q = |e|^2 / sigma^2 has mean tr(M S M^T) and variance
2 tr((M S M^T)^2), S the noise correlation; Q is referred to a scaled
chi-square with those two moments (Satterthwaite), or, with an estimated
floor, to an F distribution with the replicates' degrees of freedom.
Because a pose's rows may share one unloaded reading, S is taken both as
independent rows and with correlation 0.5 between the rows of a pose (the
largest a shared reference of equal noise gives), and the larger p-value is
used: the test does not call a model wrong because of that correlation.
"""

from dataclasses import dataclass

import numpy as np
from scipy import stats

from robstiff_drake.identification.cross_validation import rows_to_eq

ALPHA_LACK_OF_FIT = 0.01  # held-out error significantly above the floor at this level: not explained
SHARED_REFERENCE_CORRELATION = 0.5
MIN_REPLICATE_DOF = 6  # fewer replicate degrees of freedom per component: no estimated floor
LOAD_MATCH_REL = 1e-3  # loads equal to this fraction of their magnitude are the same load


@dataclass
class Floor:
    sigma_mm: float | None  # the floor used for the verdict
    source: str | None  # "stated", "replicates" or None
    stated_mm: float | None
    replicate_mm: float | None
    replicate_dof: int  # per component
    replicate_sets: int


def replicate_sets(campaign, groups, rows):
    """Lists of row indices (within ``rows``) measured at the same pose under the same load."""
    W = campaign.wrench
    sets = []
    for g in np.unique(groups[rows]):
        members = [r for r in rows if groups[r] == g]
        used = set()
        for i, r in enumerate(members):
            if r in used:
                continue
            scale = max(np.linalg.norm(W[r]), 1e-9)
            same = [s for s in members[i:] if s not in used and np.linalg.norm(W[s] - W[r]) <= LOAD_MATCH_REL * scale]
            used.update(same)
            if len(same) > 1:
                sets.append(same)
    return sets


def estimate_floor(campaign, groups, rows, stated_mm=None):
    """The floor from the statement and/or the replicate rows among ``rows``."""
    sets = replicate_sets(campaign, groups, rows)
    dof = sum(len(s) - 1 for s in sets)
    rep = None
    if dof >= MIN_REPLICATE_DOF:
        ss = sum(float(np.sum((campaign.disp_mm[s] - campaign.disp_mm[s].mean(axis=0)) ** 2)) for s in sets)
        rep = float(np.sqrt(ss / (3 * dof)))
    if stated_mm is not None:
        return Floor(float(stated_mm), "stated", float(stated_mm), rep, dof, len(sets))
    if rep is not None:
        return Floor(rep, "replicates", None, rep, dof, len(sets))
    return Floor(None, None, None, None, dof, len(sets))


def cv_map(X, folds, rows):
    """M with e = M y over the equations of ``rows`` (held-out residuals of a
    linear model with columns X, (3N, p), refitted in each fold)."""
    eq_all = rows_to_eq(rows)
    pos = {int(e): i for i, e in enumerate(eq_all)}
    M = np.eye(len(eq_all))
    scale = np.linalg.norm(X[eq_all], axis=0)
    scale[scale == 0] = 1.0
    Xs = X / scale
    for train, test in folds:
        te, tr = rows_to_eq(test), rows_to_eq(train)
        P = Xs[te] @ np.linalg.pinv(Xs[tr])
        M[np.ix_([pos[int(e)] for e in te], [pos[int(e)] for e in tr])] = -P
    return M


def _moments(M, groups_rows, rho):
    """(E, V) of |M eps|^2 for unit-variance noise with correlation rho within a pose."""
    if rho == 0:
        B = M @ M.T
    else:
        same = (groups_rows[:, None] == groups_rows[None, :]).astype(float)
        S_rows = (1 - rho) * np.eye(len(groups_rows)) + rho * same
        S = np.kron(S_rows, np.eye(3))
        B = M @ S @ M.T
    return float(np.trace(B)), 2.0 * float(np.sum(B * B))


@dataclass
class LackOfFit:
    p_value: float
    statistic: float  # Q / E: 1 when the held-out error is at the floor
    dof: float  # Satterthwaite degrees of freedom
    test: str
    p_below: float = 1.0  # lower tail: the held-out error significantly BELOW the floor (an overstated floor)


def lack_of_fit(resid_eq_m, X, folds, rows, groups, floor):
    """Test the held-out residuals (3N,) m against the floor (see module docstring)."""
    eq = rows_to_eq(rows)
    Q = float(resid_eq_m[eq] @ resid_eq_m[eq])
    M = cv_map(X, folds, rows)
    g_rows = np.asarray(groups)[rows]
    rhos = [0.0] + ([SHARED_REFERENCE_CORRELATION] if len(np.unique(g_rows)) < len(g_rows) else [])
    best, p_below = None, 0.0
    sigma2 = (floor.sigma_mm * 1e-3) ** 2
    for rho in rhos:
        E, V = _moments(M, g_rows, rho)
        g, h = V / (2 * E), 2 * E * E / V
        if floor.source == "replicates":
            F = (Q / (g * h)) / sigma2
            p = float(stats.f.sf(F, h, 3 * floor.replicate_dof))
            low = float(stats.f.cdf(F, h, 3 * floor.replicate_dof))
            res = LackOfFit(p, Q / (E * sigma2), h, f"F({h:.0f}, {3 * floor.replicate_dof}) against the replicates")
        else:
            p = float(stats.chi2.sf(Q / sigma2 / g, h))
            low = float(stats.chi2.cdf(Q / sigma2 / g, h))
            res = LackOfFit(p, Q / (E * sigma2), h, f"scaled chi-square, {h:.0f} degrees of freedom")
        p_below = max(p_below, low)
        if best is None or res.p_value > best.p_value:
            best = res
    best.p_below = p_below
    return best


def unexplained_mm(rms_mm, floor_mm):
    """sqrt(max(rms^2 - floor^2, 0)), or None without a floor."""
    if floor_mm is None:
        return None
    return float(np.sqrt(max(rms_mm**2 - floor_mm**2, 0.0)))
