"""Grouped cross-validation for the residual diagnosis.  Plain numpy + scipy.

The rows measured at one pose share one unloaded reference reading (the
displacement is loaded minus unloaded), so their errors are not independent:
every test here treats a pose as one unit.

  * ``pose_groups``: the pose of each row (the ``pose`` column, or, without
    it, rows with identical joint angles);
  * ``folds``: K test folds, a pose's rows never split between fitting and
    testing; the permutation has a fixed seed, so a run is reproducible.
    The poses are numbered by their joint angles (``pose_groups``), not by
    their labels' text or the file's row order, so the folds of a campaign
    do not change when its poses are labelled P1 or P01 or its rows are
    sorted otherwise; ``FOLD_SEEDS`` are the assignments whose spread the
    diagnosis reports;
  * ``clustered_wald``: are some coefficients of a least-squares fit zero?
    The pose-clustered bias-reduced (CR2) sandwich, a Bell-McCaffrey t per
    parameter and Bonferroni over them, the small-sample corrections for few
    clusters (clustered_test.py): valid whatever the correlation of a pose's
    rows;
"""

import numpy as np
from scipy import special

from robstiff_drake.identification.diagnosis.clustered_test import clustered_fit

K_FOLDS = 5
FOLD_SEED = 0  # fixed: the same file always gets the same folds
# the fold assignments over which the diagnosis reports the spread of its
# held-out figures (one number from one assignment can move by several points)
FOLD_SEEDS = tuple(range(10))
MIN_POSES = 3  # fewer poses: the tests fall back to rows as units (and say so)
Q_MATCH_DEG = 1e-6  # rows whose six angles agree to this are one pose when the file has no pose column


def pose_groups(campaign):
    """(N,) int group index of each row: its pose (the ``pose`` column, or,
    without it, rows with identical joint angles).  The groups are numbered
    in the order of their joint angles (each pose's mean angles, compared
    joint by joint; ties, two labels at the same angles, in the order of
    their first row), so the numbering, and with it the folds, depends on the
    poses' values only, not on how their labels are written."""
    q = np.asarray(campaign.q_deg, dtype=float)
    if campaign.pose is not None:
        _, idx = np.unique(np.asarray(campaign.pose, dtype=str), return_inverse=True)
    else:
        key = np.round(q / Q_MATCH_DEG).astype(np.int64)
        _, idx = np.unique(key, axis=0, return_inverse=True)
    idx = np.asarray(idx).ravel()
    n = int(idx.max()) + 1 if idx.size else 0
    counts = np.bincount(idx, minlength=n)[:, None]
    mean_q = np.zeros((n, q.shape[1]))
    np.add.at(mean_q, idx, q)
    mean_q /= np.maximum(counts, 1)
    first = np.full(n, len(idx))
    np.minimum.at(first, idx, np.arange(len(idx)))
    # lexsort: the last key is the primary one (q1, then q2, ..., then the first row)
    order = np.lexsort([first] + [mean_q[:, j] for j in reversed(range(q.shape[1]))])
    rank = np.empty(n, dtype=int)
    rank[order] = np.arange(n)
    return rank[idx]


def test_groups(groups, rows):
    """The units of the grouped tests: the poses, or the rows when the rows
    used span fewer than MIN_POSES poses.  Returns (groups, poses are units)."""
    if len(np.unique(np.asarray(groups)[rows])) >= MIN_POSES:
        return np.asarray(groups), True
    return np.arange(len(groups)), False


def folds(groups, k=K_FOLDS, seed=FOLD_SEED):
    """Row indices of k test folds; a group's rows stay together."""
    groups = np.asarray(groups)
    uniq = np.unique(groups)
    order = np.random.default_rng(seed).permutation(len(uniq))
    k = min(k, len(uniq))
    out = []
    for f in range(k):
        members = uniq[order[f::k]]
        out.append(np.flatnonzero(np.isin(groups, members)))
    return out


def splits(rows, groups, k=K_FOLDS, seed=FOLD_SEED):
    """[(train rows, test rows)] of the k pose-grouped folds over ``rows``."""
    rows = np.asarray(rows)
    out = []
    for f in folds(np.asarray(groups)[rows], k, seed):
        test = rows[f]
        out.append((np.setdiff1d(rows, test), test))
    return out


def rows_to_eq(rows):
    """Row indices -> equation indices (three displacement components per row)."""
    rows = np.asarray(rows)
    return (3 * rows[:, None] + np.arange(3)).ravel()


def clustered_cov(X, y, groups_eq):
    """Least squares of y (n,) on X (n, p) with the covariance of the
    coefficients clustered by ``groups_eq`` (n,): the bias-reduced CR2
    sandwich (identification/diagnosis/clustered_test.py).  Returns a
    ClusteredFit (coef, cov, G, r; ``.p(cols)`` its test); the
    covariance is None with fewer than 3 clusters."""
    return clustered_fit(X, y, groups_eq)


def wald_p(coef, cov, cols, G):
    """p-value of the Wald test that coef[cols] = 0 with covariance ``cov``
    from G clusters, referred to F(q, G - 1); 1 without a covariance.  (The
    tracker's search uses it with its own CR1 covariance; the residual
    diagnosis uses the corrected test, ``clustered_wald``.)"""
    if cov is None:
        return 1.0
    idx = np.arange(len(coef))[cols]
    b = coef[idx]
    Vb = cov[np.ix_(idx, idx)]
    s = np.sqrt(np.maximum(np.diag(Vb), 1e-300))
    q = len(b)
    W = float((b / s) @ np.linalg.pinv(Vb / np.outer(s, s)) @ (b / s))
    return float(special.fdtrc(q, G - 1, W / q))


def clustered_wald(X, y, groups_eq, cols):
    """Least squares of y (n,) on X (n, p), and the p-value of the test that
    the coefficients ``cols`` (a slice) are zero, with the CR2 covariance
    clustered by ``groups_eq`` (n,) and a Bell-McCaffrey t per contrast,
    Bonferroni over them (identification/diagnosis/clustered_test.py): valid whatever the
    correlation of a pose's rows, and calibrated on few poses.  Returns
    (p, coefficients, residual)."""
    fit = clustered_fit(X, y, groups_eq)
    return fit.p(cols), fit.coef, fit.r
