"""The pose-clustered test of the residual diagnosis with its small-sample
corrections for few clusters.  Plain numpy + scipy.

A campaign's rows measured at one pose share one unloaded reference reading,
so the diagnosis tests a candidate's parameters with a covariance clustered
by pose (a sandwich).  With few poses the plain sandwich (CR1: the scores'
outer products times G / (G - 1)) is biased low and the Wald statistic is far
from chi-square or F(q, G - 1); the test then rejects too often, worst where
a few poses carry the candidate's columns (high leverage).  The test used
(``REFERENCE``; Cameron & Miller 2015, "A Practitioner's Guide to
Cluster-Robust Inference", sections VI-VII; Imbens & Kolesar 2016;
Pustejovsky & Tipton 2018):

  * **CR2**, the bias-reduced sandwich of Bell & McCaffrey (2002): each
    pose's residuals are scaled by (I - H_gg)^(-1/2), H_gg the pose's block
    of the hat matrix, which makes the covariance unbiased when the errors
    are independent with one variance (the working model).  The pseudo-
    inverse square root is taken where a pose's leverage is 1.  Computed from
    a thin SVD of each pose's columns, so the cost is linear in the rows.
  * **Bell-McCaffrey t per contrast, Bonferroni over q**: one tested
    coefficient's t statistic with the CR2 variance is referred to t with
    the Satterthwaite degrees of freedom matched to that variance under the
    working model (``eta`` below with one contrast; Imbens & Kolesar's
    recommendation).  For q > 1 parameters the same is done for the q
    contrasts the working model makes uncorrelated (the eigenvectors of its
    covariance of the tested coefficients; fixed by the design, not by the
    measured deflections), and the smallest p-value is multiplied by q
    (Bonferroni).  With the contrasts uncorrelated the union bound is nearly
    exact in the far tail where the diagnosis decides (0.01 / the candidates
    of a round, about 1e-4, and 1e-6 for a size beyond the typical), loose
    only near 5 %; and evidence in a combination of correlated parameters
    (a tool offset against the springs) stays in one contrast instead of
    being spread over q weak per-parameter tests.

Measured (studies/clustered_test_choice.py; its table is in
docs/diagnosis.md): a true null at a nominal 5 % on a synthetic regression
of 10 poses x 9 equations (tests/clustered_null.py) is rejected in 31 (q = 1)
and 83 (q = 3) of 200 draws by CR1 + F(q, G - 1), 6 and 0 by CR2 + HTZ (the
approximate Hotelling T^2 test of Pustejovsky & Tipton 2018, kept here as
``htz``: its scaled F(q, eta - q + 1) has no tail where eta, small on 10
poses of uneven leverage, is near q, so it is very conservative for q > 1),
and 6 and 1 by this test; CR2 with W / q referred to F(q, eta) (``f_eta``,
invariant but without HTZ's correction for the covariance's randomness)
rejects 6 and 18 (liberal for q > 1).
A wild cluster bootstrap (restricted, Rademacher) rejects 12 for one
parameter, but its p cannot reach 1e-4 with bounded draws on few poses
(studies/wild_bootstrap_check.py).
On the diagnosis: the study's table.

The sums over pairs of poses that eta needs are formed as (pq x pq) moment
tensors, so no (G x G) or (3N x 3N) matrix is built.
"""

from dataclasses import dataclass

import numpy as np
from scipy import special

LEVERAGE_TOL = 1e-10  # an eigenvalue of I - H_gg below this: leverage 1, pseudo-inverse
# the test of ClusteredFit.p: "bm" (CR2, Bell-McCaffrey t per contrast, Bonferroni over q; the one used);
# "htz" (CR2, HTZ), "f_eta" (CR2, W / q against F(q, eta)) and "cr1" (CR1 sandwich, F(q, G - 1)) are kept for
# studies/clustered_test_choice.py
REFERENCE = "bm"
REFERENCES = ("bm", "htz", "f_eta", "cr1")


@dataclass
class ClusteredFit:
    """A least-squares fit with its pose-clustered CR2 covariance (CR1 with
    REFERENCE "cr1") (module docstring)."""

    coef: np.ndarray  # (p,) SI
    cov: np.ndarray  # (p, p) CR2 covariance (CR1 with REFERENCE "cr1"), SI; None with fewer than 3 clusters
    G: int  # clusters
    r: np.ndarray  # (n,) residual
    scale: np.ndarray  # (p,) column norms (the fit is done on X / scale)
    bread: np.ndarray  # (p, p) pinv(Xs' Xs)
    SVt: list  # per cluster size: (m, k, p) S V' of each cluster's thin SVD of Xs
    Minv: list  # per cluster size: (m, k, k) (I - M)^-1/2, M = S V' bread V S

    reference: str = "bm"  # REFERENCE when the fit was made

    def p(self, cols):
        """p-value of the test that coef[cols] = 0 (REFERENCE); 1 without a covariance."""
        if self.reference == "cr1":
            return cr1_p(self, cols)
        if self.reference in ("htz", "f_eta"):
            return htz(self, cols, hotelling=self.reference == "htz")[0]
        return bm_bonferroni(self, cols)[0]


def clustered_fit(X, y, groups_eq):
    """Least squares of y (n,) on X (n, p) with the CR2 covariance clustered by
    ``groups_eq`` (n,) (module docstring).  Returns a ClusteredFit."""
    scale, Xs, bread, g, G = _scaled(X, groups_eq)
    coef_s, *_ = np.linalg.lstsq(Xs, y, rcond=None)
    r = y - Xs @ coef_s
    if G < 3:
        return ClusteredFit(coef_s / scale, None, G, r, scale, bread, [], [], REFERENCE)
    cov_s, SVts, Minvs = cr2_cov(Xs, r, g, bread)
    if REFERENCE == "cr1":
        U = np.zeros((G, Xs.shape[1]))
        np.add.at(U, g, Xs * r[:, None])
        cov_s = bread @ (U.T @ U) @ bread * (G / (G - 1))
    return ClusteredFit(coef_s / scale, cov_s / np.outer(scale, scale), G, r, scale, bread, SVts, Minvs, REFERENCE)


def _scaled(X, groups_eq):
    """(scale, Xs, bread, g, G): X's column norms (1 for a zero column), X
    scaled by them, pinv(Xs' Xs), each row's cluster index 0..G-1 and G."""
    scale = np.linalg.norm(X, axis=0)
    scale[scale == 0] = 1.0
    Xs = X / scale
    _, g = np.unique(np.asarray(groups_eq), return_inverse=True)
    g = np.asarray(g).ravel()
    return scale, Xs, np.linalg.pinv(Xs.T @ Xs), g, int(g.max()) + 1 if g.size else 0


def cr2_cov(Xs, r, g, bread):
    """The CR2 covariance of the coefficients of Xs (n, p) given the residual r
    (n,), the cluster index g (n,) (0..G-1) and bread = pinv(Xs' Xs); with the
    per-cluster pieces the degrees of freedom need.  Returns (covariance,
    S V' per cluster size, (I - M)^-1/2 per cluster size)."""
    order = np.argsort(g, kind="stable")
    starts = np.r_[0, np.flatnonzero(np.diff(g[order])) + 1]
    sizes = np.diff(np.r_[starts, len(g)])
    scores = np.zeros((int(g.max()) + 1, Xs.shape[1]))
    SVts, Minvs = [], []
    for s in np.unique(sizes):  # clusters of one size at a time, batched
        which = np.flatnonzero(sizes == s)
        idx = order[starts[which][:, None] + np.arange(s)]  # (m, s) rows of each cluster
        U, S, Vt = np.linalg.svd(Xs[idx], full_matrices=False)
        SVt = S[:, :, None] * Vt  # (m, k, p)
        M = SVt @ bread @ np.swapaxes(SVt, 1, 2)  # U' H_gg U
        w, Q = np.linalg.eigh(np.eye(M.shape[1]) - M)
        inv = np.where(w > LEVERAGE_TOL, 1.0 / np.sqrt(np.maximum(w, LEVERAGE_TOL)), 0.0)
        Minv = (Q * inv[:, None, :]) @ np.swapaxes(Q, 1, 2)
        z = Minv @ np.einsum("msk,ms->mk", U, r[idx])[:, :, None]  # (I - M)^-1/2 U' e_g
        scores[which] = (np.swapaxes(SVt, 1, 2) @ z)[:, :, 0]  # X_g' A_g e_g
        SVts.append(SVt)
        Minvs.append(Minv)
    return bread @ (scores.T @ scores) @ bread, SVts, Minvs


def interval_half_widths(X, r, groups_eq, level=0.95):
    """Half-widths (X's column units) of the ``level`` intervals of every
    coefficient of a least-squares fit of columns X (n, p) with residual r
    (n,), clustered by ``groups_eq`` (n,): the CR2 standard error times
    t(eta_j), eta_j the coefficient's Bell-McCaffrey (Satterthwaite) degrees
    of freedom, as the test (``bm_bonferroni``) refers one contrast; t(G - 1)
    where eta_j is undefined (a coefficient the working model cannot
    estimate)."""
    from scipy import stats

    scale, Xs, bread, g, G = _scaled(X, groups_eq)
    cov_s, SVts, Minvs = cr2_cov(Xs, r, g, bread)  # linear in the rows (batched per pose size)
    fit = ClusteredFit(np.zeros(X.shape[1]), cov_s, G, r, np.ones(X.shape[1]), bread, SVts, Minvs)
    dof = np.full(X.shape[1], float(max(G - 1, 1)))
    for j in range(X.shape[1]):
        C = np.zeros((1, X.shape[1]))
        C[0, j] = 1.0
        eta = _eta(fit, C)
        if np.isfinite(eta) and eta > 0:
            dof[j] = eta
    return stats.t.ppf(0.5 + level / 2, dof) * np.sqrt(np.maximum(np.diag(cov_s), 0.0)) / scale


def _tested(fit, cols):
    """(index, scaled coefficients, their scaled covariance) of coef[cols]."""
    idx = np.arange(len(fit.coef))[cols]
    return idx, (fit.coef * fit.scale)[idx], (fit.cov * np.outer(fit.scale, fit.scale))[np.ix_(idx, idx)]


def _wald(b, Vb):
    """b' Vb^-1 b, Vb scaled to a unit diagonal first (columns of very different size)."""
    s = np.sqrt(np.maximum(np.diag(Vb), 1e-300))
    return float((b / s) @ np.linalg.pinv(Vb / np.outer(s, s)) @ (b / s))


def bm_bonferroni(fit, cols):
    """(p-value, the q degrees of freedom) of the test that fit.coef[cols] = 0:
    the q contrasts of the tested coefficients that the working model makes
    uncorrelated (the eigenvectors of its covariance, pinv(X' X) of the
    scaled problem, fixed by the design), each one's CR2 t statistic against
    t(eta_k), eta_k its Bell-McCaffrey (Satterthwaite) degrees of freedom, the
    smallest p times q (module docstring); (1, []) without a covariance."""
    if fit.cov is None:
        return 1.0, []
    idx, b, Vb = _tested(fit, cols)
    _, Q = np.linalg.eigh(fit.bread[np.ix_(idx, idx)])
    etas, ps = [], []
    for c in Q.T:
        C = np.zeros((1, len(fit.coef)))
        C[0, idx] = c
        eta = _eta(fit, C)
        etas.append(eta)
        t2 = float(c @ b) ** 2 / max(float(c @ Vb @ c), 1e-300)
        ps.append(float(special.fdtrc(1, eta, t2)) if np.isfinite(eta) and eta > 0 else 1.0)
    return min(1.0, len(idx) * min(ps)), etas


def cr1_p(fit, cols):
    """p-value of the uncorrected test (fit made with REFERENCE "cr1": CR1
    covariance): W / q referred to F(q, G - 1); 1 without a covariance."""
    if fit.cov is None:
        return 1.0
    idx, b, Vb = _tested(fit, cols)
    return float(special.fdtrc(len(idx), fit.G - 1, _wald(b, Vb) / len(idx)))


def htz(fit, cols, hotelling=True):
    """(p-value, eta) of the approximate Hotelling T^2 test (HTZ) that
    fit.coef[cols] = 0 (module docstring); (1, nan) without a covariance.
    ``hotelling`` False: W / q referred to F(q, eta) instead."""
    if fit.cov is None:
        return 1.0, float("nan")
    idx, b, Vb = _tested(fit, cols)  # the scaled problem's coefficients
    p, q = len(fit.coef), len(idx)
    C = np.zeros((q, p))
    C[np.arange(q), idx] = 1.0
    W = _wald(b, Vb)
    eta = _eta(fit, C)
    if not hotelling:
        return (float(special.fdtrc(q, eta, W / q)) if np.isfinite(eta) else 1.0), eta
    if not np.isfinite(eta) or eta - q + 1 <= 0:
        return 1.0, eta
    return float(special.fdtrc(q, eta - q + 1, W * (eta - q + 1) / (eta * q))), eta


def _eta(fit, C):
    """Degrees of freedom eta of the CR2 covariance of C coef (HTZ's; with one
    row, Bell-McCaffrey's): q (q + 1) / sum over pairs of poses (g, h) of
    (tr G_gh)^2 + tr(G_gh G_gh), G_gh the working-model covariance of the
    whitened per-pose contributions (Pustejovsky & Tipton 2018)."""
    B = fit.bread
    Om = C @ B @ C.T  # the working model's covariance of C coef (unit variance)
    w, Q = np.linalg.eigh(Om)
    if np.any(w <= 1e-14 * max(w.max(), 1e-300)):
        return float("nan")
    BCw = B @ C.T @ (Q / np.sqrt(w)) @ Q.T  # B C' Om^-1/2, (p, q)
    wb, Qb = np.linalg.eigh(B)
    Bh = (Qb * np.sqrt(np.maximum(wb, 0.0))) @ Qb.T  # B^1/2
    p, q = BCw.shape
    T = np.zeros((p * q, p * q))  # sum_g vec(K_g) vec(K_g)'
    trD2 = trDE = trDtrE = trD_sq = 0.0
    for SVt, Minv in zip(fit.SVt, fit.Minv):
        Wg = Minv @ (SVt @ BCw)  # (I - M)^-1/2 S V' B C' Om^-1/2, (m, k, q)
        Z = np.swapaxes(SVt, 1, 2) @ Wg  # X_g' P_g, (m, p, q)
        K = Bh @ Z  # (m, p, q)
        D = np.swapaxes(Wg, 1, 2) @ Wg  # P_g' P_g
        E = np.swapaxes(K, 1, 2) @ K  # K_g' K_g
        v = K.reshape(len(K), -1)
        T += v.T @ v
        tD, tE = np.trace(D, axis1=1, axis2=2), np.trace(E, axis1=1, axis2=2)
        trD_sq += float(tD @ tD)
        trDtrE += float(tD @ tE)
        trD2 += float(np.sum(D * np.swapaxes(D, 1, 2)))
        trDE += float(np.sum(D * np.swapaxes(E, 1, 2)))
    T4 = T.reshape(p, q, p, q)
    sum_trE_sq = float(np.sum(T * T))  # sum_gh (tr E_gh)^2
    sum_trEE = float(np.einsum("asbt,bsat->", T4, T4))  # sum_gh tr(E_gh E_gh)
    s1 = sum_trE_sq - 2 * trDtrE + trD_sq
    s2 = sum_trEE - 2 * trDE + trD2
    return q * (q + 1) / max(s1 + s2, 1e-300)
