"""Grouped cross-validation for the residual diagnosis.  Plain numpy + scipy.

The rows measured at one pose share one unloaded reference reading (the
displacement is loaded minus unloaded), so their errors are not independent:
every test here treats a pose as one unit.

  * ``pose_groups``: the pose of each row (the ``pose`` column, or, without
    it, rows with identical joint angles);
  * ``folds``: K test folds, a pose's rows never split between fitting and
    testing; the permutation has a fixed seed, so a run is reproducible;
  * ``grouped_gain_test``: is the held-out error per pose smaller with one
    model than with another?  A one-sided paired t-test over poses.
"""

import numpy as np
from scipy import stats

K_FOLDS = 5
FOLD_SEED = 0  # fixed: the same file always gets the same folds
Q_MATCH_DEG = 1e-6  # rows whose six angles agree to this are one pose when the file has no pose column


def pose_groups(campaign):
    """(N,) int group index of each row: its pose."""
    if campaign.pose is not None:
        _, idx = np.unique(np.asarray(campaign.pose, dtype=str), return_inverse=True)
        return idx
    key = np.round(np.asarray(campaign.q_deg) / Q_MATCH_DEG).astype(np.int64)
    _, idx = np.unique(key, axis=0, return_inverse=True)
    return idx.ravel()


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


def rows_to_eq(rows):
    """Row indices -> equation indices (three displacement components per row)."""
    rows = np.asarray(rows)
    return (3 * rows[:, None] + np.arange(3)).ravel()


def per_group_sse(residual_eq, groups):
    """Sum of squared residuals per group; residual_eq is (3N,)."""
    r2 = residual_eq.reshape(-1, 3)
    r2 = np.sum(r2 * r2, axis=1)
    return np.bincount(groups, weights=r2, minlength=int(groups.max()) + 1)


def grouped_gain_test(sse_old, sse_new):
    """One-sided paired t-test over groups that the new model's held-out
    error is smaller.  Returns (p, t).  With fewer than 3 groups, p = 1."""
    d = np.asarray(sse_old) - np.asarray(sse_new)
    g = len(d)
    if g < 3:
        return 1.0, 0.0
    sd = float(np.std(d, ddof=1))
    mean = float(np.mean(d))
    if sd == 0:
        return (0.0, np.inf) if mean > 0 else (1.0, 0.0)
    t = mean / (sd / np.sqrt(g))
    return float(stats.t.sf(t, g - 1)), float(t)
