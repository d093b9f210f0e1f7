"""Effects that explain the same residual: the correlation of their
estimates when fitted together.  Plain numpy.

Two parameter blocks A and B of a least-squares fit (a joint's compliance,
a term's parameters) are confounded when the data cannot tell them apart:
their estimates trade off against each other.  With the coefficients'
covariance S (proportional to (X^T X)^-1, the design's part; the noise
scales it but not the correlation), the largest correlation between any
combination of A's estimates and any combination of B's is the largest
singular value of S_AA^-1/2 S_AB S_BB^-1/2 (a canonical correlation); for
two single parameters it is their correlation, with its sign (negative: a
larger A goes with a smaller B).

A correlation of CONFOUNDED_MIN (0.8) inflates each one's variance by
1 / (1 - 0.8^2) = 2.8 over what it would be if the other were known (and a
bias in one moves the other by 0.8 of it, in standard errors): the campaign
does not separate them well, and `robstiff plan-poses --separate A,B` plans
the measurements that would.
"""

import numpy as np

CONFOUNDED_MIN = 0.8


def _inv_sqrt(S):
    w, V = np.linalg.eigh(S)
    w = np.maximum(w, 1e-12 * max(float(w.max()), 1e-300))
    return (V / np.sqrt(w)) @ V.T


def correlation(cov, a, b):
    """Correlation of the estimates of blocks a and b (index arrays) under
    ``cov``: signed for two single parameters, else the largest canonical
    correlation (>= 0)."""
    a, b = np.atleast_1d(a), np.atleast_1d(b)
    Saa, Sbb, Sab = cov[np.ix_(a, a)], cov[np.ix_(b, b)], cov[np.ix_(a, b)]
    if len(a) == 1 and len(b) == 1:
        den = np.sqrt(Saa[0, 0] * Sbb[0, 0])
        return float(Sab[0, 0] / den) if den > 0 else 0.0
    if not (np.all(np.isfinite(Saa)) and np.all(np.isfinite(Sbb))):
        return 0.0
    M = _inv_sqrt(Saa) @ Sab @ _inv_sqrt(Sbb)
    return float(min(np.linalg.svd(M, compute_uv=False)[0], 1.0))


def design_covariance(X):
    """(X^T X)^-1 with columns scaled to unit norm and scaled back (the
    covariance of the estimates up to the noise variance)."""
    scale = np.linalg.norm(X, axis=0)
    scale[scale == 0] = 1.0
    Xs = X / scale
    return np.linalg.pinv(Xs.T @ Xs) / np.outer(scale, scale)


def confounded_pairs(X, blocks, pairs=None, threshold=CONFOUNDED_MIN):
    """[{terms: [A, B], correlation}] of the blocks ({name: index array} into
    X's columns) whose estimates correlate at ``threshold`` or more in the
    fit of all of X, strongest first; ``pairs``: which pairs to look at
    (default every pair)."""
    cov = design_covariance(X)
    names = list(blocks)
    if pairs is None:
        pairs = [(a, b) for i, a in enumerate(names) for b in names[i + 1:]]
    out = []
    for a, b in pairs:
        r = correlation(cov, blocks[a], blocks[b])
        if abs(r) >= threshold:
            out.append({"terms": [a, b], "correlation": r})
    return sorted(out, key=lambda d: -abs(d["correlation"]))
