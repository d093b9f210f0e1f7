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

from robstiff_drake.identification.diagnosis.cross_validation import rows_to_eq

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
    stated_by: str | None = None  # where a stated floor came from, in words ("stated (--noise-mm)", the file's line)

    @property
    def source_text(self):
        """Where the floor came from, in words (the JSON's noise_floor_source
        and the report's), or None without a floor."""
        if self.source == "stated":
            return self.stated_by or "stated"
        if self.source == "replicates":
            return f"estimated from {self.replicate_sets} sets of replicate rows ({self.replicate_dof} dof)"
        return None


def replicate_sets(campaign, groups, rows):
    """Lists of row indices (within ``rows``) measured at the same pose under
    the same load: the rows sorted by pose and load, a set being a run of
    consecutive rows whose load is within LOAD_MATCH_REL of the previous
    one's (vectorised: linear in the rows after the sort)."""
    W = campaign.wrench
    rows = np.asarray(rows)
    g = np.asarray(groups)[rows]
    Wr = W[rows]
    order = np.lexsort(tuple(Wr[:, k] for k in range(Wr.shape[1] - 1, -1, -1)) + (g,))
    rs, gs, Ws = rows[order], g[order], Wr[order]
    scale = np.maximum(np.linalg.norm(Ws, axis=1), 1e-9)
    same = np.r_[False, (gs[1:] == gs[:-1]) & (np.linalg.norm(Ws[1:] - Ws[:-1], axis=1) <= LOAD_MATCH_REL * scale[:-1])]
    starts = np.flatnonzero(~same)
    sets = [list(block) for block in np.split(rs, starts[1:]) if len(block) > 1]
    return [sorted(int(r) for r in s) for s in sets]


def estimate_floor(campaign, groups, rows, stated_mm=None, stated_by=None):
    """The floor from the statement and/or the replicate rows among ``rows``
    (``stated_by``: where ``stated_mm`` came from, in words)."""
    sets = replicate_sets(campaign, groups, rows)
    dof = sum(len(s) - 1 for s in sets)
    rep = None
    if dof >= MIN_REPLICATE_DOF:
        ss = sum(float(np.sum((campaign.disp_mm[s] - campaign.disp_mm[s].mean(axis=0)) ** 2)) for s in sets)
        rep = float(np.sqrt(ss / (3 * dof)))
    if stated_mm is not None:
        return Floor(float(stated_mm), "stated", float(stated_mm), rep, dof, len(sets), stated_by)
    if rep is not None:
        return Floor(rep, "replicates", None, rep, dof, len(sets))
    return Floor(None, None, None, None, dof, len(sets))


def cv_map(X, folds, rows):
    """M with e = M y over the equations of ``rows`` (held-out residuals of a
    linear model with columns X, (3N, p), refitted in each fold).  Dense,
    (3N)^2: for checking the moments below on small campaigns only."""
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


def dense_moments(M, groups_rows, rho):
    """(E, V) of |M eps|^2 for unit-variance noise with correlation rho
    within a pose, from the dense map (a check of ``moments``)."""
    if rho == 0:
        B = M @ M.T
    else:
        same = (groups_rows[:, None] == groups_rows[None, :]).astype(float)
        S_rows = (1 - rho) * np.eye(len(groups_rows)) + rho * same
        S = np.kron(S_rows, np.eye(3))
        B = M @ S @ M.T
    return float(np.trace(B)), 2.0 * float(np.sum(B * B))


def _group_sum(A, g_eq):
    """Each row of A (n, p) replaced by the sum of the rows of its group (P A)."""
    _, inv = np.unique(g_eq, return_inverse=True)
    sums = np.zeros((inv.max() + 1, A.shape[1]))
    np.add.at(sums, inv, A)
    return sums[inv], np.bincount(inv)[inv]


def moments(X, folds, rows, groups_rows, rho):
    """(E, V) of Q = |M eps|^2, eps with unit variance and correlation rho
    between the equations of one pose and component, M the held-out map of
    the folds (see the module docstring): E = tr(B), V = 2 tr(B^2),
    B = M S M^T.  Exact, in memory linear in the rows: M = I - U V^T with
    U_f = E_f X G_f (fold f's test rows), V_f = D_f X (its training rows),
    G_f = (X^T D_f X)^+, and S = (1 - rho) I + rho P (P sums a pose's
    equations of one component), so B = S + F Lambda F^T with F = [U, S V]
    and every trace reduces to p x p Gram matrices of the folds.  The rows
    of a pose must share a fold when rho > 0 (the folds are grouped)."""
    eq_all = rows_to_eq(rows)
    n = len(eq_all)
    pos = np.full(int(eq_all.max()) + 1, -1)
    pos[eq_all] = np.arange(n)
    every = n == len(X) and np.array_equal(eq_all, np.arange(n))  # all the equations in order: no gathered copy
    Xr = X[eq_all] if not every else X
    scale = np.linalg.norm(Xr, axis=0)
    scale[scale == 0] = 1.0
    Xr = Xr / scale if every else np.divide(Xr, scale, out=Xr)
    p = Xr.shape[1]
    g_eq = np.repeat(np.asarray(groups_rows), 3) * 3 + np.tile(np.arange(3), len(rows))
    Xb, n_g = _group_sum(Xr, g_eq) if rho else (np.zeros_like(Xr), np.ones(n))
    # S X = (1 - rho) X + rho P X and S^2 X = (1 - rho) S X + rho ((1 - rho) P X + rho n_g P X), written in place
    # (the same operations in the same order: one temporary at a time, not five n x p arrays)
    Y = (1 - rho) * Xr
    Y += rho * Xb
    SY = (1 - rho) * Xb
    SY += rho * n_g[:, None] * Xb
    Xb = None
    SY *= rho
    SY += (1 - rho) * Y
    tests = [pos[rows_to_eq(test)] for _, test in folds]
    K = len(tests)
    A = [Xr[t].T @ Xr[t] for t in tests]  # X^T E_f X
    YX = [Xr[t].T @ Y[t] for t in tests]  # X^T E_f S X
    YY = [Y[t].T @ Y[t] for t in tests]  # X^T S E_f S X
    SYX = [SY[t].T @ Xr[t] for t in tests]  # X^T S^2 E_f X
    A_all, YY_all = sum(A), sum(YY)
    covered = np.zeros(n, dtype=bool)
    for t in tests:
        covered[t] = True
    if not covered.all():
        raise ValueError("the folds' test rows must cover the rows")
    G = [np.linalg.pinv(A_all - A[f]) for f in range(K)]
    # V_f^T S V_g = X^T D_f S D_g X and W_f^T W_g = X^T S D_f D_g S X (S, E_h commute: P is block-diagonal by fold)
    YX_all = sum(YX)

    def outside(total, parts, f, g):
        return total - parts[f] - (parts[g] if g != f else 0)

    kp = K * p
    UU, UW, WW, C = (np.zeros((kp, kp)) for _ in range(4))
    USU, WSU = np.zeros((kp, kp)), np.zeros((kp, kp))
    for f in range(K):
        sf = slice(f * p, (f + 1) * p)
        UU[sf, sf] = G[f] @ A[f] @ G[f]
        USU[sf, sf] = G[f] @ YX[f] @ G[f]
        for g in range(K):
            sg = slice(g * p, (g + 1) * p)
            C[sf, sg] = outside(YX_all, YX, f, g)
            WW[sf, sg] = outside(YY_all, YY, f, g)
            if f != g:
                UW[sf, sg] = G[f] @ YX[f].T  # U_f^T W_g = G_f X^T E_f S X (E_f D_g = E_f)
                WSU[sg, sf] = SYX[f] @ G[f]  # W_g^T S U_f = X^T S^2 E_f X G_f
    tr_S = float(n)
    sizes = np.bincount(np.unique(g_eq, return_inverse=True)[1]) if rho else np.ones(n)
    tr_S2 = (1 - rho**2) * n + rho**2 * float(np.sum(sizes**2))
    E = tr_S - 2 * np.trace(UW) + np.trace(C @ UU)
    tr_SL = -2 * np.trace(WSU) + np.trace(C @ USU)
    Gam = np.block([[UU, UW], [UW.T, WW]])
    Lam = np.block([[C, -np.eye(kp)], [-np.eye(kp), np.zeros((kp, kp))]])
    LG = Lam @ Gam
    tr_L2 = float(np.sum(LG * LG.T))
    return float(E), 2.0 * float(tr_S2 + 2 * tr_SL + tr_L2)


def _groups_within_folds(folds, rows, groups_rows):
    fold_of = {}
    where = {int(r): i for i, r in enumerate(rows)}
    for f, (_, test) in enumerate(folds):
        for r in test:
            g = groups_rows[where[int(r)]]
            if fold_of.setdefault(g, f) != f:
                return False
    return True


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
    g_rows = np.asarray(groups)[rows]
    shared = len(np.unique(g_rows)) < len(g_rows) and _groups_within_folds(folds, rows, g_rows)
    rhos = [0.0] + ([SHARED_REFERENCE_CORRELATION] if shared else [])
    best, p_below = None, 0.0
    sigma2 = (floor.sigma_mm * 1e-3) ** 2
    for rho in rhos:
        E, V = moments(X, folds, rows, g_rows, rho)
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
