"""A non-parametric map of what a tracker campaign's named effects leave:
the residual (base frame) as a smooth function of the joint angles, by
ridge regression on random Fourier features of the angles' sines and
cosines (a Gaussian kernel on the torus of joint angles, approximated with
a fixed number of features so that memory and time stay linear in the
rows).  Plain numpy.

It is a hypothesis, not an effect: it is kept only if, fitted inside each
held-out fold on that fold's training rows (its width and ridge chosen by
an inner 3-fold split of those rows), it lowers the held-out mean 3D error
by MIN_GAIN and in at least MIN_FOLDS of the folds (it generalises), and
the report says what it is.  The features' random draw has a fixed seed.
"""

import numpy as np

N_FEATURES = 256
WIDTHS = (0.35, 0.7, 1.4)  # kernel width on the (cos q, sin q) embedding (about rad for small differences)
RIDGES = (1e-4, 1e-3, 1e-2, 1e-1)  # x (rows / features): the penalty per feature
SEED = 20261125
INNER_FOLDS = 3
MIN_GAIN = 0.10
MIN_FOLDS = 4


def _embed(q):
    return np.hstack([np.cos(q), np.sin(q)])


class Features:
    def __init__(self, width, n_features=N_FEATURES, seed=SEED):
        rng = np.random.default_rng(seed)
        self.W = rng.normal(size=(12, n_features)) / width
        self.b = rng.uniform(0, 2 * np.pi, n_features)
        self.scale = np.sqrt(2.0 / n_features)

    def __call__(self, q):
        return self.scale * np.cos(_embed(q) @ self.W + self.b)


class ResidualMap:
    """Ridge regression of residuals (n, 3) on the features of q (n, 6)."""

    def __init__(self, width, ridge):
        self.features = Features(width)
        self.ridge = ridge

    def fit(self, q, resid):
        F = self.features(q)
        A = F.T @ F + self.ridge * len(q) / F.shape[1] * np.eye(F.shape[1])
        self.coef = np.linalg.solve(A, F.T @ resid)
        return self

    def predict(self, q):
        return self.features(q) @ self.coef


def choose(q, resid, rng_order=None):
    """(width, ridge) by an inner 3-fold split of the rows (fixed order),
    from Gram matrices of the features (one per width)."""
    n = len(q)
    order = np.random.default_rng(SEED).permutation(n) if rng_order is None else rng_order
    parts = [order[k::INNER_FOLDS] for k in range(INNER_FOLDS)]
    best = (np.inf, None)
    for width in WIDTHS:
        F = Features(width)(q)
        Gs = [F[p].T @ F[p] for p in parts]
        bs = [F[p].T @ resid[p] for p in parts]
        rr = [float(np.sum(resid[p] ** 2)) for p in parts]
        Gt, bt = sum(Gs), sum(bs)
        sse = np.zeros(len(RIDGES))
        for Gk, bk, rk, p in zip(Gs, bs, rr, parts):
            w, V = np.linalg.eigh(Gt - Gk)  # once per fold: every ridge from the same eigenvectors
            proj = V.T @ (bt - bk)
            for i, ridge in enumerate(RIDGES):
                C = V @ (proj / (np.maximum(w, 0) + ridge * (n - len(p)) / F.shape[1])[:, None])
                sse[i] += rk - 2 * np.sum(C * bk) + np.sum(C * (Gk @ C))
        i = int(np.argmin(sse))
        if sse[i] < best[0]:
            best = (sse[i], (width, RIDGES[i]))
    return best[1]
