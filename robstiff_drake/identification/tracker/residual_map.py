"""A non-parametric map of what a tracker campaign's named effects leave:
an error in the joint angles, each joint's a smooth function of the
controller's angles, dq_j(J) = sum_k f_jk(J_k) + g_j(J_2 + J_3) +
h_j(J_2 - J_3), every f, g, h a Fourier series up to harmonic H (additive
in the angles, plus the elbow's sum and difference, where an arm's
bending and its parallel axes couple two joints), seen at the measured point
through the fitted arm's Jacobian (d = J_v dq).  The weights by ridge
regression; H and the ridge chosen inside each fold.  Memory and time are
linear in the rows.  Plain numpy.

It applies only inside the campaign's joint-space domain: at a pose whose
nearest training pose (Euclidean over the six controller angles, rad) is
farther than the training poses' own typical spacing (DOMAIN_QUANTILE of
their nearest-neighbour distances, d0), it shrinks linearly to zero at
DOMAIN_FAR x d0: a Fourier series fitted where there are measurements says
nothing where there are none (unshrunk, one fold's map reached 477 mm).

It is a hypothesis, not an effect: it is kept only if, fitted inside each
held-out fold on that fold's training rows (H and ridge chosen by an inner
3-fold split of those rows), it lowers the held-out mean and RMS 3D error in
every fold (never a fold worse than the parametric model), raises no fold's
largest error by more than MAX_GROWTH, and the mean by MIN_GAIN overall, and the report says what it is.
"""

import numpy as np
from scipy.spatial import cKDTree

HARMONICS = (2, 4, 6)  # the highest harmonic H of each series, chosen inside the fold
RIDGES = (1e-7, 1e-6, 1e-5, 1e-4, 1e-3)  # x the design's mean diagonal: the penalty per weight
SEED = 20261125
INNER_FOLDS = 3
MIN_GAIN = 0.03
MAX_GROWTH = 1.25  # no fold's largest held-out error may grow by more than this factor (a map that helps on
# average but adds a large error at a few poses is worse for a user who needs every pose right)
DOMAIN_QUANTILE = 0.95
DOMAIN_FAR = 2.0
# The map has at most 6 x 16 x 6 = 576 weights: a fold's map is fitted on at most this many of its training
# rows (a fixed-seed draw: 12,000 equations for 576 weights), and its H and ridge chosen on at most CHOOSE_ROWS,
# so that a 12,000-row campaign's map costs what a 4,000-row one's does
MAX_ROWS = 4000
CHOOSE_ROWS = 2400


def subsample(n, limit):
    """Indices of at most ``limit`` of n rows (fixed seed), sorted."""
    if n <= limit:
        return np.arange(n)
    return np.sort(np.random.default_rng(SEED).choice(n, limit, replace=False))


def features(J, H):
    """(n, K) Fourier features (harmonics 1..H) of each controller angle (n, 6)
    and of the elbow's sum and difference J2 +- J3 (rad), harmonic-major: the
    features of a smaller H are the first columns."""
    ang = np.column_stack([J, J[:, 1] + J[:, 2], J[:, 1] - J[:, 2]])
    h = np.arange(1, H + 1)
    x = ang[:, None, :] * h[None, :, None]  # (n, H, 8)
    return np.concatenate([np.cos(x), np.sin(x)], axis=2).reshape(len(J), -1)


def _columns(H_max, H):
    """Indices of the design's columns (joint-major, features harmonic-major) for harmonics up to H."""
    per = 16 * H_max
    return np.concatenate([j * per + np.arange(16 * H) for j in range(6)])


def design(J, Jv, H):
    """(3n, 6 K) columns: joint j's error (features . w_j) through J_v (n, 3, 6)."""
    F = features(J, H)
    return np.einsum("nrj,nk->nrjk", Jv, F).reshape(3 * len(J), -1)


class ResidualMap:
    """Ridge regression of residuals (n, 3), base frame, on the joint-space design."""

    def __init__(self, H, ridge):
        self.H, self.ridge = H, ridge

    def fit(self, J, Jv, resid):
        X = design(J, Jv, self.H)
        A = X.T @ X
        A[np.diag_indices_from(A)] += self.ridge * np.trace(A) / len(A)
        self.coef = np.linalg.solve(A, X.T @ resid.reshape(-1))
        self.tree = cKDTree(np.asarray(J, float))
        nn = self.tree.query(J, k=2)[0][:, 1] if len(J) > 1 else np.zeros(1)
        self.d0 = max(float(np.quantile(nn, DOMAIN_QUANTILE)), 1e-9)
        return self

    def weight(self, J):
        """(n,) 1 inside the training poses' domain, shrinking to 0 at DOMAIN_FAR x their spacing."""
        d = self.tree.query(np.asarray(J, float), k=1)[0]
        return np.clip((DOMAIN_FAR * self.d0 - d) / ((DOMAIN_FAR - 1) * self.d0), 0.0, 1.0)

    def predict(self, J, Jv, block=2048):
        """(n, 3) the map's residuals at angles J (n, 6), Jacobians Jv (n, 3, 6), weighted by the domain,
        ``block`` rows at a time (a design row is 3 x 576 floats: a 20,000-row fold's whole design was 276 MB)."""
        out = np.empty((len(J), 3))
        for s in range(0, len(J), block):
            out[s:s + block] = (design(J[s:s + block], Jv[s:s + block], self.H) @ self.coef).reshape(-1, 3)
        return out * self.weight(J)[:, None]


def choose(J, Jv, resid):
    """(H, ridge) by an inner 3-fold split of the rows (fixed order), from
    the Gram matrices of the largest H's design (a smaller H's are their
    sub-blocks; one eigendecomposition per H and fold serves every ridge)."""
    n = len(J)
    order = np.random.default_rng(SEED).permutation(n)
    parts = [np.sort(order[k::INNER_FOLDS]) for k in range(INNER_FOLDS)]
    H_max = max(HARMONICS)
    X = design(J, Jv, H_max)
    y = resid.reshape(-1)
    eqs = [(3 * p[:, None] + np.arange(3)).ravel() for p in parts]
    Gs = [X[e].T @ X[e] for e in eqs]
    bs = [X[e].T @ y[e] for e in eqs]
    rr = [float(y[e] @ y[e]) for e in eqs]
    Gt, bt = sum(Gs), sum(bs)
    best = (np.inf, None)
    for H in HARMONICS:
        c = _columns(H_max, H)
        sse = np.zeros(len(RIDGES))
        for Gk, bk, rk in zip(Gs, bs, rr):
            A = (Gt - Gk)[np.ix_(c, c)]
            w, V = np.linalg.eigh(A)
            proj = V.T @ (bt - bk)[c]
            for i, ridge in enumerate(RIDGES):
                C = V @ (proj / (np.maximum(w, 0) + ridge * np.trace(A) / len(A)))
                sse[i] += rk - 2 * C @ bk[c] + C @ Gk[np.ix_(c, c)] @ C
        i = int(np.argmin(sse))
        if sse[i] < best[0]:
            best = (sse[i], (H, RIDGES[i]))
    return best[1]
